r"""Specular manifold sampling: the connections a straight seed does not lead to, estimated without bias.

``mneevolpath`` (:mod:`harness.reference.mnee`) connects a medium vertex ``x0`` to a point light
``y`` through the solution its straight seed leads to (one refraction, or a chain of refractions
through other parts of the object). Two kinds of specular paths are left out
(:mod:`harness.reference.losses` measures them): *further solutions* of the same constraint (a
curved or faceted boundary can refract the light toward ``x0`` at several points; the seed finds one)
and paths with a *reflection* at the boundary. This module adds both with Zeltner, Georgiev and
Jakob's specular manifold sampling ("Specular Manifold Sampling for Rendering High-Frequency
Caustics and Glints", SIGGRAPH 2020, Sec. 4-5):

1. **Random seed.** A direction ``d`` uniform on the sphere around ``x0``; the seed path follows it
   specularly through the vertex kinds of the chain (``T`` a refraction, ``R`` a reflection inside
   the medium, ``r`` a reflection off the outside; :data:`harness.reference.mnee_chain.KINDS`):
   reflect or refract at each boundary hit (total internal reflection ends a ``T`` seed). For a chain
   with a reflection off the outside, half the seeds (:data:`LIGHT_SIDE_SHARE`) are traced from the
   light instead, uniform in the cone that holds the object (:func:`seed_from_light`): the light such a
   chain carries mostly grazes the reflecting part (Fresnel reflectance is large only there), a basin
   that directions from ``x0`` rarely find.
2. **Newton walk** on the chain's constraint from that seed (:func:`harness.reference.mnee_chain.walk_chain`
   with the kinds: the half vector with the indices of both sides, so a reflection has the same
   index on both), to a solution ``X`` whose every vertex is reflected or refracted on the side its
   kind says (:func:`sided`).
3. **Its light** ``f(X) = I G prod(F or 1 - F) prod Tr`` (the chain's generalized geometry term,
   Hanika et al. 2015 Eq. 8 with the typed blocks; Fresnel reflectance at a reflection, transmittance at a
   refraction; ratio-tracked transmittance along the segments inside the medium; the air segments
   unoccluded), as for the straight-seeded chains.
4. **Unbiased weight** (Zeltner et al. Sec. 5, Eq. 11): the seed leads to ``X`` with an unknown
   probability ``p(X)``; Bernoulli trials (new seeds and walks) until a walk ends at ``X`` again
   take ``N`` trials with ``E[N] = 1 / p(X)``, so ``f(X) N`` estimates ``f(X) / p(X)`` and the sum
   over the solutions is ``E[f(X) N] = sum_X f(X)``. ``N`` is capped at ``max_trials`` (Zeltner et
   al.'s biased variant: ``E[min(N, M)] = (1 - (1 - p)^M) / p``); the lanes that reach the cap are
   counted.

Measured against the photon tracer, label by label, by ``benchmarks/mnee_sms.py``
(``docs/benchmarks/mnee_sms.md``: the torus lit through its hole, and the scanned bunny, whose light
reflected off its body into its ears is the chain ``Tr``; independent runs on the bunny, and the share of a
sampled chain's light that its heaviest points carry, ``docs/benchmarks/mnee_sms_spread.md``); against the
mirror point in a slab (``R T``) and the mirrored light under a second part (``T r``) by ``tests/test_mnee_sms.py``.

For the single refraction the solution the straight seed leads to is already connected
(:mod:`harness.reference.mnee`), so a random walk that ends there contributes nothing (``exclude``):
the sum runs over the *other* solutions.

Chains sampled by default (``sms_chains = "T,RT,Tr,TTT"``; ``x0`` first, the light last): ``T``
(further single-refraction solutions), ``RT`` (the light enters, reflects inside, scatters: the photon
label ``ER`` of :mod:`harness.reference.specular_paths`), ``Tr`` (the light reflects off another part of
the object, enters, scatters: ``rE``) and ``TTT`` (further solutions through another part: ``ETE``;
the straight-seeded chain's own solution is excluded as the single refraction's is). Any chain of
``T``, ``R`` and ``r`` that starts inside and ends outside may be named (``RRT``: ``ERR``). Limits:
chains not named (``ETRE``, ``ERRR`` ...) stay counted as losses by :mod:`harness.reference.losses`; the cap biases toward darker
where ``p(X) < 1 / max_trials`` (the capped share is reported); two solutions closer than
:data:`SAME` of the scene's scale count as one; each lane pays the trials of the solution it
found, so the cost grows with the number of solutions.
"""

from harness.reference.llvm import ensure_libllvm

try:  # must precede ``import mitsuba`` (as in harness.reference.mnee)
    ensure_libllvm()
except RuntimeError:
    pass

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

from harness.reference import mnee_chain as chain  # noqa: E402

