r"""The light the exact reference misses, counted on the photons' own paths: which traced path does a connection find?

:mod:`harness.reference.losses` compares two powers, the first-scattered light traced from the
lights (:mod:`harness.reference.specular_paths`) and the light ``mneevolpath``'s connections deliver at
points inside the mesh (:mod:`harness.reference.connection_power`). With specular manifold sampling the
second is heavy-tailed: a sampled solution that a random seed finds with probability ``p`` is
delivered as ``f N`` with ``E[N] = 1 / p`` at the few points that find it, so its standard error falls
slowly, and a verdict near its limit needs more points than it may draw. This module estimates the
same shortfall on the photons instead, where nothing is weighted by ``1 / p``:

1. **Points on the photons' paths.** Photons are traced as :func:`harness.reference.specular_paths.trace`
   traces them, recording every segment inside the medium with its path (the boundary events from
   the light, their positions ``X``). On a segment of weight ``w`` and ``S`` sub-intervals of length
   ``h`` (the tracer's own first-scattering integral, nearest voxel), a point is drawn: sub-interval
   ``k`` with probability ``q_k`` proportional to its first-scattered power (mean over channels),
   then ``u`` uniform in it. Its weight per channel,

       W = w T_k alpha sigma_t exp(-sigma_t u) h / q_k                          (C1)

   (``T_k`` the transmittance to the sub-interval), has the segment's first-scattered power as its
   expectation. Every segment gets one point.
2. **Does the connection find the photon's path?** At each point ``x0`` the integrator's own code
   runs toward the photon's light (:meth:`harness.reference.mnee_connect.ManifoldConnections._seeded`:
   the straight seed, the single refraction's walk, the chains through 3, 5, ... crossings). The path
   ``X`` read from ``x0`` (the photon's events reversed: ``E`` and ``T`` are refractions ``T``, ``R`` a
   reflection inside, ``r`` one outside) is *covered*:

   * by the straight seed, where the walk with as many refractions connects a solution whose first
     vertex is ``X``'s (within :data:`harness.reference.mnee_sms.SAME`);
   * else, where the chain's kinds are among ``sms_chains`` and the straight seed's walk did not end at
     ``X`` (which sampling excludes), by specular manifold sampling with probability
     ``1 - (1 - p(X))^M`` (``M = sms_trials``): the expected weight of a sampled solution,
     ``p E[min(N, M)]`` (:mod:`harness.reference.mnee_sms` step 4). One run of the integrator's
     Bernoulli trials (:func:`harness.reference.mnee_sms._trials`) toward ``X`` gives an indicator with
     that mean.

   The indicator ``h`` is 0 or 1; nothing is divided by ``p``.
3. **The share missed**, per channel, a ratio over photons:

       m = sum W (1 - h) / sum W                                                (C2)

   with its standard error by the delta method over photons (each photon's points together one
   sample; the cone's stratification is ignored, which errs large).

Its noise: ``h`` is bounded, but the weights are the tracer's, which carry the shading-normal factor
(:func:`harness.reference.specular_paths.shading_normal_correction`, unbounded at grazing hits on a faceted
mesh). On the torus lit through its hole one photon that leaves and re-enters the ring at a grazing angle
carried much of a batch's missed light; such a tail makes a small sample read low with a small standard
error. So a limit is judged after at least :data:`MIN_PHOTONS` photons, and ``heaviest_share`` records how
much of the missed light the heaviest photon carries.

What it sees and what it does not: every path the connections do not find (reflection chains not
sampled, chains beyond ``max_crossings``, single walks that end on another solution, the capped
trials' share), in expectation the same shortfall as ``1 - delivered / traced``. It does not see an
error in the value of a connection that is found (geometry term, Fresnel, transmittance): that is the
power comparison's, and the tests' (:mod:`harness.reference.mnee`'s, against the half-space, the
index-matched limit and the area light). Limits: point lights only; the path's identity is judged by
its first vertex for the straight-seeded walks and by every vertex for the sampled ones; the
first-scattering weight is the tracer's (:mod:`harness.reference.specular_paths`, shading-normal
factor included).
"""

import numpy as np

#: Photons per batch; the fewest a limit is judged with (the photons' weights carry the shading-normal factor,
#: heavy-tailed at grazing hits on a faceted mesh: module docstring); the most, while the share is undecided.
PHOTONS = 1 << 16
MIN_PHOTONS = 1 << 18
MAX_PHOTONS = 1 << 20
#: The letters of a photon's events (from the light) as vertex kinds read from the medium vertex.
KIND_OF_EVENT = {"E": "T", "T": "T", "R": "R", "r": "r"}


