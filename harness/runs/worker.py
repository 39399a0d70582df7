"""What one Dask worker does for one configuration: render, then measure.

SSLPV configurations come in step groups (:func:`run_group`); those of the other methods
(``harness.methods``: the dipole rivals) one at a time (:func:`run_method`).

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
    from harness.methods import release_all

    release_all()                                  # the other methods' renderers (harness.methods)


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
    return run_group(scene_path, size, params, [params["steps"]], ref, floors)[0]


def _finite_or_none(obj):
    """A JSON-ready copy of the renderer's diagnostics: numpy to Python, NaN/inf to None."""
    if isinstance(obj, dict):
        return {str(k): _finite_or_none(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite_or_none(v) for v in obj]
    if hasattr(obj, "tolist"):
        return _finite_or_none(obj.tolist())
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


def _ok_result(result, ref, floors, group_steps):
    images = {"subsurface": result.subsurface, "full": result.full}
    for part, img in images.items():
        if not np.all(np.isfinite(img)):
            raise FloatingPointError(f"SSLPV {part} image has {int(np.count_nonzero(~np.isfinite(img)))} "
                                     "non-finite pixels")
    metrics = measure(images, ref, floors)
    # Only the four stages of the paper's Table 1 (a timer query that failed reports NaN and is dropped).
    timings = {k: float(v) for k, v in result.timings_ms.items()
               if k in STAGES and isinstance(v, (int, float)) and np.isfinite(v)}
    if len(timings) == len(STAGES):
        timings["total"] = float(sum(timings.values()))
    shared = result.timings_ms.get("shared")
    return {"status": "ok", "images": images, "mask": result.mask, "timings": timings, "metrics": metrics,
            "gl_renderer": result.gl_renderer, "steps_used": result.steps_used,
            "diagnostics": _finite_or_none(result.diagnostics) if result.diagnostics is not None else None,
            "calibration": _finite_or_none(result.calibration) if result.calibration is not None else None,
            "shared": {"stages": list(shared), "group_steps": list(group_steps)} if shared else None}


#: Test hook: ``SCENE:LABEL`` (e.g. ``wide_slab:N16-K8-collision``) holds the worker of the group that
#: holds this configuration before it renders, for at most this many seconds, so that a test can kill a
#: sweep at a known point (every other group recorded, this one not).
PAUSE_LIMIT_S = 600.0


def _pause_if_asked(scene_path, params, ks):
    from pathlib import Path

    from harness.runs.params import config_label

    pause = os.environ.get("SSLPV_SWEEP_PAUSE_CONFIG")
    if not pause:
        return
    name = Path(scene_path).name
    if any(pause == f"{name}:{config_label(dict(params, steps=k))}" for k in ks):
        end = time.monotonic() + PAUSE_LIMIT_S
        while time.monotonic() < end:
            time.sleep(0.2)


def _sslpv_costs(result, scene, params):
    """SSLPV's work counts and precomputation as the method interface states them (``harness.methods.sslpv``)."""
    from harness.methods import get_method

    res = get_method("sslpv").result(result, scene, params)
    return {"work": {k: int(v) for k, v in res.work.items()}, "precompute": precompute_record(res)}


def run_group(scene_path, size, params, steps_list, ref, floors, diagnostics=True):
    """Render one configuration per step count in ``steps_list`` (all else from ``params``) and measure each.

    Two or more integer step counts are rendered by ONE
    :meth:`~sslpv_gl.renderer.SSLPVRenderer.render_steps` call: RSM, injection and the
    material once, one propagation to the largest count, the shading pass as each count
    passes. Each image is bit-identical to rendering its count alone. Each result's
    ``propagation`` timing is that of the steps up to its own count; ``rsm`` and
    ``injection`` were measured once for the group and are repeated in every result,
    whose ``shared`` entry (``{"stages", "group_steps"}``) says so. A single step count
    (or ``auto``/``steady``) is an ordinary :meth:`render` and has ``shared = None``.

    Returns one dict per entry of ``steps_list``, in its order; errors are returned,
    not raised (a failed group fails each of its step counts with the same error).
    ``diagnostics=True`` asks the renderer for its diagnostics (read back outside the
    stage timers).
    """
    from sslpv_gl.params import SSLPVParams

    from harness.runs.params import config_label

    t0 = time.perf_counter()
    ks = list(steps_list)
    out = [None] * len(ks)
    # Fault injection for the sweep's own tests: the configuration with this label fails;
    # SSLPV_SWEEP_KILL_WORKERS=1 kills the worker process, as the OOM killer would.
    if os.environ.get("SSLPV_SWEEP_KILL_WORKERS") == "1":
        import signal

        os.kill(os.getpid(), signal.SIGKILL)
    inject_fail = os.environ.get("SSLPV_SWEEP_FAIL_CONFIG")
    _pause_if_asked(scene_path, params, ks)
    todo = []
    for i, k in enumerate(ks):
        if inject_fail and inject_fail == config_label(dict(params, steps=k)):
            out[i] = {"status": "failed", "error": "RuntimeError: failure injected by SSLPV_SWEEP_FAIL_CONFIG"}
        else:
            todo.append(i)
    try:
        if todo:
            scene = _scene(str(scene_path), tuple(size) if size else None)
            base = SSLPVParams(**dict(params, steps=ks[todo[0]]))
            run_ks = [ks[i] for i in todo]
            if len(run_ks) > 1:
                results = renderer().render_steps(scene, base, run_ks, diagnostics=diagnostics)
                by_k = {r.steps_used: r for r in results}
                if len(by_k) != len(set(run_ks)):      # render_steps gives one result per distinct count
                    by_k = dict(zip(sorted(set(run_ks)), results))
                group_steps = sorted(set(run_ks))
            else:
                by_k = {run_ks[0]: renderer().render(scene, base, diagnostics=diagnostics)}
                group_steps = run_ks
            for i in todo:
                try:
                    out[i] = _ok_result(by_k[ks[i]], ref, floors, group_steps)
                    out[i].update(_sslpv_costs(by_k[ks[i]], scene, base.replace(steps=ks[i])))
                except Exception as exc:  # one bad image fails its own configuration only
                    out[i] = {"status": "failed", "error": f"{type(exc).__name__}: {exc}".splitlines()[0]}
    except Exception as exc:  # one failed group is recorded; the sweep goes on
        err = f"{type(exc).__name__}: {exc}".splitlines()[0]
        for i in todo:
            out[i] = {"status": "failed", "error": err}
    wall = time.perf_counter() - t0
    for r in out:
        r["wall_s"] = wall
    return out


# --------------------------------------------------------------------------- other methods (harness.methods)

def _method_timings(res):
    """Frame stages of a :class:`harness.methods.MethodResult` (finite ones), and their sum as ``total``."""
    timings = {k: float(v) for k, v in res.timings_ms.items() if isinstance(v, (int, float)) and np.isfinite(v)}
    if timings and len(timings) == len(res.timings_ms):
        timings["total"] = float(sum(timings.values()))
    return timings


def precompute_record(res):
    """``{step: {"ms", "work"}}`` of a :class:`harness.methods.MethodResult` (the store's precompute_json)."""
    steps = sorted(set(res.precompute_ms) | set(res.precompute_work))
    return {s: {"ms": _finite_or_none(float(res.precompute_ms[s])) if s in res.precompute_ms else None,
                "work": int(res.precompute_work[s]) if s in res.precompute_work else None} for s in steps}


def run_method(scene_path, size, method, params, ref, floors):
    """Render one configuration of a method other than SSLPV (``harness.methods``) and measure it.

    ``params`` is the method's parameter dict. Errors are returned, not raised. The result
    carries the frame timings (``total`` their sum), the work counts and the precomputation
    (``{step: {"ms", "work"}}``), kept apart from the frame.
    """
    from harness.methods import get_method

    t0 = time.perf_counter()
    try:
        m = get_method(method)
        scene = _scene(str(scene_path), tuple(size) if size else None)
        m.check_scene(scene)
        res = m.render(scene, m.params_from_dict(params))
        images = {"subsurface": res.subsurface, "full": res.full}
        for part, img in images.items():
            if not np.all(np.isfinite(img)):
                raise FloatingPointError(f"{method} {part} image has {int(np.count_nonzero(~np.isfinite(img)))} "
                                         "non-finite pixels")
        out = {"status": "ok", "images": images, "mask": res.mask, "timings": _method_timings(res),
               "metrics": measure(images, ref, floors), "gl_renderer": res.device, "steps_used": None,
               "diagnostics": _finite_or_none(res.info) or None, "calibration": None, "shared": None,
               "work": {k: int(v) for k, v in res.work.items()}, "precompute": precompute_record(res),
               "warnings": list(res.warnings)}
    except Exception as exc:  # one failed configuration is recorded; the sweep goes on
        out = {"status": "failed", "error": f"{type(exc).__name__}: {exc}".splitlines()[0]}
    out["wall_s"] = time.perf_counter() - t0
    return out
