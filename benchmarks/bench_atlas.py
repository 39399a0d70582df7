"""The atlas gather (Carr, Hall & Hart 2003) against the dense gather, and on every suite scene.

Part ``convergence``: per scene (``--scenes``, at its committed small size), the standard dipole's
dense gather at spacing 1 and the atlas gather at each budget of ``--budgets`` (``SIZE:links=L`` for
the adaptive scheme, ``SIZE:level=l`` for the non-adaptive one): the error of the atlas image against
the dense one over the pixels both cover, as the normalised squared error ``sum (x - y)^2 / sum y^2``
and the project's relMSE (``harness.metrics.relmse``, ``eps = 1e-2``), the largest ``|x - y|``
relative to the largest value, the links per texel, the work of pass 2 (links evaluated), its
dispatches, the frame's stage times and the precomputation (atlas + links).

Part ``suite``: every suite scene at its committed small size, both kernels, at ``--budget``: the
directional dipole is refused by the gather (a row saying so), the standard dipole's texels, patches,
links, frame, precomputation, the spot check against the twin and the wall time of the whole render.

Frame times: the sum of the frame stages (host time on llvmpipe, ``dipole_gl/timing.py``) after every
program was compiled on a small warm-up render. Times on a shared machine: see the page's header.

    .venv/bin/python benchmarks/bench_atlas.py convergence [--scenes a,b] [--budgets 128:links=16,...] [--write]
    .venv/bin/python benchmarks/bench_atlas.py suite [--scenes a,b] [--budget 128:links=16] [--write]
"""

import argparse
import sys
import time

import numpy as np

from page import Page

from harness.metrics.pixel import relmse
from harness.regression.accuracy import small_scene
from harness.scene import list_scenes, load_scene
from dipole_gl.params import DipoleParams
from dipole_gl.renderer import DipoleRenderer

CONVERGENCE_SCENES = "apple_sphere,skin_torus,jade_backlit_dielectric"
BUDGETS = "128:level=4,128:level=3,128:links=4,128:links=16,128:links=64,256:links=16"
SUITE_BUDGET = "128:links=16"
KERNELS = ("dipole", "dirpole")


def budget_params(text, terms="diffusion"):
    """``SIZE:links=L`` or ``SIZE:level=l`` -> DipoleParams of the atlas gather."""
    size, rest = text.split(":")
    key, value = rest.split("=")
    kw = {"links": int(value)} if key == "links" else {"link_level": int(value)}
    return DipoleParams(gather="atlas", atlas_size=int(size), terms=terms, **kw)


def warm_up(renderer):
    scene = load_scene("layered_dielectric").with_resolution(8, 8)
    renderer.render(scene, "dipole", DipoleParams(spacing=3.0))
    renderer.render(scene, "dipole", DipoleParams(gather="atlas", atlas_size=8, links=4))


def timed(renderer, scene, kernel, params):
    t = time.perf_counter()
    res = renderer.render(scene, kernel, params)
    return res, time.perf_counter() - t


def frame_s(res):
    return sum(res.timings_ms.values()) / 1e3


