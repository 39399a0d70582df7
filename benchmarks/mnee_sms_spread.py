"""How far one delivery of the connections' light can be trusted: independent runs, their spread, and the tail.

The exactness verdict (:mod:`harness.reference.losses`) holds the light ``mneevolpath``'s connections deliver
into the medium (:func:`harness.reference.connection_power.delivered`: a mean over points uniform inside
the mesh, with its standard error) against the photon tracer's. A sampled chain's estimate at a point is
``f(X) N`` (:mod:`harness.reference.mnee_sms`): where a solution is found by few seeds, the first walk
rarely reaches it and ``N`` is large when it does, so a few points carry much of a chain's light and a run
that draws none of them is low with a small standard error. This page measures that, per scene and label
(labels as in ``benchmarks/mnee_sms.py``): the traced share (``--photons`` photons), then ``--seeds``
independent deliveries of ``--points`` points each at the cap ``--trials`` on the chains ``--chains``
(default: the scene's), each with its own standard error; their pooled mean with the pooled standard error
and with the standard error of the runs' spread; and the share of the light of the label's sampled chains
carried by the top :data:`TOP` of the pooled points. A spread larger than the runs' own standard errors, or a top share
far above :data:`TOP`, says that a single run's standard error understates its error.

Usage: ``.venv/bin/python benchmarks/mnee_sms_spread.py [--scenes bunny_dielectric]``
``[--trials 256] [--chains T,RT,Tr,TTT] [--seeds 4] [--points 524288] [--photons 1048576] [--write]``.
"""

import argparse
import time

import numpy as np
from mnee_sms import label_groups, rgb, scene_named

from harness.reference import mitsuba_scene as ms

#: The share of the points whose light the page reports (the heaviest ones).
TOP = 1e-4


def top_share(f):
    """Per channel, the share of ``sum(f)`` (points, 3) carried by the largest :data:`TOP` of the points."""
    k = max(1, int(round(TOP * len(f))))
    top = -np.sort(-f, axis=0)[:k].sum(0)
    total = f.sum(0)
    return np.where(total > 0, top / np.where(total > 0, total, 1.0), 0.0)


def spread(means):
    """The mean of independent runs' means (runs, 3) and the standard error from their spread."""
    means = np.asarray(means)
    return means.mean(0), means.std(0, ddof=1) / np.sqrt(len(means))


def main():
    from page import Page

    from harness.reference import connection_power, specular_paths

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", nargs="+", default=["bunny_dielectric"])
    ap.add_argument("--trials", type=int, default=256)
    ap.add_argument("--chains", default=None, help="sms_chains (default: the scene's)")
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--points", type=int, default=1 << 19)
    ap.add_argument("--photons", type=int, default=1 << 20)
    ap.add_argument("--write", action="store_true", help="write docs/benchmarks/mnee_sms_spread.md")
    args = ap.parse_args()
    if args.seeds < 2:
        ap.error("--seeds: at least 2 runs are needed for a spread")
    ms.use_variant("llvm_ad_rgb")
    from harness.reference.mnee_sms import parse_chains

    page = Page("mnee_sms_spread", "One delivery of the connections' light: independent runs, spread and tail")
    page.para(
        f"First-scattered power by photon label as shares of all the traced power ({args.photons} photons, "
        "`harness/reference/specular_paths.py`), against the same power delivered by `mneevolpath`'s "
        f"connections (`harness/reference/connection_power.py`) in {args.seeds} independent runs of "
        f"{args.points} points, specular manifold sampling at cap {args.trials}. Per run: its share ± its own "
        "standard error. `pooled`: every run's points together, ± the pooled standard error / ± the standard "
        f"error of the runs' spread. `top {100 * TOP:g} %`: the share of the light of the label's sampled "
        "chains (every sampled chain in the last row), pooled, carried by that share of the points. Shares per channel R / G / B.")
    for name in args.scenes:
        scene = scene_named(name)
        chains_text = args.chains or scene.boundary.sms_chains
        try:
            chains = parse_chains(chains_text)
        except ValueError as exc:
            ap.error(f"--chains: {exc}")
        integ = {"sms_trials": args.trials, "sms_chains": chains_text}
        t0 = time.perf_counter()
        by = specular_paths.trace(scene, photons=args.photons, seed=11)["by_label"]
        total = sum(by.values(), np.zeros(3))
        runs = [connection_power.point_values(scene, points=args.points, seed=100 + s, integrator=integ)[0]
                for s in range(args.seeds)]
        groups = label_groups(chains)
        rows = []
        for lab, g in list(groups.items()) + [("every label", None)]:  # ETE with ETETE, as on mnee_sms
            idx = slice(None) if g is None else g["straight"] + g["sampled"]
            per = [f[idx].sum(0) / total for f in runs]            # (points, 3) per run, as shares
            means = [p.mean(0) for p in per]
            ses = [p.std(0, ddof=1) / np.sqrt(len(p)) for p in per]
            pooled = np.concatenate(per)
            mean, spread_se = spread(means)
            traced = total if g is None else by.get(lab, np.zeros(3)) + (by.get("ETETE", 0.0) if lab == "ETE" else 0.0)
            sampled = slice(2, None) if g is None else g["sampled"]
            tail = top_share(np.concatenate([f[sampled].sum(0) for f in runs])) if (g is None or g["sampled"]) else None
            rows.append([lab, rgb(traced / total, 4)] + [f"{rgb(m, 4)} ± {rgb(s, 4)}" for m, s in zip(means, ses)]
                        + [f"{rgb(mean, 4)} ± {rgb(pooled.std(0, ddof=1) / np.sqrt(len(pooled)), 4)} / "
                           f"± {rgb(spread_se, 4)}", "–" if tail is None else rgb(tail, 2)])
        page.table(["label", "traced"] + [f"run {s + 1}" for s in range(args.seeds)] + ["pooled", f"top {100 * TOP:g} %"],
                   rows, note=f"{name} (eta {scene.boundary.eta:g}, chains {chains_text}); "
                              f"{time.perf_counter() - t0:.0f} s in all.")
    page.finish(args.write)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
