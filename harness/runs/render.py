"""One render of one scene into a folder (``sslpv-harness render``, and every sweep configuration).

Writes, atomically (the folder appears complete or not at all):

* ``full.exr`` -- subsurface + direct reflection, linear RGB, top row first, with the ``mask`` layer;
* ``subsurface.exr`` -- the SSLPV part, with the coverage ``mask`` as an extra layer;
* ``preview.png`` -- the full image, auto exposure;
* ``render.json`` -- the method and every parameter, scene name and content hash, GL renderer,
  per-stage GPU timings (ms), warnings and image size (``width``, ``height``, and ``size`` as asked:
  ``"small"``, ``[W, H]`` or None for the scene's own); for a method other than SSLPV also
  its precomputation (``precompute``: step -> ms and work) and work counts per stage (``work``).
"""

from __future__ import annotations

import json
from pathlib import Path

from harness.io.atomic import atomic_dir
from harness.io.outputs import check_replaceable, check_writable
from harness.io.images import auto_exposure, write_exr, write_png
from harness.reference.committed import sized_scene
from harness.scene import load_scene

from sslpv_gl.params import SSLPVParams

__all__ = ["run_render", "write_render_dir"]


def write_render_dir(out_dir, full, subsurface, mask, info, preview, exposure):
    """Write one render folder atomically: both EXRs (with the coverage ``mask`` layer),
    a PNG preview of ``preview`` at ``exposure`` stops, and ``render.json`` from ``info``.

    The one layout of a render, used by ``render`` and by every sweep configuration.
    """
    mask = mask.astype("f4")
    with atomic_dir(out_dir) as tmp:
        write_exr(tmp / "full.exr", full, extra={"mask": mask})
        write_exr(tmp / "subsurface.exr", subsurface, extra={"mask": mask})
        write_png(tmp / "preview.png", preview, exposure)
        (tmp / "render.json").write_text(json.dumps(info, indent=2, sort_keys=True, default=str) + "\n")


def run_render(scene_name_or_path, out_dir, params: SSLPVParams | None = None, as_json=False, renderer=None,
               method="sslpv", size=None):
    """Render a scene with ``method`` and write the output folder; returns the ``render.json`` content.

    ``size`` is the image size as a sweep takes it (:func:`harness.reference.committed.sized_scene`):
    ``[W, H]``, ``"small"`` (the committed small size, that of the scene's committed reference) or
    None (the scene's own).

    ``renderer`` (an :class:`~sslpv_gl.renderer.SSLPVRenderer`) may be passed to
    reuse a context; ``as_json`` only affects how the CLI prints the result.
    """
    from sslpv_gl.renderer import SSLPVRenderer

    scene = sized_scene(load_scene(scene_name_or_path), size)
    out_dir = Path(out_dir) if out_dir is not None else Path("renders") / scene.name
    check_replaceable(out_dir)                 # refused before the render, not after it
    check_writable(out_dir, "--out")
    if method != "sslpv":
        return _run_method_render(scene, out_dir, params, method, size)
    params = params or SSLPVParams()
    result = (renderer or SSLPVRenderer()).render(scene, params)
    exposure = auto_exposure(result.full)
    info = {
        "scene": scene.name,
        "scene_path": str(scene.path),
        "content_hash": scene.content_hash,
        "params": params.as_dict(),
        "gl_renderer": result.gl_renderer,
        "timings_ms": {k: float(v) for k, v in result.timings_ms.items()},
        "width": scene.camera.width,
        "height": scene.camera.height,
        "size": size,
        "covered_pixels": int(result.mask.sum()),
        "preview_exposure": exposure,
        "warnings": list(result.warnings),
        "mesh_repair": scene.mesh.repair,
        "method": "SSLPV (Borlum et al., HPG 2011), GLSL renderer sslpv_gl",
    }
    write_render_dir(out_dir, result.full, result.subsurface, result.mask, info, result.full, exposure)
    info["out_dir"] = str(out_dir)
    return info


def _run_method_render(scene, out_dir, params, method, size):
    """``run_render`` for a method other than SSLPV (``harness.methods``)."""
    from harness.methods import get_method

    m = get_method(method)
    params = params or m.params_type()
    m.check_scene(scene)
    res = m.render(scene, params)
    exposure = auto_exposure(res.full)
    info = {
        "scene": scene.name, "scene_path": str(scene.path), "content_hash": scene.content_hash,
        "method": method, "method_title": m.title, "params": m.as_dict(params), "gl_renderer": res.device,
        "timings_ms": {k: float(v) for k, v in res.timings_ms.items()}, "frame_ms": res.frame_ms,
        "precompute": {k: {"ms": res.precompute_ms.get(k), "work": res.precompute_work.get(k)}
                       for k in sorted(set(res.precompute_ms) | set(res.precompute_work))},
        "work": {k: int(v) for k, v in res.work.items()}, "work_units": {k: m.work_units.get(k) for k in res.work},
        "info": res.info, "width": scene.camera.width, "height": scene.camera.height, "size": size,
        "covered_pixels": int(res.mask.sum()), "preview_exposure": exposure, "warnings": list(res.warnings),
        "mesh_repair": scene.mesh.repair,
    }
    write_render_dir(out_dir, res.full, res.subsurface, res.mask, info, res.full, exposure)
    info["out_dir"] = str(out_dir)
    return info
