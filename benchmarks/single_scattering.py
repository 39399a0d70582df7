"""The rivals' single-scattering term S^(1) (Jensen et al. 2001) against Mitsuba's single-scattering image.

``python benchmarks/single_scattering.py [--write] [--spp 256] [--seeds 4]`` writes
``docs/benchmarks/single_scattering.md``:

1. every validation case of ``benchmarks/single_refs.py`` (committed Mitsuba images in
   ``tests/data/single``): the ratio of GL's S^(1) mean to Mitsuba's over the compared pixels, its
   standard error, the share of pixels within 2 and 3 standard errors, and the estimator's
   approximations bounded by refinement (``single_refs.compare_case``, what
   ``tests/test_dipole_single.py`` asserts);
2. the back-lit suite scenes at their committed small size: Mitsuba's single-scattering image
   (rendered here, ``--spp`` x ``--seeds``) as a share of the committed reference (all orders), GL's
   S^(1) as a share of it, and the dense standard dipole's energy ratio with ``terms`` = diffusion
   and both;
3. what ``terms = both`` costs the nightly's rival configurations (the ``single`` stage and its
   check), per suite scene at the committed small size.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import single_refs  # noqa: E402
from page import Page  # noqa: E402
from scipy import stats  # noqa: E402

BACKLIT = ("backlit_slab", "jade_backlit_dielectric")
NIGHTLY = {"dense": {"fit": "coarsen"}, "vertex": {"density": 0.5, "range": 2.0, "fit": "coarsen"}}
COST_SCENES = ("sphere_homogeneous", "backlit_slab", "jade_backlit_dielectric", "two_lights", "skin_torus_dielectric")


def validation(renderer):
    rows = []
    for name in single_refs.CASES:
        c = single_refs.compare_case(renderer, name)
        base, eta, light, *_ = single_refs.CASES[name]
        lit = "front" if (light is not None or base == "sphere_homogeneous") else "back"
        judged = "yes" if name in ("sphere_front_eta1", "slab_back_eta1", "thick_front_eta1", "slab_back_eta13",
                                   "thick_front_eta13") else "no"
        ok = abs(c["ratio"] - 1.0) <= c["tolerance"]
        rows.append([name, f"{eta:g}", lit, f"{c['ratio']:.4f}", f"{c['se']:.4f}", f"{c['within2']:.2f}",
                     f"{c['within3']:.2f}", f"{c['march']:.4f}", f"{c['atlas']:.4f}", f"{c['pixel']:.4f}",
                     f"{c['line']:.4f}", f"{c['tolerance']:.4f}", "yes" if ok else "no", judged, str(c["pixels"])])
        print(rows[-1], file=sys.stderr, flush=True)
    return rows


def backlit(renderer, spp, seeds):
    from dipole_gl.params import DipoleParams
    from harness.io.images import read_exr
    from harness.reference.committed import small_scene
    from harness.scene import load_scene

    rows = []
    for name in BACKLIT:
        sc = small_scene(load_scene(name))
        ref_dir = single_refs.ROOT / "baselines" / "refs" / name
        truth = read_exr(ref_dir / "subsurface.exr")["rgb"]
        cov = read_exr(ref_dir / "mask.exr")["rgb"][..., 0]
        t = time.perf_counter()
        ss, _ = single_refs.render_single(sc, spp, seeds)
        t = time.perf_counter() - t
        gl = {terms: renderer.render(sc, "dipole", DipoleParams(terms=terms, fit="coarsen"))
              for terms in ("single", "diffusion", "both")}
        m = (cov >= 1.0) & gl["single"].mask
        tm = truth[m].mean()
        rows.append([name, f"{ss[m].mean() / tm:.3f}", f"{gl['single'].subsurface[m].mean() / tm:.3f}",
                     f"{gl['single'].subsurface[m].mean() / ss[m].mean():.3f}",
                     f"{gl['diffusion'].subsurface[m].mean() / tm:.3f}", f"{gl['both'].subsurface[m].mean() / tm:.3f}",
                     f"{t:.0f}"])
        print(rows[-1], file=sys.stderr, flush=True)
    return rows


def cost(renderer):
    from dipole_gl.params import DipoleParams
    from harness.reference.committed import small_scene
    from harness.scene import load_scene

    rows = []
    for name in COST_SCENES:
        sc = small_scene(load_scene(name))
        for kernel in ("dipole", "dirpole"):
            for gather, kw in NIGHTLY.items():
                p = DipoleParams(gather=gather, terms="both", **kw)
                renderer.render(sc, kernel, p)                             # warm: programs, precomputation
                t = time.perf_counter()
                both = renderer.render(sc, kernel, p)
                t_both = time.perf_counter() - t
                t = time.perf_counter()
                renderer.render(sc, kernel, p.replace(terms="diffusion"))
                t_diff = time.perf_counter() - t
                frame = sum(both.timings_ms.values())
                extra = both.timings_ms.get("single", 0.0) + (both.timings_ms.get("gbuffer", 0.0) if gather == "vertex"
                                                               else 0.0)
                rows.append([name, kernel, gather, f"{frame:.0f}", f"{extra:.0f}", f"{both.info['single']['ms']:.1f}",
                             f"{t_diff:.2f}", f"{t_both:.2f}"])
                print(rows[-1], file=sys.stderr, flush=True)
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", action="store_true", help="write docs/benchmarks/single_scattering.md")
    ap.add_argument("--spp", type=int, default=256, help="Mitsuba samples per pixel and seed (back-lit scenes)")
    ap.add_argument("--seeds", type=int, default=4, help="Mitsuba seeds (back-lit scenes)")
    args = ap.parse_args(argv)
    from dipole_gl.renderer import DipoleRenderer

    renderer = DipoleRenderer()
    page = Page("single_scattering", "The rivals' single-scattering term S1 against Mitsuba's single-scattering image")
    page.gl_renderer = renderer.gl_renderer
    page.para(
        "Jensen et al. 2001's single-scattering term S1 (`dipole_gl/single.py`, `docs/dipole_rivals.md` Sec. 11) "
        "rendered alone (`terms = single`) against Mitsuba cut after the first scattering vertex (`volpath` "
        "`max_depth = 2` index-matched, `mneevolpath` `max_depth = 4` behind a smooth dielectric; one depth less "
        "renders black, one more brighter: `benchmarks/single_refs.py --check-depths`). Cases: a suite scene with "
        f"its medium made grey, g = {single_refs.G}, at {single_refs.SIZE} x {single_refs.SIZE} "
        "(`benchmarks/single_refs.py`: the sphere sigma_t 8, the slab 6, albedo 0.95; `thick` is the slab three "
        "times thicker, 0.9 cm). Ratio: GL's mean over Mitsuba's over the pixels two pixels inside the fully covered "
        "footprint; SE: its standard error from the reference's seeds; within k SE: the share of those pixels with "
        "|GL - Mitsuba| <= k SE of the pixel. The approximations are bounded by refining each: march (64 against "
        "256 nodes), atlas (1024^2 against 2048^2 texels), pixel (the centre against 2 x 2 centres), straight line "
        "(at eta != 1 on a slab: the estimator against the same with the true refraction point). Tolerance = 3 SE + "
        "the four; `judged`: asserted by `tests/test_dipole_single.py`.")
    page.table(["case", "eta", "light", "ratio GL/Mitsuba", "SE", "within 2 SE", "within 3 SE", "march", "atlas",
                "pixel", "straight line", "tolerance", "within", "judged", "pixels"], validation(renderer))
    dof = int(single_refs.load_reference("sphere_front_eta1")["seeds"]) - 1
    page.para(
        f"With the references' seeds, a pixel's SE has {dof} degrees of freedom: noise alone puts "
        f"{2 * stats.t.cdf(2, dof) - 1:.3f} of the pixels within 2 SE and {2 * stats.t.cdf(3, dof) - 1:.3f} within 3 SE "
        "(Student's t). `slab_front_eta1` shows the march's limit: a 0.3 cm slab (1.8 mean free paths) lit from the "
        "camera's side, where the view ray leaves through the back face and the march, which does not know it, "
        "keeps gathering light behind the slab (the half-space assumption of Jensen et al.'s estimator). "
        "`sphere_front_eta13` is not judged: on a curved surface the estimator's two flat-interface approximations "
        "(the straight line to the light, the beam's spread through a plane) have no bound here, and what part of "
        "its difference each makes is not measured.")
    page.para(
        "Back light, the suite's back-lit scenes at their committed small size against their committed reference "
        f"(all orders of scattering; its fully covered pixels). Mitsuba's single scattering rendered here with "
        f"{args.spp} spp x {args.seeds} seeds; the dense standard dipole at the nightly's settings (`fit = coarsen`).")
    page.table(["scene", "S1 (Mitsuba) / truth", "S1 (GL) / truth", "S1 GL / Mitsuba", "dipole diffusion / truth",
                "dipole both / truth", "Mitsuba s"], backlit(renderer, args.spp, args.seeds))
    page.para(
        "What `terms = both` adds to the nightly's rival configurations at the committed small size: the frame's "
        "stages (ms, GL or host where the driver does not time compute work), the stages S1 adds (`single`: the "
        "light atlas and the march; for the vertex gather also its `gbuffer`), the twin's check of S1 (host ms), "
        "and the whole render with `terms = diffusion` and `both` (s, host, programs and precomputation warm).")
    page.table(["scene", "kernel", "gather", "frame ms (both)", "S1 stages ms", "S1 check ms", "render s (diffusion)",
                "render s (both)"], cost(renderer))
    page.finish(args.write)


if __name__ == "__main__":
    main()
