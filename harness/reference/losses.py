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
  lost connections over the image's light;
* ``first_scatter``: the power that first scatters in the medium, traced from the point lights
  through every specular path (:func:`harness.reference.specular_paths.trace`, an independent
  route: batches of :data:`TRACE_PHOTONS` photons, whose weights take the shading-normal factor so
  that they carry the camera's transport, as the reference renders it), by class (``direct``: one refraction; ``chain3``,
  ``chain5`` ...: through other parts of the object; ``reflection``: any reflection on the
  way, which only the sampled chains of ``[boundary] sms_trials`` make), against the same power
  as the connections deliver it (:func:`harness.reference.connection_power.delivered`,
  :data:`DELIVERED_POINTS` points):
  ``missed_share = 1 - delivered / traced`` and its standard error (both routes' noise). It counts
  every loss of the connections at once: reflection vertices, single walks that end on another
  (occluded) solution than the one that carries the light, chains the straight seed does not lead to;
  and an error in the value of the connections made, of either sign.
* ``coverage``: the same share counted on the photons' own paths (:mod:`harness.reference.coverage`):
  at a first-scatter point of each traced segment, whether the integrator's connection finds that
  photon's path (by the straight seed, or by specular manifold sampling's trials within ``sms_trials``).
  Nothing there is weighted by the inverse probability of a sampled solution, so its standard error
  falls as a Bernoulli share's, not as a heavy tail's (both routes side by side, scene by scene:
  ``docs/benchmarks/reference_exactness.md``).

:func:`verdict`: the reference is exact when the two routes agree (:func:`consistent`, within
:data:`CONSISTENT_SE` combined standard errors: else the connections' value is in doubt) and every
channel's loss (the larger of ``lost_image_share`` and ``coverage.missed_share``, or
``first_scatter.missed_share`` in a reference measured before ``coverage``) is at most
:data:`LOSS_FRACTION_OF_TARGET` of the reference's noise target (the median relative SE it
was rendered to); otherwise ``reference.json`` says ``"exact": false`` and why, and
:func:`check_exact` refuses to judge against it unless :data:`ALLOW_ENV` is set.

Limits: the estimate is the light of the straight seed, an approximation of the missed
path's (exact at eta -> 1; at larger eta the refracted chain may carry more or less, and a
chain with no solution carries none, so the estimate errs on the side of calling a
reference inexact). ``missed_share`` weighs the medium by where light first scatters, not by
what the camera sees, and is a share of that light, not of the image (on the torus lit through
its hole the image's shortfall in the area-light limit is 0.03-0.08 larger than this one
predicts, about 2 SE per channel: ``docs/benchmarks/mnee_chains.md``); it covers point lights
only. Its standard error holds both routes' noise: the delivered power's over points drawn inside
the mesh, and the traced total's over the photons' stratified directions (each checked against the
spread over seeds: ``tests/test_connection_power.py``, ``tests/test_specular_paths.py``); with specular
manifold sampling the delivered power is heavy-tailed (a few points carry much of a sampled chain's light,
``docs/benchmarks/mnee_sms_spread.md``), so a batch that draws none of them reads a larger loss with a
small standard error, one that draws one a smaller loss with a larger standard error. A loss
within :data:`DECIDED_SE` standard errors of the limit after :data:`MAX_DELIVERED_POINTS` points is
"undecided" and judged not exact.
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
TRACE_PHOTONS = 1 << 16
#: With a limit, photons are traced in batches of TRACE_PHOTONS until the traced total's standard error is at
#: most an eighth of the limit (relative), or until this many photons.
MAX_TRACE_PHOTONS = 1 << 20
DELIVERED_POINTS = 1 << 18
#: The delivered power is measured in batches of DELIVERED_POINTS until its standard error is at most a
#: quarter of the limit it is judged against, or until this many points.
MAX_DELIVERED_POINTS = 1 << 22
#: A loss is decided when it lies this many standard errors below (exact) or above (not exact) the limit.
DECIDED_SE = 2.0


def measure(scene, variant="llvm_ad_rgb", spp=LOSS_SPP, seeds=LOSS_SEEDS, seed_base=7_000_000, limit=None):
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
    from harness.reference import coverage

    # The photons' paths decide the share missed (light-tailed); the power comparison, one batch, checks the
    # connections' value against it (:func:`consistent`).
    return {"spp": spp, "seeds": seeds, "max_crossings": int(scene.boundary.max_crossings), "channels": out,
            "coverage": coverage.missed(scene, variant=variant, limit=limit),
            "first_scatter": first_scatter(scene, variant)}


