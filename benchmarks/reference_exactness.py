"""The exactness verdict on every smooth-dielectric scene: as its committed reference was rendered, and sampled.

For each scene (``--scenes``; by default every suite scene behind a smooth dielectric, and the
non-convex validation scene :func:`harness.reference.nonconvex.torus_hole`), :func:`harness.reference.losses.first_scatter` and
:func:`harness.reference.losses.verdict` against the scene's small-reference noise target, with the
reference's connections set three ways:

* ``committed``: as the scene's committed small reference was rendered (``reference.json``'s
  integrator block: where it names no ``max_crossings``, it predates the chains and connected
  through one crossing only; where it names no ``sms_trials``, without sampling);
* ``chains``: the scene's own boundary without specular manifold sampling (``sms_trials = 0``);
* ``sampled``: with sampling, ``sms_trials`` = ``--trials`` (or the scene's own, where it sets one) and
  the scene's ``sms_chains`` (:data:`SAMPLED_CHAINS` where it sets none), or ``--chains`` where given.

The loss is the share of the first-scattered light on the paths the connections do not find
(:mod:`harness.reference.coverage`: photons traced in batches of 65536, at least 2^18, more while undecided,
up to 2^20; beside it the largest share of the missed light that one photon carries),
decided beyond two standard errors of a quarter of the noise target; ``undecided`` is judged not
exact. Beside it, the same share by power, ``1 - delivered / traced`` (one batch of points inside the
mesh: :func:`harness.reference.losses.first_scatter`), which must agree with it within
:data:`harness.reference.losses.CONSISTENT_SE` combined standard errors (``routes disagree``
otherwise); and what each took.

Usage: ``.venv/bin/python benchmarks/reference_exactness.py [--scenes A B ...] [--trials 256]``
``[--chains T,RT,Tr,TTT] [--ways committed chains sampled] [--write]``.
"""

import argparse
import dataclasses
import json
import time

import numpy as np

from harness.paths import REPO
from harness.reference import coverage, losses
from harness.reference import mitsuba_scene as ms
from harness.reference import nonconvex
from harness.scene import load_scene, scene_hash

VALIDATION = ("torus_hole",)

WAYS = ("committed", "chains", "sampled")
#: The chains sampled where the scene names none: on the torus lit through its hole, light that enters and
#: reflects two to four times inside (``ERR``, ``ERRR``, ``ERRRR``: ``docs/benchmarks/mnee_sms.md`` names the
#: last two among the largest labels no default chain delivers, 0.8 % of the red light together) too.
SAMPLED_CHAINS = {"torus_hole": "T,RT,Tr,TTT,RRT,RRRT,RRRRT"}


def scene_named(name):
    return nonconvex.torus_hole(1.4) if name == "torus_hole" else load_scene(name)


def committed_boundary(name, boundary):
    """The boundary as the committed small reference was rendered, or None where there is none."""
    meta = REPO / "baselines" / "refs" / name.split("/")[-1] / "reference.json"
    if not meta.is_file():
        return None
    blocks = ms.integrator_blocks(json.loads(meta.read_text()).get("integrator", {}))
    connections = [{k: v for k, v in b.items() if k != "rr_depth"} for b in blocks]
    if any(c != connections[0] for c in connections):   # one grey pass per channel: the same connections in each
        raise ValueError(f"{meta}: integrator: the channels' passes were rendered with different connections")
    integ = blocks[0]
    return dataclasses.replace(boundary, max_crossings=int(integ.get("max_crossings", 1)),
                               sms_trials=int(integ.get("sms_trials", 0)),
                               sms_chains=str(integ.get("sms_chains", boundary.sms_chains)))


def with_boundary(scene, boundary):
    out = dataclasses.replace(scene, boundary=boundary)
    return dataclasses.replace(out, content_hash=scene_hash(out))


def pct(a):
    return " / ".join(f"{100 * v:.2f}" for v in np.ravel(a))


