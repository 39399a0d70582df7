"""The time to a reference's noise target with specular manifold sampling split into a pass of its own.

``mneevolpath``'s sampled solutions (``[boundary] sms_trials``) carry a few per cent of a dielectric scene's
light and most of its render time; their light adds to the rest's as distinct paths, so a reference may render
them with one sample for every ``sms_split`` of the rest (:class:`harness.reference.jobs.RenderSetup`, tested
against the whole by ``tests/test_sms_split.py``). For each scene (``--scenes``, at its committed small size
and with its own sampling cap) and each split (``--splits``; 1 renders one pass), a reference of ``--spp``
samples per seed and 8 seeds is rendered twice with disjoint seeds: the first compiles the kernels (Dr.Jit
caches them), the second is timed. Its median relative standard error ``r`` (lit pixels, as the reference
measures it; the mean of ``r^2`` over the two renders) and wall time ``t`` give the time to any noise target,
``t r^2 / target^2`` (SE ~ 1/sqrt(samples)), as a ratio to the split of 1 measured in the same run.

Limits: one machine's ratio (the two parts' costs scale alike with the image size, not necessarily with the
device); ``r`` is a median over one set of 8 seeds, so each ratio carries its noise (about 15 % for ``r^2``
at 8 seeds); the render's spp per seed is small, so the sampled part's ``ceil(spp / split)`` rounding makes its
share of the samples larger than ``1 / split`` (the table gives the samples each part took).

Usage: ``.venv/bin/python benchmarks/bench_sms_split.py [--scenes A B ...] [--splits 1 4 16] [--spp 8]``
``[--write]``.
"""

import argparse
import tempfile
import time
from pathlib import Path

from harness.reference import committed
from harness.reference import mitsuba_scene as ms
from harness.reference.render import render_reference
from harness.scene import load_scene

SCENES = ("skin_torus_dielectric", "bunny_dielectric")
K = 8
#: The two renders' seeds: disjoint, so that their noise figures are independent.
SEED_BASES = (100, 1100)


def measure(scene, split, spp):
    """``(wall seconds of the timed render, mean r^2 of the two, the sampled part's samples per seed)``."""
    runs = []
    for seed_base in SEED_BASES:
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            meta = render_reference(scene, Path(tmp) / "ref", spp=spp, K=K, seed_base=seed_base,
                                    judge_exactness=False, sms_split=split)
            runs.append((time.perf_counter() - t0, float(meta["median_rel_se_subsurface"])))
    sampled = -(-spp // split) if split > 1 else spp
    return runs[1][0], (runs[0][1] ** 2 + runs[1][1] ** 2) / 2, sampled


def main():
    from page import Page

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", nargs="+", default=list(SCENES))
    ap.add_argument("--splits", nargs="+", type=int, default=[1, 4, 16])
    ap.add_argument("--spp", type=int, default=8, help="samples per seed of the rest's pass")
    ap.add_argument("--write", action="store_true", help="write docs/benchmarks/bench_sms_split.md")
    args = ap.parse_args()
    if 1 not in args.splits:
        raise SystemExit("error: --splits: 1 is missing; the ratios are to the reference rendered whole")
    ms.use_variant("llvm_ad_rgb")
    page = Page("bench_sms_split", "Specular manifold sampling in a pass of its own: the time to the noise target")
    page.para(
        f"Each scene at its committed small size with its own sampling cap; a reference of {args.spp} samples per "
        f"seed of the rest and {K} seeds, rendered twice with disjoint seeds (the second timed, the kernels "
        "compiled by the first). `r`: the median relative standard error over lit pixels (root of the mean "
        "`r^2` of the two renders); `time to target`: `t r^2`, as a ratio to the reference rendered whole (split 1) "
        "in the same run: below 1 is faster. Method and limits: `benchmarks/bench_sms_split.py`'s docstring.")
    rows = []
    for name in args.scenes:
        scene = committed.small_scene(load_scene(name))
        b = scene.boundary
        base = None
        for split in sorted(args.splits):
            wall, r2, sampled = measure(scene, split, args.spp)
            cost = wall * r2
            base = cost if split == 1 else base
            parts = f"{args.spp} / {sampled}" if split > 1 else f"{args.spp} (whole)"
            rows.append([scene.name, f"{b.sms_trials} ({b.sms_chains})", str(split), parts, f"{wall:.1f}",
                         f"{r2 ** 0.5:.4f}", f"{cost / base:.3f}"])
            print(rows[-1], flush=True)
    page.table(["scene", "sms_trials (chains)", "split", "spp per seed: rest / sampled", "wall [s]", "r",
                "time to target, to split 1"], rows)
    page.finish(args.write)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