#: The chains sampled by default (``sms_chains``), from ``x0``: further single refractions, a reflection
#: inside, a reflection off the outside, further chains through three crossings; and the most Bernoulli
#: trials of one solution's weight that ``sms_trials`` (Zeltner et al.'s cap M) may ask for.
from harness.scene.model import SMS_CHAINS_DEFAULT, SMS_TRIALS_LIMIT as MAX_TRIALS_LIMIT  # noqa: E402, F401
#: Two solutions are the same when every vertex lies within this fraction of ``max(|x|, 1)``.
SAME = 1e-3


def parse_chains(text):
    """``"T,RT,Tr"`` -> ``(("T",), ("R", "T"), ("T", "r"))``; a chain the kinds do not allow raises one line."""
    out = []
    for word in (w.strip() for w in text.split(",")):
        if not word:
            continue
        kinds = tuple(word)
        try:
            chain.sides(kinds)
        except ValueError as exc:
            raise ValueError(f"mneevolpath: sms_chains: {word!r}: {exc}") from None
        out.append(kinds)
    if not out:
        raise ValueError(f"mneevolpath: sms_chains = {text!r} names no chain; give e.g. 'T,RT,Tr'")
    return tuple(out)


def seed_path(scene, x0, d, kinds, eta, shape_id, active):
    """The specular path from ``x0`` along ``d`` through ``kinds``: ``(verts, dist, ok)`` (step 1)."""
    inside = chain.sides(kinds)
    ray = mi.Ray3f(x0, d)
    ok = mi.Bool(active)
    verts, dist = [], None
    for i, kind in enumerate(kinds):
        si = scene.ray_intersect(ray, chain.WALK_FLAGS, ok)
        ok &= si.is_valid() & (dr.reinterpret_array(mi.UInt32, si.shape) == shape_id) & chain._oriented(
            inside[i], si, ray.d)
        verts.append(chain.vertex_of(si))
        if i == 0:
            dist = mi.Float(si.t)
        new, bent = _bend(kind, si.sh_frame.n, -ray.d, inside[i], eta)
        ok &= bent
        ray = si.spawn_ray(new)
    return verts, dist, ok


def sided(kinds, verts, aux):
    """Every vertex bends the light the way its kind says: a refraction has its two directions on the
    two sides of both normals, a reflection both on the side of its segment (inside for ``R``)."""
    ok = mi.Bool(True)
    for i, (kind, inside) in enumerate(zip(kinds, chain.sides(kinds))):
        _, n, ng = verts[i][0], verts[i][1], verts[i][2]
        wa, wb = aux["wa"][i], aux["wb"][i]
        for nrm in (n, ng):
            a, b = dr.dot(nrm, wa), dr.dot(nrm, wb)
            ok &= (a < 0) if inside else (a > 0)
            ok &= (a * b < 0) if kind == "T" else (a * b > 0)
    return ok


def _same(verts, ref):
    ok = mi.Bool(True)
    for v, r in zip(verts, ref):
        ok &= dr.norm(v[0] - r) <= SAME * dr.maximum(dr.max(dr.abs(r)), 1.0)
    return ok


def _bend(kind, n, wi, arrive_inside, eta):
    """The specular direction leaving a vertex of ``kind`` hit along ``-wi`` from inside (``arrive_inside``) or
    outside: ``(direction, ok)`` (a refraction is not ok beyond the critical angle)."""
    if kind != "T":
        return 2.0 * dr.dot(n, wi) * n - wi, mi.Bool(True)
    # sin_t = r sin_i with r the index the ray comes from over the one it enters, about the normal facing wi
    r = eta if arrive_inside else 1.0 / eta
    nn = -n if arrive_inside else n
    c = dr.dot(nn, wi)
    k2 = 1.0 - dr.square(r) * (1.0 - dr.square(c))
    return dr.normalize(-r * wi + (r * c - dr.sqrt(dr.maximum(k2, 0.0))) * nn), k2 > 0.0


def seed_from_light(scene, x0, y, u, kinds, eta, shape_id, active):
    """A seed traced from the light (step 1, the light's side): ``(verts, omega, dist, ok)``.

    A direction ``u`` uniform in the cone from ``y`` that holds the scene's bounding sphere is followed
    specularly through ``kinds`` read from the light; the seed the walk takes is then the path from ``x0``
    toward those vertices' positions, each the first surface hit on the way (as a walk's step projects).
    """
    sphere = scene.bbox().bounding_sphere()
    to_c = mi.Vector3f(sphere.center) - y
    dist_c = dr.norm(to_c)
    cos_max = dr.sqrt(dr.maximum(1.0 - dr.square(sphere.radius / dist_c), 0.0))
    cos_max = dr.select(dist_c > sphere.radius, cos_max, -1.0)
    d = mi.Frame3f(to_c / dist_c).to_world(mi.warp.square_to_uniform_cone(u, cos_max))
    inside = chain.sides(kinds)
    ray = mi.Ray3f(y, d)
    ok = mi.Bool(active)
    pos = [None] * len(kinds)
    for i in reversed(range(len(kinds))):
        arrive_inside = inside[i] != (kinds[i] == "T")        # the vertex's light side
        si = scene.ray_intersect(ray, chain.WALK_FLAGS, ok)
        ok &= si.is_valid() & (dr.reinterpret_array(mi.UInt32, si.shape) == shape_id) & chain._oriented(
            arrive_inside, si, ray.d)
        pos[i] = mi.Point3f(si.p)
        new, bent = _bend(kinds[i], si.sh_frame.n, -ray.d, arrive_inside, eta)
        ok &= bent
        ray = si.spawn_ray(new)
    rel = pos[0] - x0
    dist = dr.norm(rel)
    verts = [[p] for p in pos]
    zero = [mi.Vector3f(0.0)] * len(kinds)
    verts, omega, dist, ok = chain._project(scene, x0, rel / dist, dist, verts, zero, mi.Float(0.0), shape_id, y, ok,
                                            inside)
    return verts, omega, dist, ok


