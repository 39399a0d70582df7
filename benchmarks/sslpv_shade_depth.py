"""Where and how the shading reads the grid: at the surface point or one cell deep, by cell or trilinear, on the suite.

``sslpv_gl.shade`` Eq. (S1): with ``shade_depth = d`` each shaded point reads the accumulation grid ``d``
cells inwards along ``-n``. This measures what that does to the image's *shape* and its energy on every
suite scene at N = 32, at the paper's K = 32 and at the steady state, with the collision mapping:

* ``si_relmse``: relMSE after the best scale per colour (``harness.metrics.pixel.si_relmse``), the part
  of the error that no radiance scale removes; a calibration can still change it through ``sigma_scale``;
* ``E``: subsurface energy against the committed small reference's, which a radiance scale does move.

Rows: ``vacuum`` (the paper's outside treatment) and ``interior`` (``sslpv_gl.boundary``), each read at the
surface (d = 0) and one cell deep (d = 1), and ``interior`` with the injection one reduced mean free path
deep (``inject_depth = 1``, ``sslpv_gl.inject`` Eq. (J1)) read one cell deep; each with the cell lookup
(``texelFetch`` of the cell that holds the read point, the default), and the paper's row and the last one
again with the trilinear lookup (the grid interpolated between the eight nearest cell centres, as a filtered
3D texture read is; ``lookup = trilinear``). The summary gives, per row and
budget, the median ``si_relmse`` over the scenes and the spread of ``E`` (a global radiance scale brings all
scenes within [0.8, 1.25] only where max E / min E <= 1.5625).

Run: ``.venv/bin/python benchmarks/sslpv_shade_depth.py`` (about 5 min on two cores; ``--scenes a,b``).
Limits: uncalibrated renders (``sigma_scale = radiance_scale = 1``); the dielectric scenes are compared on the
subsurface image, as the calibrations compare them; one grid.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from harness.errors import InputError

ROWS = (("vacuum", 0.0, 0.0, "cell"), ("vacuum", 0.0, 1.0, "cell"), ("interior", 0.0, 0.0, "cell"),
        ("interior", 0.0, 1.0, "cell"), ("interior", 1.0, 1.0, "cell"), ("vacuum", 0.0, 0.0, "trilinear"),
        ("interior", 1.0, 1.0, "trilinear"))
BUDGETS = (32, "steady")


def measure(renderer, name, grid=32):
    """``[(outside, inject_depth, shade_depth, lookup, {K: (si_relmse, E)})]`` for one scene."""
    from harness.metrics import compute
    from harness.regression.accuracy import case_reference, small_scene
    from sslpv_gl.params import SSLPVParams

    scene = small_scene(name)
    ref = case_reference(scene)
    out = []
    for outside, inject, shade, lookup in ROWS:
        p = SSLPVParams(N=grid, steps=32, mapping="collision", outside=outside, inject_depth=inject,
                        shade_depth=shade, lookup=lookup)
        renders = renderer.render_steps(scene, p, [k for k in BUDGETS if isinstance(k, int)])
        renders.append(renderer.render(scene, p.replace(steps="steady")))
        figs = {}
        for k, res in zip(BUDGETS, renders):
            figs[k] = tuple(compute(m, res.subsurface, ref["subsurface"], ref["mask"]).value
                            for m in ("si_relmse", "energy_ratio"))
        out.append((outside, inject, shade, lookup, figs))
    return scene, out


def main(argv=None):
    from harness.scene import list_scenes
    from sslpv_gl.renderer import SSLPVRenderer

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", help="comma-separated scene names (default: every suite scene)")
    args = ap.parse_args(argv)
    known = list_scenes()
    scenes = args.scenes.split(",") if args.scenes else known
    for s in scenes:
        if s not in known:
            err = InputError("--scenes", "scenes", f"unknown scene {s!r}", "use one of: " + ", ".join(known))
            print(f"error: {err}", file=sys.stderr)
            return 2
    renderer = SSLPVRenderer()
    print(f"GL renderer: {renderer.gl_renderer}; N = 32, mapping collision, uncalibrated")
    print(f"{'scene':<24} {'lit':<5} {'outside':<9} {'inject':>6} {'shade':>5} {'lookup':<9}   "
          f"{'si K32':>7} {'E K32':>7}   {'si steady':>9} {'E steady':>8}")
    table = {}
    for name in scenes:
        scene, rows = measure(renderer, name)
        lit = "back" if "back-lit" in scene.tags else "front"
        for outside, inject, shade, lookup, figs in rows:
            table.setdefault((outside, inject, shade, lookup), {})[name] = figs
            (s32, e32), (sst, est) = figs[32], figs["steady"]
            print(f"{name:<24} {lit:<5} {outside:<9} {inject:6g} {shade:5g} {lookup:<9}   {s32:7.4f} {e32:7.3g}   "
                  f"{sst:9.4f} {est:8.3g}", flush=True)
    print()
    print(f"{'outside':<9} {'inject':>6} {'shade':>5} {'lookup':<9} {'K':>7}   {'median si':>9} {'min E':>7} {'max E':>7} "
          f"{'max/min':>8}")
    for (outside, inject, shade, lookup), per in table.items():
        for k in BUDGETS:
            si = [per[n][k][0] for n in per]
            e = [per[n][k][1] for n in per]
            print(f"{outside:<9} {inject:6g} {shade:5g} {lookup:<9} {str(k):>7}   {np.median(si):9.4f} {min(e):7.3g} "
                  f"{max(e):7.3g} {max(e) / min(e):8.3g}")
    return 0


if __name__ == "__main__":
    from page import run

    raise SystemExit(run(main, "sslpv_shade_depth",
                         "Where and how the shading reads the grid: at the surface or one cell deep, by cell or "
                         "trilinear"))