def main():
    from page import Page

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", nargs="+", default=ms.smooth_suite_scenes() + list(VALIDATION))
    ap.add_argument("--trials", type=int, default=256)
    ap.add_argument("--chains", default=None, help="sms_chains for the sampled way (default: the scene's)")
    ap.add_argument("--ways", nargs="+", choices=WAYS, default=list(WAYS))
    ap.add_argument("--write", action="store_true", help="write docs/benchmarks/reference_exactness.md")
    args = ap.parse_args()
    ms.use_variant("llvm_ad_rgb")
    page = Page("reference_exactness", "Is the reference exact? The verdict on each smooth-dielectric scene")
    page.para(
        "The share of the first-scattered light that `mneevolpath`'s connections miss, in per cent per channel "
        "R / G / B with its standard error, two ways: on the photons' paths (`harness/reference/coverage.py`: at a "
        "first-scatter point of every traced segment, whether the connection finds that photon's path; photons in "
        f"batches of {coverage.PHOTONS}, at least {coverage.MIN_PHOTONS}, more while undecided, up to "
        f"{coverage.MAX_PHOTONS}; `heaviest` is the largest share of the missed light one photon carries, R / G / B), "
        "which the verdict decides with, and by power (`1 - delivered / traced`, `harness/reference/losses.py`: photons traced through every "
        f"specular path, {losses.TRACE_PHOTONS}, against the connections' power at {losses.DELIVERED_POINTS} points "
        "inside the mesh), which must agree with it within "
        f"{losses.CONSISTENT_SE:g} combined standard errors; and the verdict against a quarter of the scene's "
        "small-reference noise target. `committed`: the connections as the committed small reference was rendered (its `reference.json`; "
        "one crossing where it names no `max_crossings`); `chains`: the scene's boundary without sampling; "
        f"`sampled`: with specular manifold sampling, `sms_trials` {args.trials} unless the scene sets its own.")
    rows = []
    for name in args.scenes:
        scene = scene_named(name)
        target = float(scene.tolerances.get("small_reference_rel_se") or scene.tolerances.get("reference_rel_se"))
        limit = losses.LOSS_FRACTION_OF_TARGET * target
        b = scene.boundary
        ways = {"committed": committed_boundary(name, b),
                "chains": dataclasses.replace(b, sms_trials=0),
                "sampled": dataclasses.replace(b, sms_trials=int(b.sms_trials or args.trials),
                                               sms_chains=args.chains or (b.sms_chains if b.sms_trials else
                                                                          SAMPLED_CHAINS.get(name, b.sms_chains)))}
        for way in args.ways:
            bound = ways[way]
            if bound is None:
                rows.append([name, way, "–", "–", "–", "–", "no committed reference"])
                continue
            t0 = time.perf_counter()
            cov = coverage.missed(with_boundary(scene, bound), limit=limit)
            t1 = time.perf_counter()
            fs = losses.first_scatter(with_boundary(scene, bound))
            t2 = time.perf_counter()
            judged = {"channels": {c: {"lost_image_share": 0.0, "lost": 0.0, "over_max": 0.0} for c in "RGB"},
                      "coverage": cov, "first_scatter": fs, "max_crossings": bound.max_crossings}
            exact, note = losses.verdict(judged, target)
            verdict = "exact" if exact else ("undecided" if "undecided" in note else "not exact")
            if not losses.consistent(judged)[0]:
                verdict = "routes disagree"
            setting = f"max_crossings {bound.max_crossings}" + (
                f", sms_trials {bound.sms_trials} ({bound.sms_chains})" if bound.sms_trials else "")
            rows.append([name, f"{way}: {setting}", f"{pct(cov['missed_share'])} ± {pct(cov['missed_share_se'])}",
                         f"{cov['photons']} / {pct(cov['heaviest_share'])} / {t1 - t0:.0f}",
                         f"{pct(fs['missed_share'])} ± {pct(fs['missed_share_se'])}", f"{fs['points']} / {t2 - t1:.0f}",
                         f"{verdict} (limit {100 * limit:.2f})"])
            print(rows[-1], flush=True)
    page.table(["scene", "connections", "missed on the photons' paths [%]", "photons / heaviest [%] / wall [s]",
                "missed by power [%]", "points / wall [s]", "verdict"], rows,
               note="A scene whose committed way is not exact has a committed reference darker than its scene by "
                    "about the missed share where light first scatters; `sslpv-harness baselines "
                    "regenerate-references` renders it with the scene's own boundary.")
    page.finish(args.write)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
