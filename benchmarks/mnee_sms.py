"""Specular manifold sampling against the photon tracer: the light of each chain, traced and delivered.

Per scene (``--scenes``; ``torus_hole`` at eta 1.4 and the scanned bunny behind its smooth dielectric by
default), the power that first scatters in the medium by the label of its specular path from the light
(:mod:`harness.reference.specular_paths`, ``--photons`` photons: ``E`` one refraction, ``ER`` enter and
reflect inside, ``rE`` reflect off the outside and enter, ``ETE`` through another part, ...) against the
same power as ``mneevolpath``'s connections deliver it (:func:`harness.reference.connection_power.delivered`
with ``parts``, ``--points`` uniform points): the straight seed's single refraction and chains, and each
chain of specular manifold sampling (:mod:`harness.reference.mnee_sms`, ``--chains``) at each cap on its
Bernoulli trials (``--trials``). A chain's label is its vertices read from the light (``T`` from ``x0``
is ``E`` where it enters the medium); the single refraction and the sampled ``T`` both deliver ``E``, the
straight-seeded chains and the sampled ``TTT`` both ``ETE``. Beside each delivery: its wall time over the
delivery without sampling, measured in the same run (each after a small delivery that compiles its kernels).

Usage: ``.venv/bin/python benchmarks/mnee_sms.py [--scenes torus_hole bunny_dielectric]``
``[--trials 64 1024] [--chains T,RT,Tr,TTT,RRT] [--points 131072] [--photons 65536] [--write]``.
"""

import argparse
import time

import numpy as np

from harness.reference import mitsuba_scene as ms
from harness.reference import nonconvex
from harness.scene import load_scene


def label_of(kinds):
    """A chain's photon label: its vertices from the light, a refraction into the medium ``E``."""
    from harness.reference.mnee_chain import sides

    return "".join(reversed([("E" if inside else "T") if k == "T" else k for k, inside in zip(kinds, sides(kinds))]))


def label_groups(chains):
    """``{label: {"straight": [part], "sampled": [part]}}``: the parts of :func:`connection_power.connection_values`
    that deliver each photon label (single refraction, straight-seeded chains, then one per sampled chain)."""
    groups = {"E": {"straight": [0], "sampled": []}, "ETE": {"straight": [1], "sampled": []}}
    for i, kinds in enumerate(chains):
        groups.setdefault(label_of(kinds), {"straight": [], "sampled": []})["sampled"].append(2 + i)
    return groups


def rgb(a, digits=3):
    return " / ".join(f"{v:.{digits}f}" for v in np.ravel(a))


def scene_named(name):
    return nonconvex.torus_hole(1.4) if name == "torus_hole" else load_scene(name)


def main():
    from page import Page

    from harness.reference import connection_power, specular_paths

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", nargs="+", default=["torus_hole", "bunny_dielectric"])
    ap.add_argument("--trials", type=int, nargs="+", default=[64, 1024])
    ap.add_argument("--chains", default="T,RT,Tr,TTT,RRT")
    ap.add_argument("--points", type=int, default=1 << 17)
    ap.add_argument("--photons", type=int, default=1 << 16)
    ap.add_argument("--write", action="store_true", help="write docs/benchmarks/mnee_sms.md")
    args = ap.parse_args()
    ms.use_variant("llvm_ad_rgb")
    from harness.reference.mnee_sms import parse_chains

    try:
        chains = parse_chains(args.chains)
    except ValueError as exc:
        ap.error(f"--chains: {exc}")
    page = Page("mnee_sms", "Specular manifold sampling against the photon tracer, chain by chain")
    page.para(
        "First-scattered power by the label of its specular path from the light, as shares of all the traced "
        f"power: traced ({args.photons} photons split at every boundary hit, `harness/reference/specular_paths.py`) "
        f"against delivered by `mneevolpath` ({args.points} uniform points, with the standard error; "
        "`harness/reference/connection_power.py`): the straight seed's connections, and the chains of specular "
        f"manifold sampling `{args.chains}` (`harness/reference/mnee_sms.py`) at each cap on their Bernoulli "
        "trials. Shares per channel R / G / B; `missed` is 1 - delivered / traced over every label.")
    for name in args.scenes:
        scene = scene_named(name)
        by = specular_paths.trace(scene, photons=args.photons)["by_label"]
        total = sum(by.values(), np.zeros(3))
        # each timed delivery follows a small one with the same kernels, so that compiling them is not timed
        connection_power.delivered(scene, points=1024, parts=True, seed=1)
        t0 = time.perf_counter()
        base, base_se, _ = connection_power.delivered(scene, points=args.points, parts=True)
        t_base = time.perf_counter() - t0
        runs = {}
        for m in args.trials:
            connection_power.delivered(scene, points=1024, parts=True, seed=1,
                                       integrator={"sms_trials": m, "sms_chains": args.chains})
            t0 = time.perf_counter()
            runs[m] = connection_power.delivered(scene, points=args.points, parts=True,
                                                 integrator={"sms_trials": m, "sms_chains": args.chains})[:2]
            runs[m] += (time.perf_counter() - t0,)
        groups = label_groups(chains)
        rows = []
        for lab, g in groups.items():
            traced = by.get(lab, np.zeros(3)) + (by.get("ETETE", np.zeros(3)) if lab == "ETE" else 0.0)
            row = [lab + (" (+ ETETE)" if lab == "ETE" else ""), rgb(traced / total)]
            row.append(f"{rgb(sum((base[i] for i in g['straight']), np.zeros(3)) / total)}")
            for m in args.trials:
                pw, se, _ = runs[m]
                idx = g["straight"] + g["sampled"]
                got = sum((pw[i] for i in idx), np.zeros(3))
                err = np.sqrt(sum((se[i] ** 2 for i in idx), np.zeros(3)))
                row.append(f"{rgb(got / total)} ± {rgb(err / total)}")
            rows.append(row)
        rest = total - sum((by.get(lab, np.zeros(3)) for lab in groups), np.zeros(3)) - by.get("ETETE", 0.0)
        rows.append(["(every other label)", rgb(rest / total), "–"] + ["–"] * len(args.trials))
        missed = [rgb(1 - base.sum(0) / total)]
        for m in args.trials:
            pw, se, t = runs[m]
            missed.append(f"{rgb(1 - pw.sum(0) / total)} ± {rgb(np.sqrt((se ** 2).sum(0)) / total)} "
                          f"({t / t_base:.1f} x the time)")
        rows.append(["missed", "–", missed[0]] + missed[1:])
        others = [k for k in sorted(by, key=lambda k: -by[k].sum()) if k not in groups and k != "ETETE"][:4]
        page.table(["label", "traced", "straight seed"] + [f"with sampling, cap {m}" for m in args.trials], rows,
                   note=f"{name} (eta {scene.boundary.eta:g}); delivery without sampling {t_base:.1f} s. The "
                        "largest other labels: " + ", ".join(f"{k} {rgb(by[k] / total)}" for k in others) + ".")
    page.finish(args.write)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