def _traced(scene, photons, seed, limit, max_photons):
    """The photon tracer's result, pooled over batches of ``photons`` (new seeds) while, with ``limit``, the traced
    total's relative standard error exceeds ``limit / 8``, up to ``max_photons``."""
    from harness.reference import specular_paths

    batches = [specular_paths.trace(scene, photons=photons, seed=seed)]

    def pooled():
        n = len(batches)
        out = {}
        for key in ("by_label", "by_class"):
            names = {k for b in batches for k in b[key]}
            out[key] = {k: sum(b[key].get(k, np.zeros(3)) for b in batches) / n for k in names}
        out["total_se"] = np.sqrt(sum(np.square(b.get("total_se", np.zeros(3))) for b in batches)) / n
        out["photons"] = photons * n
        return out

    def too_noisy():
        p = pooled()
        total = sum(p["by_class"].values(), np.zeros(3))
        return bool(np.any(p["total_se"] > limit / 8 * np.where(total > 0, total, np.inf)))

    while limit is not None and (len(batches) + 1) * photons <= max_photons and too_noisy():
        batches.append(specular_paths.trace(scene, photons=photons, seed=seed + 1000 + len(batches)))
    return pooled()


def first_scatter(scene, variant="llvm_ad_rgb", photons=TRACE_PHOTONS, points=DELIVERED_POINTS, seed=0, limit=None,
                  max_points=MAX_DELIVERED_POINTS, max_photons=MAX_TRACE_PHOTONS):
    """The first-scattered power traced through every specular path against what the connections deliver.

    Returns per channel (lists of 3): ``traced`` by class, ``delivered`` and its ``delivered_se``,
    ``missed_share = 1 - delivered / traced`` with ``missed_share_se``, and the ``reflection_share``
    and ``chains_over_max_share`` of the traced power (module docstring). With ``limit`` (the share
    the loss is judged against), batches of ``points`` are added (new seeds, pooled) while a channel's
    missed share lies within :data:`DECIDED_SE` standard errors of the limit, until the largest
    ``missed_share_se`` is at most ``limit / 4`` or ``max_points`` points were drawn, so that
    :func:`verdict` can decide; photons are traced in batches of ``photons`` until the traced total's
    relative standard error is at most ``limit / 8`` or ``max_photons`` were traced.
    """
    from harness.reference import connection_power, specular_paths

    traced = _traced(scene, photons, seed, limit, max_photons)
    part = specular_paths.shares(traced, int(scene.boundary.max_crossings))
    total = part["total"]
    safe = np.where(total > 0, total, 1.0)
    total_se = np.asarray(traced.get("total_se", np.zeros(3)), float)

    def missed_se(got, se):
        """The standard error of ``1 - got / total``: the delivered power's and the traced total's."""
        return np.sqrt(np.square(se / safe) + np.square(got * total_se / safe ** 2))
    batches = [connection_power.delivered(scene, points=points, seed=seed, variant=variant)[:2]]

    def pooled():
        return sum(g for g, _ in batches) / len(batches), np.sqrt(sum(s ** 2 for _, s in batches)) / len(batches)

    def undecided():
        got, se = pooled()
        missed, m_se = np.where(total > 0, 1.0 - got / safe, 0.0), missed_se(got, se)
        open_ = (missed - DECIDED_SE * m_se <= limit) & (missed + DECIDED_SE * m_se > limit)
        return bool(np.any(open_)) and float(np.max(m_se)) > limit / 4

    while limit is not None and len(batches) * points < max_points and undecided():
        batches.append(connection_power.delivered(scene, points=points, seed=seed + len(batches), variant=variant)[:2])
    got, se = pooled()
    points = points * len(batches)
    return {"photons": traced["photons"], "points": points,
            "traced": {k: v.tolist() for k, v in traced["by_class"].items()},
            "delivered": got.tolist(), "delivered_se": se.tolist(),
            "missed_share": np.where(total > 0, 1.0 - got / safe, 0.0).tolist(),
            "missed_share_se": missed_se(got, se).tolist(), "traced_se": total_se.tolist(),
            "reflection_share": part["reflection"].tolist(),
            "chains_over_max_share": part["chains_over_max"].tolist()}


def _missed_route(losses):
    """The measurement of the first-scattered light missed that the verdict decides with: the photons' paths
    (``coverage``) where recorded, else the power comparison (``first_scatter``, older references), else None."""
    return losses.get("coverage") or losses.get("first_scatter")


