"""What the exact reference leaves out behind a smooth dielectric: measured, recorded, and judged.

``mneevolpath`` (:mod:`harness.reference.mnee`) connects a medium vertex to a point light
through 1, 3, 5, ... crossings of the boundary, up to ``[boundary] max_crossings``
(:mod:`harness.reference.mnee_chain`). A connection whose straight seed segment crosses
more often, passes another shape, or whose chain walk fails is not made; its light is
estimated by the same connection along the straight seed with every dielectric treated as
index-matched (``I Tr / r^2`` times the phase function and the path's throughput: the exact
connection at eta -> 1, measured, not guessed). :func:`measure` renders the scene's passes
with the integrator's ``stats`` AOVs (:data:`LOSS_SEEDS` x :data:`LOSS_SPP` spp at the
reference's size) and returns, per colour channel:

* ``crossings``: the share of connections from medium vertices by the number of crossings
  of their seed segment (1, 3, 5, >= 7);
* ``single_walk_failed``: the share whose one-refraction walk did not converge (most start
  where no single refraction reaches, beyond the critical angle, and carry no light:
  :mod:`harness.reference.mnee`'s failure table; not counted as lost);
* ``chain_connected``, ``lost``, ``over_max``: the shares connected by a chain, not made
  although the path's length allowed it, and of those the ones over ``max_crossings``;
* ``lost_image_share`` and its standard error over the seeds: the estimated light of the
  lost connections over the image's light.

:func:`verdict`: the reference is exact when every channel's ``lost_image_share`` is at most
:data:`LOSS_FRACTION_OF_TARGET` of the reference's noise target (the median relative SE it
was rendered to); otherwise ``reference.json`` says ``"exact": false`` and why, and
:func:`check_exact` refuses to judge against it unless :data:`ALLOW_ENV` is set.

Limits: the estimate is the light of the straight seed, an approximation of the missed
path's (exact at eta -> 1; at larger eta the refracted chain may carry more or less, and a
chain with no solution carries none, so the estimate errs on the side of calling a
reference inexact). Light lost to the one-refraction walk's failures and to further
solutions is the lower bound of the ``probe_seeds`` diagnostics, not part of this estimate.
"""

import json
import os
from pathlib import Path

import numpy as np

from harness.errors import InputError

LOSS_SPP = 16
LOSS_SEEDS = 4
#: The lost light's share of the image may be at most this fraction of the noise target.
LOSS_FRACTION_OF_TARGET = 0.25
#: Set to 1 to judge against a reference that says it is not exact (explicit opt-in).
ALLOW_ENV = "SSLPV_ALLOW_INEXACT_REFERENCE"
BINS = ("1", "3", "5", ">=7")


def measure(scene, variant="llvm_ad_rgb", spp=LOSS_SPP, seeds=LOSS_SEEDS, seed_base=7_000_000):
    """Per-channel shares of the connections and the estimated lost light of ``scene`` (module docstring)."""
    from harness.reference import mitsuba_scene as ms
    from harness.reference.mnee import STATS_AOVS

    mi = ms.use_variant(variant)
    out = {}
    for channel in ms.channel_passes(scene.medium):
        d = ms.build_scene_dict(scene, channel=channel)
        d["integrator"].update(stats=True)
        mscene = mi.load_dict(d)
        per_seed = np.stack([np.asarray(mi.render(mscene, seed=seed_base + s, spp=spp), dtype=np.float64).sum((0, 1))
                             for s in range(seeds)])                      # (seeds, 3 + aovs)
        image, stats = per_seed[:, :3], dict(zip(STATS_AOVS, per_seed[:, 3:].T))
        total = {k: float(v.sum()) for k, v in stats.items()}
        started = total["mnee_started"]

        def share(key):
            return total[key] / started if started > 0 else 0.0

        for c in ((0, 1, 2) if channel is None else (channel,)):
            lost = stats["mnee_lost_" + "rgb"[c]]
            ratio = np.where(image[:, c] > 0, lost / np.where(image[:, c] > 0, image[:, c], 1.0), 0.0)
            out["RGB"[c]] = {
                # connections from medium vertices per camera sample (the AOVs are averages over samples)
                "connections_per_sample": started / seeds / max(1, scene.camera.width * scene.camera.height),
                "crossings": {b: share(k) for b, k in zip(BINS, ("mnee_cross1", "mnee_cross3", "mnee_cross5",
                                                                  "mnee_cross7_more"))},
                "single_walk_failed": 1.0 - share("mnee_converged") if started > 0 else 0.0,
                "chain_connected": share("mnee_chain_connected"),
                "lost": share("mnee_lost"),
                "over_max": share("mnee_over_max"),
                "lost_image_share": float(ratio.mean()),
                "lost_image_share_se": float(ratio.std(ddof=1) / np.sqrt(len(ratio))) if len(ratio) > 1 else None,
            }
    return {"spp": spp, "seeds": seeds, "max_crossings": int(scene.boundary.max_crossings), "channels": out}


def verdict(losses, target_rel_se):
    """``(exact, reason)``: exact when every channel's lost image share is <= LOSS_FRACTION_OF_TARGET x target."""
    limit = LOSS_FRACTION_OF_TARGET * float(target_rel_se)
    worst = max(losses["channels"].items(), key=lambda kv: kv[1]["lost_image_share"])
    name, ch = worst
    if ch["lost_image_share"] <= limit:
        return True, (f"exact: the connections not made carry an estimated {ch['lost_image_share']:.2%} of the image "
                      f"(channel {name}), at most {LOSS_FRACTION_OF_TARGET:g} x the noise target ({limit:.2%})")
    return False, (f"not exact: the connections not made (lost {ch['lost']:.2%} of them, {ch['over_max']:.2%} over "
                   f"max_crossings = {losses['max_crossings']}) carry an estimated {ch['lost_image_share']:.2%} of "
                   f"the image in channel {name}, more than {LOSS_FRACTION_OF_TARGET:g} x the noise target "
                   f"({limit:.2%})")


def check_exact(ref_dir):
    """Refuse (one line) a reference whose ``reference.json`` says ``"exact": false``, unless :data:`ALLOW_ENV` = 1."""
    meta_path = Path(ref_dir) / "reference.json"
    if not meta_path.is_file() or os.environ.get(ALLOW_ENV) == "1":
        return
    try:
        meta = json.loads(meta_path.read_text())
    except ValueError:
        return
    if meta.get("exact", True) is not False:
        return
    raise InputError(meta_path, "exact", f"{meta.get('exact_note', 'the reference is not exact')}; SSLPV is not "
                     "judged against it", f"raise [boundary] max_crossings and re-render it, or set {ALLOW_ENV}=1 "
                     "to judge against it anyway")