def convergence(renderer, page, scenes, budgets):
    page.para("The atlas gather against the dense gather of the standard dipole (spacing 1 l', the kernel's "
              "diffusion term alone), per scene at its committed small size. Budget: atlas texels per side and "
              "either `links` per texel (the adaptive scheme) or the MIP `level` every texel links to (the "
              "non-adaptive scheme). `error` is `sum (x - y)^2 / sum y^2` over the pixels both cover, `relMSE` "
              "the project's metric (`harness.metrics.relmse`, eps = 1e-2), `max` the largest `|x - y|` over the "
              "largest value; `links / texel` the mean used; pass-2 work is the links evaluated per frame; times "
              "in seconds (pass 2, whole frame, precomputation of atlas + links).")
    rows = []
    for name in scenes:
        scene = small_scene(name)
        dense, _ = timed(renderer, scene, "dipole", DipoleParams(terms="diffusion"))
        ref = dense.subsurface
        rows.append([name, "dense", "-", "-", "-", "-", f"{dense.work['gather']:,}", dense.info["dispatches"],
                     f"{dense.timings_ms['gather'] / 1e3:.2f}", f"{frame_s(dense):.2f}",
                     f"{dense.precompute_ms.get('sampling', 0.0) / 1e3:.2f}"])
        print(f"  {rows[-1]}", file=sys.stderr)
        for text in budgets:
            try:
                res, _ = timed(renderer, scene, "dipole", budget_params(text))
            except Exception as exc:                               # a refusal is a row, not the end of the table
                rows.append([name, text, f"refused: {exc}"] + ["-"] * 8)
                continue
            m = dense.mask & res.mask
            x = res.subsurface
            err = float(np.sum((x[m] - ref[m]) ** 2) / np.sum(ref[m] ** 2))
            rel = relmse(x, ref, m).value
            worst = float(np.abs(x[m] - ref[m]).max() / np.abs(ref[m]).max())
            pre = (res.precompute_ms["atlas"] + res.precompute_ms["links"]) / 1e3
            rows.append([name, text, f"{err:.2e}", f"{rel:.2e}", f"{worst:.1e}", f"{res.info['links_per_texel']:.1f}",
                         f"{res.work['gather']:,}", res.info["dispatches"], f"{res.timings_ms['gather'] / 1e3:.2f}",
                         f"{frame_s(res):.2f}", f"{pre:.1f}"])
            print(f"  {rows[-1]}", file=sys.stderr)
    page.table(["scene", "budget", "error", "relMSE", "max", "links / texel", "pass-2 work", "dispatches",
                "pass 2 [s]", "frame [s]", "precomp. [s]"], rows)


def suite(renderer, page, scenes, text):
    page.para(f"Every suite scene at its committed small size, both kernels, `--gather atlas` at `{text}` "
              "(`terms = both`, as the nightly renders). Frame and precomputation (atlas + links) in seconds; the "
              "spot check's largest difference against the twin and its seconds; wall: the whole render "
              "(precomputation, frame, checks).")
    rows, total = [], 0.0
    for name in scenes:
        scene = small_scene(name)
        for kernel in KERNELS:
            try:
                res, wall = timed(renderer, scene, kernel, budget_params(text, terms="both"))
            except Exception as exc:                               # a refusal is a row, not the end of the table
                rows.append([name, kernel, f"refused: {type(exc).__name__}: {str(exc)[:90]}"] + ["-"] * 7)
                continue
            total += wall
            i, c = res.info, res.info["check"]
            pre = (res.precompute_ms["atlas"] + res.precompute_ms["links"]) / 1e3
            rows.append([name, kernel, f"{i['texels']:,}", f"{i['patches']:,}", f"{i['links_per_texel']:.1f}",
                         i["dispatches"], f"{frame_s(res):.2f}", f"{pre:.1f}",
                         f"{c['max_rel_diff']:.1e} / {c['ms'] / 1e3:.2f}", f"{wall:.1f}"])
            print(f"  {rows[-1]}", file=sys.stderr)
    page.table(["scene", "kernel", "texels", "patches", "links / texel", "dispatches", "frame [s]", "precomp. [s]",
                "check: diff / s", "wall [s]"], rows)
    page.para(f"The rendered configurations: {total:.0f} s of wall time.")


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("part", choices=("convergence", "suite"))
    ap.add_argument("--scenes", default=None, help=f"comma-separated (convergence: {CONVERGENCE_SCENES}; suite: all)")
    ap.add_argument("--budgets", default=BUDGETS, help=f"convergence: SIZE:links=L or SIZE:level=l (default {BUDGETS})")
    ap.add_argument("--budget", default=SUITE_BUDGET, help=f"suite: the budget (default {SUITE_BUDGET})")
    ap.add_argument("--write", action="store_true", help="write docs/benchmarks/bench_atlas_<part>.md")
    args = ap.parse_args(argv)
    shown = [a for a in ([sys.argv[0]] + list(argv)) if a != "--write"]
    title = {"convergence": "The atlas gather converging to the dense gather",
             "suite": "The atlas gather on every suite scene"}[args.part]
    page = Page(f"bench_atlas_{args.part}", title, argv=shown)
    renderer = DipoleRenderer()
    page.gl_renderer = renderer.gl_renderer
    warm_up(renderer)
    if args.part == "convergence":
        convergence(renderer, page, (args.scenes or CONVERGENCE_SCENES).split(","), args.budgets.split(","))
    else:
        suite(renderer, page, args.scenes.split(",") if args.scenes else list_scenes(), args.budget)
    renderer.release()
    page.finish(args.write)


if __name__ == "__main__":
    main()