def channel_loss(losses, name):
    """``(loss, which)``: the larger of a channel's ``lost_image_share`` and first-scatter ``missed_share``."""
    ch = losses["channels"][name]
    fs = _missed_route(losses)
    missed = fs["missed_share"]["RGB".index(name)] if fs else 0.0
    if missed > ch["lost_image_share"]:
        on = " (on the photons' paths)" if "coverage" in losses else ""
        return missed, "first-scattered light the connections miss" + on
    return ch["lost_image_share"], "image light of the connections not made"


def _decided(losses, name):
    """``(loss, se)`` of a channel as judged: the first-scattered light missed with its standard error where it
    is the larger loss, else the lost image share (whose light estimate has no bias toward exact)."""
    loss, which = channel_loss(losses, name)
    fs = _missed_route(losses)
    if fs and which.startswith("first-scattered") and "missed_share_se" in fs:
        return loss, float(fs["missed_share_se"]["RGB".index(name)])
    return loss, 0.0


#: The power comparison and the photons' paths disagree when their missed shares differ by more than this many
#: combined standard errors: the connections' value (not their reach) is then in doubt.
CONSISTENT_SE = 3.0


def consistent(losses):
    """``(ok, reason)``: where both routes are recorded, whether ``1 - delivered / traced`` agrees with the share
    missed on the photons' paths within :data:`CONSISTENT_SE` combined standard errors in every channel. The two
    estimate the same share when every connection found carries the light of its path; a difference is an error
    of the connections' value (geometry term, Fresnel, transmittance) or of one route."""
    cov, fs = losses.get("coverage"), losses.get("first_scatter")
    if not cov or not fs or "missed_share_se" not in fs:
        return True, ""
    worst = None
    for c in range(3):
        se = float(np.hypot(cov["missed_share_se"][c], fs["missed_share_se"][c]))
        z = (fs["missed_share"][c] - cov["missed_share"][c]) / se if se > 0 else 0.0
        if abs(z) > CONSISTENT_SE and (worst is None or abs(z) > abs(worst[1])):
            worst = ("RGB"[c], z)
    if worst is None:
        return True, ""
    c = "RGB".index(worst[0])
    return False, (f"not exact: the connections' power misses {fs['missed_share'][c]:.2%} ± "
                   f"{fs['missed_share_se'][c]:.2%} of the traced light but the photons' paths they do not find "
                   f"carry {cov['missed_share'][c]:.2%} ± {cov['missed_share_se'][c]:.2%} (channel {worst[0]}, "
                   f"{worst[1]:+.1f} standard errors, more than {CONSISTENT_SE:g}): the value of the connections "
                   "found is in doubt")


def verdict(losses, target_rel_se):
    """``(exact, reason)``: exact when every channel's loss is at most LOSS_FRACTION_OF_TARGET x target by
    :data:`DECIDED_SE` standard errors of its measurement; a loss within that band of the limit is undecided
    and judged not exact (the reason says so)."""
    limit = LOSS_FRACTION_OF_TARGET * float(target_rel_se)
    ok, why = consistent(losses)
    if not ok:
        return False, why

    def upper(c):
        loss, se = _decided(losses, c)
        return loss + DECIDED_SE * se

    name = max(losses["channels"], key=upper)
    ch = losses["channels"][name]
    loss, which = channel_loss(losses, name)
    _, se = _decided(losses, name)
    fs = losses.get("first_scatter")
    refl = f", {fs['reflection_share']['RGB'.index(name)]:.2%} of it through reflections" if fs else ""
    route = _missed_route(losses)
    pm = f" ± {se:.2%}" if se else ""
    if loss + DECIDED_SE * se <= limit:
        return True, (f"exact: the connections miss an estimated {loss:.2%}{pm} ({which}, channel {name}), at most "
                      f"{LOSS_FRACTION_OF_TARGET:g} x the noise target ({limit:.2%})")
    if loss - DECIDED_SE * se <= limit:
        return False, (f"not exact (undecided): the connections miss an estimated {loss:.2%}{pm} ({which}, channel "
                       f"{name}{refl}), within {DECIDED_SE:g} standard errors of {LOSS_FRACTION_OF_TARGET:g} x the "
                       f"noise target ({limit:.2%}) after {route['points'] if route else 0} points")
    return False, (f"not exact: the connections miss an estimated {loss:.2%}{pm} ({which}, channel {name}{refl}; "
                   f"connections not made {ch['lost']:.2%}, {ch['over_max']:.2%} over max_crossings = "
                   f"{losses['max_crossings']}), more than {LOSS_FRACTION_OF_TARGET:g} x the noise target "
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
                     "judged against it", f"raise [boundary] max_crossings or set [boundary] sms_trials = 256 (chains "
                     f"with a reflection, further solutions) and re-render it, or set {ALLOW_ENV}=1 to judge against "
                     "it anyway")