def kinds_of(label):
    """The chain's vertex kinds from the medium vertex for a photon label: ``"ER"`` -> ``("R", "T")``."""
    return tuple(KIND_OF_EVENT[c] for c in reversed(label))


def draw_points(scene, record, rng):
    """A first-scatter point on each recorded segment (module docstring, step 1, Eq. C1).

    Returns a dict of ``x`` (P, 3), ``W`` (P, 3), ``label`` (P,), ``verts`` (a list: the path's positions from
    the light, (len(label), 3) each), ``light`` (P,) and ``photon`` (P,) (the light index times a large number
    plus the photon: one key per photon).
    """
    from harness.reference.specular_paths import SUBSTEPS, substeps

    out = {"x": [], "W": [], "label": [], "verts": [], "light": [], "photon": []}
    for batch in record:
        o, d, t, w = batch["o"], batch["d"], batch["t"], batch["w"]
        st, al, tr, tk = (np.stack(a, 1) for a in zip(*substeps(scene.medium, o, d, t)))   # (m, S, 3) each
        pbar = (w[:, None] * tr * al * (1.0 - tk)).mean(2)      # (m, S): sub-intervals' power, mean over channels
        seg_power = pbar.sum(1)
        idx = np.flatnonzero(seg_power > 0)
        if not len(idx):
            continue
        h = t[idx] / SUBSTEPS
        q = pbar[idx] / seg_power[idx, None]
        k = np.minimum((q.cumsum(1) < rng.random(len(idx))[:, None]).sum(1), SUBSTEPS - 1)
        qk = q[np.arange(len(idx)), k]
        u = rng.random(len(idx)) * h
        stk, alk, trk = st[idx, k], al[idx, k], tr[idx, k]
        out["W"].append(w[idx] * trk * alk * stk * np.exp(-stk * u[:, None]) * h[:, None] / qk[:, None])   # (C1)
        out["x"].append(o[idx] + (k * h + u)[:, None] * d[idx])
        out["label"].append(batch["label"][idx])
        out["verts"].extend(batch["verts"][idx])
        out["light"].append(np.full(len(idx), batch["light"]))
        out["photon"].append(batch["light"] * (1 << 40) + batch["pid"][idx])
    return {k: (v if k == "verts" else np.concatenate(v)) for k, v in out.items()}


def covered(scene, pts, seed=0, variant="llvm_ad_rgb", loaded=None):
    """``h`` (P,) bool: whether ``mneevolpath``'s connection at each point finds its photon's path (step 2)."""
    from harness.reference import connection_power
    from harness.reference import mnee_sms as sms

    mi, dr, mscene = loaded or connection_power._load(scene, variant, None)
    integ = mscene.integrator()
    integ._prepare(mscene)
    emitter_of = _emitter_indices(mi, mscene, scene)
    hit = np.zeros(len(pts["x"]), bool)
    labels = pts["label"]
    for label in np.unique(labels):
        idx = np.flatnonzero(labels == label)
        kinds = kinds_of(label)
        n = len(idx)
        mei, _ = connection_power.medium_vertices(mi, dr, mscene, pts["x"][idx], np.ones(n, bool))
        x0, active = mei.p, dr.full(mi.Bool, True, n)
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(seed + int(idx[0]), n)
        emitter = dr.gather(mi.EmitterPtr, mscene.emitters_dr(), mi.UInt32(emitter_of[pts["light"][idx]]))
        s = integ._seeded(mscene, sampler, mei, mei.medium, active, mi.UInt32(0), emitter, sampler.next_2d(), 1.0)
        verts = np.stack([pts["verts"][i] for i in idx])[:, ::-1]          # from x0: the events reversed
        ref = [connection_power.point3f(mi, verts[:, j]) for j in range(len(kinds))]
        found = dr.full(mi.Bool, False, n)
        excluded = dr.full(mi.Bool, False, n)
        if set(kinds) == {"T"} and len(kinds) in s["connected"]:
            x1, converged, conn = s["connected"][len(kinds)]
            same = sms._same([[x1]], ref[:1])
            found |= conn & same
            excluded = converged & same
        if integ.sms_trials and kinds in integ.sms_chains:
            lane = s["manifold"] & ~excluded
            _, capped = sms._trials(integ, mscene, sampler, x0, s["y"], kinds, s["eta"], s["shape_id"], ref,
                                    integ.sms_trials, lane)
            found |= lane & ~capped
        hit[idx] = np.asarray(found, bool)
    return hit


