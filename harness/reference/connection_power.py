r"""The light ``mneevolpath``'s connections deliver into the medium, as one number per channel to hold against a light tracer.

For a point light the first-scattered power in the medium is

    P = int_V sigma_s(x) phi(x) dV,

with ``phi(x)`` the fluence the light delivers at ``x`` (for a delta light, the sum over the
connecting specular paths of ``I G T Tr``). :func:`delivered` estimates it with ``phi`` as
``mneevolpath`` computes it, by calling the integrator's own connection
(:meth:`harness.reference.mnee_connect.ManifoldConnections._connect`: the single refraction's
walk from the straight seed, the chains through 3, 5, ... crossings up to ``max_crossings``,
ratio-tracked transmittance) at points drawn uniformly inside the mesh (rejection from the medium's
box, inside by the parity of ray hits), ``P ~ |V| mean(sigma_s phi)`` with ``|V|`` the mesh's volume
(divergence theorem, :func:`harness.scene.geometry.signed_volume`; where the mesh leaves the box, the
box's volume times the share of its points inside), with its standard error. Drawing only inside
points rather than the whole box leaves out the zeros outside, whose variance would otherwise dominate
where the object fills a small part of its box (a torus). :func:`harness.reference.specular_paths.trace`
gives the same power by an independent route (photons from the light through every specular path); the
ratio of the two is the share of the light the connections deliver (:mod:`harness.reference.losses`).

What the comparison sees: every loss of the connections (single walks that fail or end on an
occluded solution while another solution exists, chains the straight seed does not lead to
or beyond ``max_crossings``, specular chains with a reflection vertex) as a shortfall, and an
error in the connection's value (geometry term, Fresnel, transmittance) as a difference of
either sign. Limits: point lights only; it weighs the medium by first scattering, not by
what the camera sees; the standard error is that of ``points`` points uniform inside the mesh
(held against the spread over seeds by ``tests/test_connection_power.py``, without specular manifold sampling).
With sampling the estimate at a point is ``f(X) N``, heavy-tailed where a solution's seeds rarely converge: a
few points carry much of a sampled chain's light, and a run that draws none of them is low with a small
standard error (independent runs against their own errors, and the top points' share:
``docs/benchmarks/mnee_sms_spread.md``).
"""

import numpy as np


def _inside(mi, dr, scene, x0, crossings=16):
    """Inside the closed mesh: an odd number of hits along +z (``crossings`` at most)."""
    count = mi.UInt32(0)
    o = mi.Point3f(x0)
    alive = mi.Bool(True)
    up = mi.Vector3f(0.0, 0.0, 1.0)
    for _ in range(crossings):
        si = scene.ray_intersect(mi.Ray3f(o, up), alive)
        alive &= si.is_valid()
        count += dr.select(alive, 1, 0)
        o = dr.select(alive, si.p + 1e-4 * dr.maximum(dr.max(dr.abs(si.p)), 1.0) * up, o)
    return (np.asarray(count) % 2) == 1


def _load(scene, variant, integrator):
    """``(mi, dr, mitsuba scene)`` of ``scene`` rendered by ``mneevolpath`` with ``integrator``'s parameters."""
    from harness.reference import mitsuba_scene as ms

    mi = ms.use_variant(variant)
    import drjit as dr

    d = ms.build_scene_dict(scene, max_depth=-1)
    if d["integrator"]["type"] != "mneevolpath":
        raise ValueError("connection_power: the scene's boundary is not a smooth dielectric")
    d["integrator"].update(integrator or {})
    return mi, dr, mi.load_dict(d)


def inside_points(scene, n, rng, loaded):
    """``(x, volume, share)``: ``n`` points uniform inside the mesh (rejection from the medium's box), the volume
    they stand for, and the share of the box's points that fell inside."""
    from harness.scene.geometry import signed_volume

    mi, dr, mscene = loaded
    m = scene.medium
    lo, hi = np.asarray(m.bbox_min, np.float64), np.asarray(m.bbox_max, np.float64)
    kept, drawn, have = [], 0, 0
    while have < n:
        c = lo + (hi - lo) * rng.random((max(2 * (n - have), 4096), 3))
        ins = _inside(mi, dr, mscene, point3f(mi, c))
        drawn += len(c)
        if not ins.any() and drawn > 64 * n:
            raise ValueError("connection_power: no point of the medium's box lies inside the mesh")
        kept.append(c[ins])
        have += int(ins.sum())
    x = np.concatenate(kept)[:n]
    share = have / drawn
    v = np.asarray(scene.mesh.vertices, np.float64)
    inside_box = np.all(v.min(0) >= lo - 1e-6 * (hi - lo)) and np.all(v.max(0) <= hi + 1e-6 * (hi - lo))
    volume = abs(float(signed_volume(scene.mesh))) if inside_box else float(np.prod(hi - lo)) * share
    return x, volume, share


