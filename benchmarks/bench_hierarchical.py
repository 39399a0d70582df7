"""The hierarchical gather (Jensen & Buhler 2002) against the dense gather, and on every suite scene.

Part ``convergence``: per scene (``--scenes``, at its committed small size) and kernel, the dense gather
at spacing 1 and the hierarchical gather over the same samples at each ``--epsilons`` value: the
error of the hierarchical image against the dense one over the covered pixels, as the normalised
squared error ``sum (x - y)^2 / sum y^2`` and as the project's relMSE (``harness.metrics.relmse``,
``eps = 1e-2``), the largest ``|x - y|`` relative to the largest value, the octree's node visits and
kernel evaluations per pixel, the descent's dispatches, and the gather's and the frame's times.

Part ``large``: the same comparison on ``marble_sphere`` (``--scenes``), where the dense gather fits only
coarsened (``fit = coarsen``, ``docs/dipole_rivals.md`` Sec. 9): both gathers at the dense gather's coarsened
spacing.

Part ``suite``: every suite scene, both kernels, at ``--epsilon`` (the default of ``dipole_gl.params``)
with ``fit = coarsen`` as the nightly runs the rivals: samples, nodes, visits per pixel, dispatches,
frame, precomputation (sampling + octree), the render's spot check against the twin, and the wall time
of the whole render (precomputation, frame, check).

Frame times: the sum of the frame stages (host time on llvmpipe, ``dipole_gl/timing.py``) of one render
after every program was compiled on a small warm-up render. Times on a shared machine: see the load
average in the page's header.

    .venv/bin/python benchmarks/bench_hierarchical.py convergence [--scenes a,b] [--epsilons 1,0.1,0] [--write]
    .venv/bin/python benchmarks/bench_hierarchical.py large [--scenes marble_sphere] [--epsilons 0.1,0.03] [--write]
    .venv/bin/python benchmarks/bench_hierarchical.py suite [--scenes a,b] [--epsilon 0.1] [--write]
"""

import argparse
import sys
import time

import numpy as np

from page import Page

from harness.metrics.pixel import relmse
from harness.regression.accuracy import small_scene
from harness.scene import list_scenes, load_scene
from dipole_gl.params import DEFAULT_EPSILON, DipoleParams
from dipole_gl.renderer import DipoleRenderer

CONVERGENCE_SCENES = "apple_sphere,two_lights,skin_torus,jade_backlit_dielectric"
EPSILONS = "1,0.3,0.1,0.03,0.01,0"
LARGE_EPSILONS = "0.3,0.1,0.03,0.01"
KERNELS = ("dipole", "dirpole")


def warm_up(renderer):
    """Compile every program of both kernels and both gathers on a tiny render."""
    scene = load_scene("two_lights").with_resolution(8, 8)
    for kernel in KERNELS:
        for params in (DipoleParams(spacing=3.0), DipoleParams(gather="hierarchical", spacing=3.0)):
            renderer.render(scene, kernel, params)


def timed(renderer, scene, kernel, params):
    t = time.perf_counter()
    res = renderer.render(scene, kernel, params)
    return res, time.perf_counter() - t


def convergence(renderer, page, scenes, epsilons, coarsen=False):
    page.para("The hierarchical gather against the dense gather of the same kernel over the same samples "
              + ("(at the spacing to which `fit = coarsen` coarsens the dense gather, in the column `spacing`)"
                 if coarsen else "(spacing 1 l')") + ", per scene at its committed small size. `error` is `sum (x - y)^2 / sum y^2` over the "
              "covered pixels, `relMSE` the project's metric (`harness.metrics.relmse`, eps = 1e-2), `max` the "
              "largest `|x - y|` over the largest value; node visits (mean / largest) and kernel evaluations (the "
              "method's work count: far field per light for the directional dipole, plus the near field's "
              "quadrature) are per covered pixel; times in seconds (gather stage, whole frame).")
    rows = []
    for name in scenes:
        scene = small_scene(name)
        for kernel in KERNELS:
            dense, _ = timed(renderer, scene, kernel, DipoleParams(fit="coarsen" if coarsen else None))
            m = dense.mask
            ref = dense.subsurface
            d = dense.info
            spacing = d["spacing_used"]
            rows.append([name, kernel, f"{spacing:g}", "dense", "-", "-", "-", "-", f"{dense.work['gather'] / m.sum():,.0f}",
                         d["dispatches"], f"{dense.timings_ms['gather'] / 1e3:.2f}",
                         f"{sum(dense.timings_ms.values()) / 1e3:.2f}"])
            print(f"  {name} {kernel} dense: {rows[-1]}", file=sys.stderr)
            for eps in epsilons:
                res, _ = timed(renderer, scene, kernel, DipoleParams(gather="hierarchical", epsilon=eps, spacing=spacing))
                x = res.subsurface
                err = float(np.sum((x[m] - ref[m]) ** 2) / np.sum(ref[m] ** 2))
                rel = relmse(x, ref, m).value
                worst = float(np.abs(x[m] - ref[m]).max() / np.abs(ref[m]).max())
                i = res.info
                rows.append([name, kernel, f"{spacing:g}", f"{eps:g}", f"{err:.2e}", f"{rel:.2e}", f"{worst:.1e}",
                             f"{i['visits_per_pixel']:,.0f} / {i['max_visits']:,}", f"{res.work['gather'] / m.sum():,.0f}",
                             i["dispatches"], f"{res.timings_ms['gather'] / 1e3:.2f}",
                             f"{sum(res.timings_ms.values()) / 1e3:.2f}"])
                print(f"  {name} {kernel} {eps}: {rows[-1]}", file=sys.stderr)
    page.table(["scene", "kernel", "spacing", "epsilon", "error", "relMSE", "max", "visits / pixel", "kernel evaluations / pixel",
                "dispatches", "gather [s]", "frame [s]"], rows)