def _emitter_indices(mi, mscene, scene):
    """Mitsuba's emitter index for each of ``scene.lights`` (matched by position)."""
    it = mi.Interaction3f()
    it.p = mi.Point3f(0.0, 0.0, 0.0)
    positions = []
    for e in mscene.emitters():
        ds, _ = e.sample_direction(it, mi.Point2f(0.5, 0.5))
        positions.append(np.array([ds.p.x[0], ds.p.y[0], ds.p.z[0]], np.float64))
    out = []
    for light in scene.lights:
        dist = [np.linalg.norm(p - np.asarray(light.position, np.float64)) for p in positions]
        out.append(int(np.argmin(dist)))
    return np.asarray(out, np.uint32)


def _batch(scene, photons, seed, variant, loaded):
    """One batch: per photon the missed and the whole weight (Eq. C2's sums), and per label the drawn weight and
    the weight covered."""
    from harness.reference import specular_paths

    record = []
    specular_paths.trace(scene, photons=photons, seed=seed, record=record)
    pts = draw_points(scene, record, np.random.default_rng(seed + 17))
    h = covered(scene, pts, seed=seed, variant=variant, loaded=loaded)
    W = pts["W"]
    keys, group = np.unique(pts["photon"], return_inverse=True)
    a, b = np.zeros((len(keys), 3)), np.zeros((len(keys), 3))
    np.add.at(a, group, W * (~h)[:, None])
    np.add.at(b, group, W)
    labels = {str(lab): (W[pts["label"] == lab].sum(0), (W * h[:, None])[pts["label"] == lab].sum(0))
              for lab in np.unique(pts["label"])}
    return a, b, photons * len(scene.lights), labels, len(h)


def _ratio(batches):
    """Eq. C2 pooled over batches, its standard error by the delta method over photons (a photon with no point adds
    zeros to both sums), the whole weight (safe to divide by), and the heaviest photon's share of the missed."""
    a = np.concatenate([x[0] for x in batches])
    b = np.concatenate([x[1] for x in batches])
    n = sum(x[2] for x in batches)
    total, missed = b.sum(0), a.sum(0)
    safe = np.where(total > 0, total, 1.0)
    m = missed / safe
    se = np.sqrt(np.square(a - m * b).sum(0) * n / max(n - 1, 1)) / safe
    heaviest = np.where(missed > 0, a.max(0) / np.where(missed > 0, missed, 1.0), 0.0)
    return m, se, safe, heaviest


def missed(scene, photons=PHOTONS, seed=0, variant="llvm_ad_rgb", limit=None, max_photons=MAX_PHOTONS,
           min_photons=MIN_PHOTONS):
    """The first-scattered light the connections do not find, per channel, on the photons' paths (Eq. C2).

    Photons are traced in batches of ``photons`` (new seeds, pooled); with ``limit``, at least
    ``min_photons``, then more while a channel's share lies within
    :data:`harness.reference.losses.DECIDED_SE` standard errors of it, up to ``max_photons``.
    ``heaviest_share``: the largest share of the missed weight that one photon carries, per channel (the tail's
    weight: near 1 / (photons missed) where no photon dominates). Returns a dict: ``missed_share`` and ``missed_share_se``
    (lists of 3), ``points`` drawn, ``photons`` traced per light, and ``by_label``: each label's share of the
    drawn weight and the share of it covered (lists of 3).
    """
    from harness.reference import connection_power
    from harness.reference.losses import DECIDED_SE

    loaded = connection_power._load(scene, variant, None)
    batches = [_batch(scene, photons, seed, variant, loaded)]

    def undecided():
        m, se, _, _ = _ratio(batches)
        open_ = (m - DECIDED_SE * se <= limit) & (m + DECIDED_SE * se > limit)
        return bool(np.any(open_))

    while limit is not None and (len(batches) + 1) * photons <= max_photons and (
            len(batches) * photons < min(min_photons, max_photons) or undecided()):
        batches.append(_batch(scene, photons, seed + 1000 * len(batches), variant, loaded))
    m, se, safe, heaviest = _ratio(batches)
    by_label = {}
    for label in sorted({k for x in batches for k in x[3]}):
        w = sum(x[3][label][0] for x in batches if label in x[3])
        c = sum(x[3][label][1] for x in batches if label in x[3])
        by_label[label] = {"share": (w / safe).tolist(),
                           "covered": np.where(w > 0, c / np.where(w > 0, w, 1.0), 0.0).tolist()}
    return {"missed_share": m.tolist(), "missed_share_se": se.tolist(), "points": int(sum(x[4] for x in batches)),
            "photons": int(photons * len(batches)), "heaviest_share": heaviest.tolist(), "by_label": by_label}
