"""The cubemap gather (the thesis draft's real-time directional dipole) against the dense gather of the same kernel.

For each scene (at its committed small size) and kernel, renders the dense gather (default spacing) and the
cubemap gather at growing budgets of disc samples ``k`` and frames ``F`` (cube faces, light buffer and disc
radius at their defaults unless given), and tabulates per budget: the gather's kernel evaluations (face
texels x lights x k x F), relMSE of the subsurface image against the dense one over the pixels both cover,
the energy ratio (sum over those pixels), the time of one frame (one rotation's gather plus the combination,
host ms) and the whole gather. The dense gather's own work and time are in the table's first row per kernel.

A second table renders every suite scene at one budget (``--suite``), both kernels: sizes, times and the
self-check (no dense comparison: the dense gather takes minutes on ``marble_sphere``).

    .venv/bin/python benchmarks/cubemap_convergence.py [--scenes a,b,c] [--budgets 8x1,32x8,...] [--suite 512x4]
                                                        [--write]
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from page import Page  # noqa: E402

from harness.regression.accuracy import small_scene  # noqa: E402
from harness.methods import get_method  # noqa: E402
from harness.scene import list_scenes  # noqa: E402
from dipole_gl.params import DipoleParams  # noqa: E402
from dipole_gl.renderer import DipoleRenderer  # noqa: E402

SCENES = "sphere_homogeneous,skin_torus,backlit_slab"
BUDGETS = "8x1,32x1,32x8,128x4,512x4,2048x2"


def _budgets(text):
    out = []
    for item in text.split(","):
        k, f = item.lower().split("x")
        out.append((int(k), int(f)))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default=SCENES, help=f"comma-separated suite scenes (default {SCENES})")
    ap.add_argument("--budgets", default=BUDGETS, help=f"samples x frames, comma-separated (default {BUDGETS})")
    ap.add_argument("--kernels", default="dipole,dirpole")
    ap.add_argument("--suite", default="512x4", help="one budget k x F to render every suite scene at, both kernels "
                    "(default 512x4; 'none' to skip)")
    ap.add_argument("--write", action="store_true", help="write docs/benchmarks/cubemap_convergence.md")
    args = ap.parse_args(argv)
    args.suite = None if args.suite == "none" else args.suite
    page = Page("cubemap_convergence", "The cubemap gather converging to the dense gather")
    renderer = DipoleRenderer()
    page.gl_renderer = renderer.gl_renderer
    d = DipoleParams(gather="cubemap")
    page.para(f"Each scene at its committed small size; cube faces {d.cube_size}^2, light buffer {d.light_size}^2 "
              f"per light, disc radius {d.disc_radius:g} diffusion lengths (at most the bounding sphere's diameter), "
              "the fixes at their derived defaults. relMSE and energy (the cubemap image's sum over the dense one's) "
              "over the pixels both gathers cover; work: kernel evaluations per frame of the dense gather, and "
              "face texels x lights x k x F disc samples for the cubemap gather (each a kernel evaluation at most); "
              "ms: host time on llvmpipe (one frame: one rotation's gather plus the combination).")
    header = ["scene", "kernel", "gather", "k x F", "work", "relMSE", "energy", "ms per frame", "gather ms (all F)"]
    rows = []
    try:
        for name in args.scenes.split(","):
            scene = small_scene(name)
            for kernel in args.kernels.split(","):
                dense = renderer.render(scene, kernel, DipoleParams(spacing=1.0))
                frame = sum(dense.timings_ms.values())
                rows.append([name, kernel, "dense", "-", f"{dense.work['gather']:,}", "0", "1", f"{frame:.0f}",
                             f"{dense.timings_ms['gather']:.0f}"])
                print(f"  {name} {kernel} dense {frame:.0f} ms", file=sys.stderr, flush=True)
                for k, frames in _budgets(args.budgets):
                    res = renderer.render(scene, kernel, DipoleParams(gather="cubemap", samples=k, frames=frames))
                    m = res.mask & dense.mask
                    a, b = res.subsurface[m].astype(np.float64), dense.subsurface[m].astype(np.float64)
                    rel = float(np.mean((a - b) ** 2) / np.mean(b ** 2))
                    rows.append([name, kernel, "cubemap", f"{k} x {frames}", f"{res.work['gather']:,}", f"{rel:.4f}",
                                 f"{a.sum() / b.sum():.3f}", f"{res.info['ms_per_frame']:.0f}",
                                 f"{res.timings_ms['gather']:.0f}"])
                    print(f"  {name} {kernel} {k}x{frames} relMSE {rel:.4f}", file=sys.stderr, flush=True)
        page.table(header, rows, note="The dense gather's ms per frame: the sum of its frame's stages.")
        if args.suite:
            k, frames = _budgets(args.suite)[0]
            page.heading(f"Every suite scene at k x F = {k} x {frames}")
            page.para("Each suite scene at its committed small size with both kernels at this budget, the other "
                      "settings at their defaults (no comparison with the dense gather, which takes minutes on "
                      "marble_sphere): the face texels, the gather's work and dispatches, one frame's ms, the whole "
                      "frame's stages (all F rotations) and the render's self-check against the twin; beside them SSLPV at the "
                      "study's N = 32, K = 32 (diffusion mapping): its propagation's cell updates and its frame "
                      "(RSM, injection, propagation, shading).")
            suite = []
            sslpv = get_method("sslpv")
            for name in list_scenes():
                scene = small_scene(name)
                t = time.perf_counter()
                res = sslpv.render(scene, sslpv.make_params(N=32, steps=32, mapping="diffusion"))
                suite.append([name, "sslpv N 32, K 32", "-", f"{res.work['propagation']:,} cell updates", "-",
                              f"{sum(res.timings_ms.values()):.0f}", f"{sum(res.timings_ms.values()):.0f}", "-",
                              f"{time.perf_counter() - t:.1f}"])
                for kernel in args.kernels.split(","):
                    t = time.perf_counter()
                    try:
                        res = renderer.render(scene, kernel, DipoleParams(gather="cubemap", samples=k, frames=frames))
                    except Exception as exc:  # noqa: BLE001 -- the table reports every failure
                        suite.append([name, kernel, f"failed: {type(exc).__name__}: {str(exc).splitlines()[0]}",
                                      "", "", "", "", "", ""])
                        continue
                    wall = time.perf_counter() - t
                    i = res.info
                    suite.append([name, kernel, f"{i['face_texels']:,}", f"{res.work['gather']:,}",
                                  str(i["dispatches"]), f"{i['ms_per_frame']:.0f}",
                                  f"{sum(res.timings_ms.values()):.0f}", f"{i['check']['max_rel_diff']:.1e}",
                                  f"{wall:.1f}"])
                    print(f"  suite {name} {kernel} {wall:.1f} s", file=sys.stderr, flush=True)
            page.table(["scene", "kernel", "face texels", "work", "dispatches", "ms per frame", "frame ms (all F)",
                        "check: max diff", "wall s"], suite)
    finally:
        renderer.release()
        get_method("sslpv").release()
    page.finish(args.write)


if __name__ == "__main__":
    main()