def point3f(mi, a):
    """Positions (P, 3) as a Mitsuba ``Point3f`` (float32)."""
    a = np.asarray(a)
    return mi.Point3f(*[mi.Float(a[:, i].astype(np.float32)) for i in range(3)])


def medium_vertices(mi, dr, mscene, x, inside=None):
    """``(mei, inside)``: medium vertices at the points ``x`` (P, 3), in the object's interior medium where
    ``inside`` (by the parity of ray hits where it is not given), in none elsewhere."""
    x0 = point3f(mi, x)
    inside = _inside(mi, dr, mscene, x0) if inside is None else np.asarray(inside, bool)
    mei = dr.zeros(mi.MediumInteraction3f, len(x))
    mei.p = x0
    mei.t = mi.Float(0.0)
    mei.medium = dr.select(mi.Bool(inside), mscene.shapes()[0].interior_medium(), dr.zeros(mi.MediumPtr))
    return mei, inside


def connection_values(scene, x, inside=None, seed=0, variant="llvm_ad_rgb", integrator=None, loaded=None):
    """``mneevolpath``'s connection at points ``x`` (P, 3) of the medium, part by part.

    Returns ``(parts, inside)``: ``parts`` a list of (P, 3) arrays, the light each connection delivers
    at each point (irradiance perpendicular to its direction, ``I G T Tr``): the single refraction from
    the straight seed first, then the chains through 3, 5, ... crossings, then one per chain kind
    of specular manifold sampling (``integrator["sms_chains"]``, :mod:`harness.reference.mnee_sms`);
    ``inside`` (P,) where a point lies in the mesh (every point counts when given). ``integrator``:
    parameters of ``mneevolpath`` to set beside the scene's (e.g. ``{"sms_trials": 64}``); ``loaded``: the
    scene as :func:`_load` returned it (loaded here otherwise).
    """
    mi, dr, mscene = loaded or _load(scene, variant, integrator)
    integ = mscene.integrator()
    integ._prepare(mscene)
    mei, inside = medium_vertices(mi, dr, mscene, x, inside)
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(seed, len(x))
    value, _, _, extras, _ = integ._connect(mscene, sampler, mei, mei.medium, mi.Bool(inside), mi.UInt32(0),
                                            lambda w, a: mi.Float(0.0))
    parts = [value] + [v for v, _ in extras]
    return [np.stack([np.asarray(v[i], np.float64) for i in range(3)], 1) for v in parts], inside


def point_values(scene, points=1 << 18, seed=0, variant="llvm_ad_rgb", integrator=None):
    """``(f, share)``: ``f`` (parts, points, 3), each point's estimate ``|V| sigma_s phi`` of the first-scattered
    power, part by part in the order of :func:`connection_values`, at ``points`` points uniform inside the mesh
    (:func:`inside_points`, drawn with ``seed``); ``share`` the share of the medium's box inside it. The mean
    over points is :func:`delivered`'s power; the points themselves show how heavy its tail is
    (``benchmarks/mnee_sms_spread.py``)."""
    from harness.reference.specular_paths import _grid_lookup

    loaded = _load(scene, variant, integrator)
    x, volume, share = inside_points(scene, points, np.random.default_rng(seed), loaded)
    values, _ = connection_values(scene, x, inside=np.ones(len(x), bool), seed=seed, loaded=loaded)
    st, al = _grid_lookup(scene.medium, x)
    return volume * np.stack([st * al * phi for phi in values]), share


def delivered(scene, points=1 << 18, seed=0, variant="llvm_ad_rgb", integrator=None, parts=False):
    """``(power, se, inside_share)``: first-scattered power (3,) delivered by ``mneevolpath``'s connections.

    ``scene`` must have a smooth dielectric boundary (the integrator is ``mneevolpath``) and
    point lights. ``se`` is the standard error (3,) over the ``points`` points uniform inside the mesh
    (:func:`inside_points`); ``inside_share`` the share of the medium's box inside it.
    ``integrator``: as in :func:`connection_values`. ``parts=True`` returns ``power`` and ``se`` per
    part instead, (parts, 3) in the order of :func:`connection_values`.
    """
    f, share = point_values(scene, points, seed, variant, integrator)
    if not parts:
        f = f.sum(0, keepdims=True)
    power, se = f.mean(1), f.std(1, ddof=1) / np.sqrt(points)
    return (power, se, share) if parts else (power[0], se[0], share)
