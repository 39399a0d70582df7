"""What one Dask worker does for one SSLPV configuration: render, then measure.

Each worker process creates and owns one OpenGL context (one
:class:`sslpv_gl.renderer.SSLPVRenderer`), made on its first task and reused for
every later task, so a context is never shared between processes. Workers
write nothing: they return images, timings and metrics, and the client alone
writes files and the results store.
"""

import functools
import os
import time

import numpy as np

_RENDERER = None
STAGES = ("rsm", "injection", "propagation", "shading")


def release_renderer():
    """Release this process's GL context before the interpreter shuts down.

    Left to interpreter finalisation, the EGL/llvmpipe teardown can abort the
    worker process (seen as 'killed by signal 6' when a cluster closes).
    """
    global _RENDERER
    if _RENDERER is not None:
        _RENDERER.ctx.release()
        _RENDERER = None


def renderer():
    global _RENDERER
    if _RENDERER is None:
        from sslpv_gl.renderer import SSLPVRenderer

        _RENDERER = SSLPVRenderer()
    return _RENDERER


@functools.lru_cache(maxsize=16)
def _scene(path, size):
    from harness.scene import load_scene

    scene = load_scene(path)
    return scene.with_resolution(*size) if size else scene


def measure(images, ref, floors):
    """Metric rows for the subsurface part and the full image, each with its noise floor."""
    from harness.metrics import compute_all

    rows = []
    for part in ("subsurface", "full"):
        results = compute_all(images[part], ref[part], ref["mask"])
        for name, res in results.items():
            rows.append({"image": part, "metric": name, "value": float(res.value),
                         "noise_floor": float(floors[part][name]), "per_channel": res.per_channel,
                         "params": res.params})
    return rows


def reference_floors(ref):
    """Each metric between the two independent halves of the reference: the noise floor.

    The reference stores halves of the subsurface part only; the full image adds
    the albedo-0 render, whose noise is far smaller, so the same floor is used for
    both parts.
    """
    from harness.metrics import noise_floor

    floors = {name: float(r.value) for name, r in noise_floor(ref["half_a"], ref["half_b"], ref["mask"]).items()}
    return {"subsurface": floors, "full": floors}


def run_config(scene_path, size, params, ref, floors):
    """Render one configuration and measure it; errors are returned, not raised."""
    from sslpv_gl.params import SSLPVParams

    from harness.runs.params import config_label

    t0 = time.perf_counter()
    try:
        # Fault injection for the sweep's own tests: the configuration with this label fails.
        if os.environ.get("SSLPV_SWEEP_FAIL_CONFIG") == config_label(params):
            raise RuntimeError("failure injected by SSLPV_SWEEP_FAIL_CONFIG")
        scene = _scene(str(scene_path), tuple(size) if size else None)
        result = renderer().render(scene, SSLPVParams(**params))
        images = {"subsurface": result.subsurface, "full": result.full}
        for part, img in images.items():
            if not np.all(np.isfinite(img)):
                raise FloatingPointError(f"SSLPV {part} image has {int(np.count_nonzero(~np.isfinite(img)))} "
                                         "non-finite pixels")
        metrics = measure(images, ref, floors)
        # Only the four stages of the paper's Table 1 (a timer query that failed reports NaN and is dropped).
        timings = {k: float(v) for k, v in result.timings_ms.items() if k in STAGES and np.isfinite(v)}
        if len(timings) == len(STAGES):
            timings["total"] = float(sum(timings.values()))
        return {"status": "ok", "images": images, "mask": result.mask, "timings": timings, "metrics": metrics,
                "gl_renderer": result.gl_renderer, "wall_s": time.perf_counter() - t0}
    except Exception as exc:  # one failed configuration is recorded; the sweep goes on
        return {"status": "failed", "error": f"{type(exc).__name__}: {exc}".splitlines()[0],
                "wall_s": time.perf_counter() - t0}