#: The share of a :func:`light_seeded` chain's seeds traced from the light.
LIGHT_SIDE_SHARE = 0.5


def light_seeded(kinds):
    """Whether a chain's seeds come partly (:data:`LIGHT_SIDE_SHARE`) from the light's side: chains with a
    reflection off the outside (module docstring, step 1)."""
    return "r" in kinds


def _walk_from(integ, scene, sampler, x0, y, kinds, eta, shape_id, active):
    """A random seed (step 1) and its walk (step 2): ``(converged, verts, omega, dist)``.

    The seed is a uniform direction from ``x0`` (:func:`seed_path`); for :func:`light_seeded` chains it is,
    with probability :data:`LIGHT_SIDE_SHARE`, a path traced from the light instead (:func:`seed_from_light`).
    The Bernoulli trials draw from the same mixture, so ``N`` still estimates ``1 / p(X)`` of the mixture
    (step 4)."""
    d = mi.warp.square_to_uniform_sphere(sampler.next_2d(active))
    if not light_seeded(kinds):
        verts, dist, ok = seed_path(scene, x0, d, kinds, eta, shape_id, active)
        return chain.walk_chain(scene, x0, y, verts, d, dist, eta, shape_id, integ.newton_iterations,
                                integ.newton_tolerance, ok, kinds)
    from_light = active & (sampler.next_1d(active) < LIGHT_SIDE_SHARE)
    verts, dist, ok = seed_path(scene, x0, d, kinds, eta, shape_id, active & ~from_light)
    lverts, lomega, ldist, lok = seed_from_light(scene, x0, y, sampler.next_2d(active), kinds, eta, shape_id,
                                                 from_light)
    verts = [[dr.select(from_light, b, a) for a, b in zip(va, vb)] for va, vb in zip(verts, lverts)]
    d = dr.select(from_light, lomega, d)
    dist = dr.select(from_light, ldist, dist)
    ok = dr.select(from_light, lok, ok)
    return chain.walk_chain(scene, x0, y, verts, d, dist, eta, shape_id, integ.newton_iterations,
                            integ.newton_tolerance, ok, kinds)


@dr.syntax
def _trials(integ, scene, sampler, x0, y, kinds, eta, shape_id, ref, max_trials, active):
    """Bernoulli trials until a walk ends at ``ref`` again (step 4): ``(N, capped)``."""
    n = mi.UInt32(0)
    going = mi.Bool(active)
    found = mi.Bool(False)
    while dr.hint(going, label="sms trials"):
        n[going] += 1
        conv, verts, _, _ = _walk_from(integ, scene, sampler, x0, y, kinds, eta, shape_id, going)
        hit = going & conv & _same(verts, ref)
        found |= hit
        going &= ~hit & (n < max_trials)
    return n, active & ~found


def sampled_value(integ, scene, sampler, x0, y, kinds, eta, shape_id, emitter, u2, sel_weight, medium, max_trials,
                  active, exclude=None):
    """One specular-manifold-sampling estimate of the light of every ``kinds`` chain at ``x0``.

    Returns ``(value, direction, found, capped)``: ``value = f(X) N / p_select`` along ``direction``
    (module docstring), ``found`` where a walk ended at an admissible solution, ``capped`` where its
    trials reached ``max_trials``. ``exclude = (x1, mask)``: a solution already connected (the straight
    seed's single refraction), which contributes nothing here.
    """
    conv, verts, omega, dist = _walk_from(integ, scene, sampler, x0, y, kinds, eta, shape_id, active)
    g, _, aux = chain.chain_geometry(omega, dist, verts, y, eta, kinds)
    conn = conv & (g > 0) & sided(kinds, verts, aux)
    if exclude is not None:
        conn &= ~(exclude[1] & _same(verts[:1], [exclude[0]]))
    conn, intensity = integ._light_from(scene, emitter, u2, verts[-1], y, conn)
    tr = integ._chain_transmittance(medium, x0, verts, kinds, sampler, conn)
    f = sel_weight * intensity * chain.chain_fresnel(verts, aux, eta, kinds) * g * tr
    n, capped = _trials(integ, scene, sampler, x0, y, kinds, eta, shape_id, [v[0] for v in verts], max_trials, conn)
    value = dr.select(conn, f * mi.Float(n), 0.0)
    return value, omega, conn, capped