def suite(renderer, page, scenes, epsilon):
    page.para(f"Every suite scene at its committed small size, both kernels, `--gather hierarchical --epsilon "
              f"{epsilon:g} --fit coarsen` (spacing 1 l' where the samples fit). Visits per covered pixel (mean / "
              "largest); frame and precomputation (sampling + octree) in seconds; the spot check's largest "
              "difference against the twin and its seconds; wall: the whole first render of the configuration "
              "(precomputation, frame, check). The renderer keeps a scene's material, samples and octree for its "
              "next render, so the directional dipole's wall time, rendered second, leaves them out (its "
              "precomp. column is what they cost when made).")
    rows, total = [], 0.0
    for name in scenes:
        scene = small_scene(name)
        for kernel in KERNELS:
            try:
                res, wall = timed(renderer, scene, kernel, DipoleParams(gather="hierarchical", epsilon=epsilon,
                                                                        fit="coarsen"))
            except Exception as exc:                               # a failure is a row, not the end of the table
                rows.append([name, kernel, f"failed: {type(exc).__name__}: {exc}"] + ["-"] * 8)
                continue
            total += wall
            i, c = res.info, res.info["check"]
            rows.append([name, kernel, f"{i['spacing_used']:g}", f"{i['samples']:,}", f"{i['nodes']:,}",
                         f"{i['visits_per_pixel']:,.0f} / {i['max_visits']:,}", i["dispatches"],
                         f"{sum(res.timings_ms.values()) / 1e3:.2f}", f"{sum(res.precompute_ms.values()) / 1e3:.2f}",
                         f"{c['max_rel_diff']:.1e} / {c['ms'] / 1e3:.2f}", f"{wall:.1f}"])
            print(f"  {rows[-1]}", file=sys.stderr)
    page.table(["scene", "kernel", "spacing", "samples", "nodes", "visits / pixel", "dispatches", "frame [s]",
                "precomp. [s]", "check: diff / s", "wall [s]"], rows)
    page.para(f"All {len(rows)} renders: {total:.0f} s of wall time.")


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("part", choices=("convergence", "large", "suite"))
    ap.add_argument("--scenes", default=None, help=f"comma-separated (convergence: {CONVERGENCE_SCENES}; suite: all)")
    ap.add_argument("--epsilons", default=EPSILONS, help=f"convergence: the bounds (default {EPSILONS})")
    ap.add_argument("--epsilon", type=float, default=DEFAULT_EPSILON, help="suite: the bound (default the method's)")
    ap.add_argument("--write", action="store_true", help="write docs/benchmarks/bench_hierarchical_<part>.md")
    args = ap.parse_args(argv)
    shown = [a for a in ([sys.argv[0]] + list(argv)) if a != "--write"]
    title = {"convergence": "The hierarchical gather converging to the dense gather",
             "large": "The hierarchical gather against the coarsened dense gather on marble_sphere",
             "suite": "The hierarchical gather on every suite scene"}[args.part]
    page = Page(f"bench_hierarchical_{args.part}", title, argv=shown)
    renderer = DipoleRenderer()
    page.gl_renderer = renderer.gl_renderer
    warm_up(renderer)
    if args.part == "convergence":
        scenes = (args.scenes or CONVERGENCE_SCENES).split(",")
        convergence(renderer, page, scenes, [float(e) for e in args.epsilons.split(",")])
    elif args.part == "large":
        epsilons = args.epsilons if args.epsilons != EPSILONS else LARGE_EPSILONS
        convergence(renderer, page, (args.scenes or "marble_sphere").split(","),
                    [float(e) for e in epsilons.split(",")], coarsen=True)
    else:
        suite(renderer, page, args.scenes.split(",") if args.scenes else list_scenes(), args.epsilon)
    renderer.release()
    page.finish(args.write)


if __name__ == "__main__":
    main()
