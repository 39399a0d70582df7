r"""The light ``mneevolpath``'s connections deliver into the medium, as one number per channel to hold against a light tracer.

For a point light the first-scattered power in the medium is

    P = int_V sigma_s(x) phi(x) dV,

with ``phi(x)`` the fluence the light delivers at ``x`` (for a delta light, the sum over the
connecting specular paths of ``I G T Tr``). :func:`delivered` estimates it with ``phi`` as
``mneevolpath`` computes it, by calling the integrator's own connection
(:meth:`harness.reference.mnee_connect.ManifoldConnections._connect`: the single refraction's
walk from the straight seed, the chains through 3, 5, ... crossings up to ``max_crossings``,
ratio-tracked transmittance) at points drawn uniformly in the medium's box (zero outside the
mesh; inside by the parity of ray hits), ``P ~ |box| mean(sigma_s phi 1_inside)``, with its
standard error. :func:`harness.reference.specular_paths.trace` gives the same power by an
independent route (photons from the light through every specular path); the ratio of the two
is the share of the light the connections deliver (:mod:`harness.reference.losses`).

What the comparison sees: every loss of the connections (single walks that fail or end on an
occluded solution while another solution exists, chains the straight seed does not lead to
or beyond ``max_crossings``, specular chains with a reflection vertex) as a shortfall, and an
error in the connection's value (geometry term, Fresnel, transmittance) as a difference of
either sign. Limits: point lights only; it weighs the medium by first scattering, not by
what the camera sees; the standard error is that of ``points`` uniform points (the estimate
is noisier where the medium fills little of its box).
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


def connection_values(scene, x, inside=None, seed=0, variant="llvm_ad_rgb", integrator=None):
    """``mneevolpath``'s connection at points ``x`` (P, 3) of the medium, part by part.

    Returns ``(parts, inside)``: ``parts`` a list of (P, 3) arrays, the light each connection delivers
    at each point (irradiance perpendicular to its direction, ``I G T Tr``): the single refraction from
    the straight seed first, then the chains through 3, 5, ... crossings, then one per chain kind
    of specular manifold sampling (``integrator["sms_chains"]``, :mod:`harness.reference.mnee_sms`);
    ``inside`` (P,) where a point lies in the mesh (every point counts when given). ``integrator``:
    parameters of ``mneevolpath`` to set beside the scene's (e.g. ``{"sms_trials": 64}``).
    """
    from harness.reference import mitsuba_scene as ms

    mi = ms.use_variant(variant)
    import drjit as dr

    d = ms.build_scene_dict(scene, max_depth=-1)
    if d["integrator"]["type"] != "mneevolpath":
        raise ValueError("connection_power: the scene's boundary is not a smooth dielectric")
    d["integrator"].update(integrator or {})
    mscene = mi.load_dict(d)
    integ = mscene.integrator()
    integ._prepare(mscene)
    medium = mscene.shapes()[0].interior_medium()
    n = len(x)
    x0 = mi.Point3f(*[mi.Float(np.asarray(x)[:, i].astype(np.float32)) for i in range(3)])
    inside = _inside(mi, dr, mscene, x0) if inside is None else np.asarray(inside, bool)
    mei = dr.zeros(mi.MediumInteraction3f, n)
    mei.p = x0
    mei.t = mi.Float(0.0)
    mei.medium = dr.select(mi.Bool(inside), medium, dr.zeros(mi.MediumPtr))
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(seed, n)
    value, _, _, extras, _ = integ._connect(mscene, sampler, mei, mei.medium, mi.Bool(inside), mi.UInt32(0),
                                            lambda w, a: mi.Float(0.0))
    parts = [value] + [v for v, _ in extras]
    return [np.stack([np.asarray(v[i], np.float64) for i in range(3)], 1) for v in parts], inside


def delivered(scene, points=1 << 18, seed=0, variant="llvm_ad_rgb", integrator=None, parts=False):
    """``(power, se, inside_share)``: first-scattered power (3,) delivered by ``mneevolpath``'s connections.

    ``scene`` must have a smooth dielectric boundary (the integrator is ``mneevolpath``) and
    point lights. ``se`` is the standard error (3,) over the ``points`` uniform points.
    ``integrator``: as in :func:`connection_values`. ``parts=True`` returns ``power`` and ``se`` per
    part instead, (parts, 3) in the order of :func:`connection_values`.
    """
    from harness.reference.specular_paths import _grid_lookup

    m = scene.medium
    lo, hi = np.asarray(m.bbox_min, np.float64), np.asarray(m.bbox_max, np.float64)
    rng = np.random.default_rng(seed)
    x = lo + (hi - lo) * rng.random((points, 3))
    values, inside = connection_values(scene, x, seed=seed, variant=variant, integrator=integrator)
    st, al = _grid_lookup(m, x)
    f = np.stack([np.where(inside[:, None], st * al * phi, 0.0) for phi in (values if parts else [sum(values)])])
    f *= float(np.prod(hi - lo))
    power, se = f.mean(1), f.std(1, ddof=1) / np.sqrt(points)
    return (power, se, float(inside.mean())) if parts else (power[0], se[0], float(inside.mean()))
