r"""Manifold walks through a chain of k refraction vertices (Hanika, Droske and Fascione 2015, Sec. 4).

Used by ``mneevolpath`` (:mod:`harness.reference.mnee`) when the straight segment from a
medium vertex ``x0`` to a point light ``y`` crosses the object's boundary k = 3, 5, ...
times (it leaves the object, crosses air, enters another part of it, leaves again). The
light's path is ``x0 -> x1 -> ... -> xk -> y``; odd vertices leave the medium, even ones
enter it.

Constraint (the generalized half vector at every vertex, unnormalised as in
:func:`harness.reference.mnee.half_vector_constraint`): at vertex ``i`` with neighbours
``a = x_{i-1}`` and ``b = x_{i+1}`` (``x_{k+1} = y``), ``w_a = (a - x_i)/|a - x_i|``,
``w_b = (b - x_i)/|b - x_i|`` and the indices ``eta_a, eta_b`` of the media on the two
sides (``(eta, 1)`` at odd, ``(1, eta)`` at even vertices),

    C_i = ((eta_a w_a + eta_b w_b) . s_i, (eta_a w_a + eta_b w_b) . t_i) = 0,

with ``(s_i, t_i)`` the tangent frame of the shading normal. ``C_i`` depends on
``x_{i-1}, x_i, x_{i+1}`` only, so ``dC/dX`` over the barycentric parameters ``(u_i,
v_i)`` of all vertices is block-tridiagonal (Hanika et al. Eq. 6): ``A_i = dC_i/dX_{i-1}``,
``B_i = dC_i/dX_i``, ``U_i = dC_i/dX_{i+1}``, each 2 x 2 (:func:`chain_blocks`). It is
solved by block Gaussian elimination without pivoting (the block Thomas algorithm,
:func:`solve_tridiagonal`); ``det dC/dX`` is the product of the eliminated diagonal
blocks.

Generalized geometry term (Hanika et al. Eq. 8, with the implicit function theorem as in
the single-vertex case): the light moved by ``dy`` perpendicular to ``w_o`` at ``x_k``
moves the chain by ``dX = -(dC/dX)^-1 (dC/dy) dy``, where only ``C_k`` depends on ``y``
(``d C_k / d y_perp = eta_b (e . s_k, e . t_k) / |y - x_k|`` for ``e`` perpendicular to the
last segment). The first block ``Z_1`` of ``(dC/dX)^-1 dC/dy_perp`` gives the area the
first vertex sweeps, ``dA(x1)/dA_perp(y) = |det Z_1| |dp_du x dp_dv|``, and by etendue
conservation between media of index ``eta`` (at ``x0``) and 1 (at ``y``) the irradiance at
``x0`` perpendicular to ``w_1`` per unit intensity is

    G = eta^2 |n_g1 . w_1| / |x1 - x0|^2 * |det Z_1| * |dp_du x dp_dv|_1,

the same form as one vertex (for k = 1 it reduces to :func:`harness.reference.mnee.generalized_geometry`);
both scalings of ``C_i`` cancel in ``Z_1`` at a root. The light at ``x0`` is then ``I G
prod_i (1 - F_i) prod_j Tr_j`` over the k Fresnel transmissions (:func:`chain_fresnel`)
and the (k + 1) / 2 medium segments; the air segments must be unoccluded.

Walk: Newton's method on all k vertices at once; the tangent-plane update ``x_i - beta
delta_i`` is projected back onto the surface by casting from the (already projected)
previous vertex toward it (Hanika et al. Sec. 4.3), so each vertex is the first surface
point seen from its predecessor. A step whose projection misses, lands on another shape, or
has the wrong orientation (odd vertices leave, even ones enter) is halved.

Limits: every vertex on the same shape (same medium and eta); internal reflections inside
the chain (light reflected back and forth inside the second part) are not part of it; the
walk finds the solution its straight seed leads to. A seed segment that grazes a part of the object
crosses the boundary beyond the critical angle, where no refraction chain lies near it (total internal
reflection): its walk steps far off the seed and fails. On the scanned bunny (``bunny_dielectric``, eta
1.3) nearly every seed through three crossings does, so no straight-seeded chain connects there; specular
manifold sampling's ``TTT`` chains (:mod:`harness.reference.mnee_sms`) start from other seeds. Connections
left out are counted and their light estimated by the caller (:mod:`harness.reference.mnee`).
"""

from harness.reference.llvm import ensure_libllvm

try:  # must precede ``import mitsuba`` (as in harness.reference.mnee)
    ensure_libllvm()
except RuntimeError:
    pass

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

MIN_DET = 1e-12
MIN_STEP = 1e-4            # smallest Newton step factor before a walk is given up
POSITION_EPS = 1e-6        # float32 error of a surface point's position (relative to max(|x|, 1))
#: Longest chain a scene may ask for (``[boundary] max_crossings``): each vertex adds a ray cast
#: per Newton iteration and two 2 x 2 blocks to the elimination.
from harness.scene.model import MAX_CROSSINGS_LIMIT  # noqa: E402, F401
WALK_FLAGS = mi.RayFlags.All | mi.RayFlags.dNSdUV


# --------------------------------------------------------------------------- 2 x 2 algebra (tuples, row-major)

def m_mul(a, b):
    return (a[0] * b[0] + a[1] * b[2], a[0] * b[1] + a[1] * b[3], a[2] * b[0] + a[3] * b[2], a[2] * b[1] + a[3] * b[3])


def m_sub(a, b):
    return tuple(x - y for x, y in zip(a, b))


def m_det(a):
    return a[0] * a[3] - a[1] * a[2]


def m_inv(a):
    d = m_det(a)
    r = dr.select(dr.abs(d) > MIN_DET * MIN_DET, dr.rcp(d), 0.0)
    return (a[3] * r, -a[1] * r, -a[2] * r, a[0] * r)


def mv_mul(a, v):
    return (a[0] * v[0] + a[1] * v[1], a[2] * v[0] + a[3] * v[1])


def v_sub(a, b):
    return (a[0] - b[0], a[1] - b[1])


# --------------------------------------------------------------------------- the constraint and its blocks

#: Vertex kinds of a typed chain (:mod:`harness.reference.mnee_sms`): a refraction, a reflection inside the
#: medium, a reflection off the outside of the object.
KINDS = ("T", "R", "r")


def sides(kinds):
    """Whether the light path is inside the medium just before each vertex (from ``x0``, which is inside)."""
    out, inside = [], True
    for kind in kinds:
        if kind not in KINDS or (kind == "R") != inside and kind != "T":
            raise ValueError(f"mnee_chain: kinds {kinds!r}: {kind!r} cannot follow a segment "
                             f"{'inside' if inside else 'outside'} the medium; use T, R (inside) or r (outside)")
        out.append(inside)
        inside = inside != (kind == "T")
    if inside:
        raise ValueError(f"mnee_chain: kinds {kinds!r} end inside the medium; the light is outside")
    return out


def typed_indices(kinds, eta):
    """``[(eta_a, eta_b)]`` per vertex of a typed chain: a refraction between the medium and air, a
    reflection with the same index on both sides (``eta`` inside, 1 outside)."""
    out = []
    for kind, inside in zip(kinds, sides(kinds)):
        if kind == "T":
            out.append((eta, 1.0) if inside else (1.0, eta))
        else:
            out.append((eta, eta) if inside else (1.0, 1.0))
    return out


def alternating(k):
    """The kinds of the chains through k crossings: k refractions."""
    return ("T",) * k


def _frame_derivative(n, dp_du, dn, s, ls):
    """Derivatives of the tangent frame (s, t) of ``n`` when the normal moves by ``dn`` (``dp_du`` fixed)."""
    ds_ = -(dn * dr.dot(n, dp_du) + n * dr.dot(dn, dp_du))
    ds = (ds_ - s * dr.dot(s, ds_)) / ls
    return ds, dr.cross(dn, s) + dr.cross(n, ds)


def vertex_blocks(wa, da, wb, db, ea, eb, v, prev_v, next_v):
    """Constraint ``C_i`` and its blocks at one vertex.

    ``wa, da`` (``wb, db``): unit direction and distance to the neighbour on the ``x0``
    (light) side; ``v`` the vertex's surface data ``(p, n, ng, dp_du, dp_dv, dn_du,
    dn_dv)``, ``prev_v`` / ``next_v`` the neighbours' (None for the fixed ends ``x0``,
    ``y``). Returns ``(C, A, B, U, frame)``; A or U is None at an end.
    """
    _, n, _, dp_du, dp_dv, dn_du, dn_dv = v
    h = ea * wa + eb * wb
    s_ = dp_du - n * dr.dot(n, dp_du)
    ls = dr.norm(s_)
    s = s_ / ls
    t = dr.cross(n, s)

    def own(dp, dn):
        # d(w_a)/dq = -(I - w_a w_a^T) dp / d_a, likewise w_b; the normal moves the frame.
        dh = -ea * (dp - wa * dr.dot(wa, dp)) / da - eb * (dp - wb * dr.dot(wb, dp)) / db
        ds, dt = _frame_derivative(n, dp_du, dn, s, ls)
        return dr.dot(dh, s) + dr.dot(h, ds), dr.dot(dh, t) + dr.dot(h, dt)

    def neighbour(e, w, d, dq):
        # A neighbour moving by dq turns w toward it: d(w) = (I - w w^T) dq / d.
        dh = e * (dq - w * dr.dot(w, dq)) / d
        return dr.dot(dh, s), dr.dot(dh, t)

    b00, b10 = own(dp_du, dn_du)
    b01, b11 = own(dp_dv, dn_dv)
    blk_a = blk_u = None
    if prev_v is not None:
        a00, a10 = neighbour(ea, wa, da, prev_v[3])
        a01, a11 = neighbour(ea, wa, da, prev_v[4])
        blk_a = (a00, a01, a10, a11)
    if next_v is not None:
        u00, u10 = neighbour(eb, wb, db, next_v[3])
        u01, u11 = neighbour(eb, wb, db, next_v[4])
        blk_u = (u00, u01, u10, u11)
    return (dr.dot(h, s), dr.dot(h, t)), blk_a, (b00, b01, b10, b11), blk_u, (s, t)


def chain_blocks(omega, dist, verts, y, eta, kinds=None):
    """Constraints, blocks and per-vertex geometry of the chain ``x0 -> verts -> y``.

    ``kinds`` (default: all refractions) names each vertex ``T``, ``R`` or ``r`` (:data:`KINDS`);
    a reflection's constraint is the half vector with the same index on both sides.

    ``x1 = x0 + dist omega`` is kept as the ray from ``x0`` (exact in float32 near the
    surface, as the single-vertex walk). Returns ``(C, A, B, U, aux)``, lists of length k
    (``A[0]`` and ``U[-1]`` None); ``aux`` holds the directions and distances.
    """
    k = len(verts)
    pairs = typed_indices(kinds or alternating(k), eta)
    C, A, B, U, frames, wa_l, wb_l, da_l, db_l = [], [], [], [], [], [], [], [], []
    for i in range(k):
        p = verts[i][0]
        if i == 0:
            wa, da = -omega, dist
        else:
            wa_ = verts[i - 1][0] - p
            da = dr.norm(wa_)
            wa = wa_ / da
        nxt = y if i == k - 1 else verts[i + 1][0]
        wb_ = nxt - p
        db = dr.norm(wb_)
        wb = wb_ / db
        ea, eb = pairs[i]
        c, a, b, u, fr = vertex_blocks(wa, da, wb, db, ea, eb, verts[i], verts[i - 1] if i else None,
                                       verts[i + 1] if i < k - 1 else None)
        C.append(c)
        A.append(a)
        B.append(b)
        U.append(u)
        frames.append(fr)
        wa_l.append(wa)
        wb_l.append(wb)
        da_l.append(da)
        db_l.append(db)
    return C, A, B, U, {"frames": frames, "wa": wa_l, "wb": wb_l, "da": da_l, "db": db_l}


def solve_tridiagonal(A, B, U, rhs):
    """Solve the block-tridiagonal system ``A_i X_{i-1} + B_i X_i + U_i X_{i+1} = R_i`` (2 x 2 blocks).

    ``rhs`` is a list of k blocks, each a 2-vector (tuple of 2) or a 2 x 2 matrix (tuple of
    4, two right-hand sides). Block Thomas algorithm (no pivoting: the diagonal blocks of a
    walk near a solution are dominated by the refraction's own curvature). Returns the
    solution blocks and ``det`` of the whole matrix (product of the eliminated blocks).
    """
    k = len(B)
    vec = len(rhs[0]) == 2
    mul = mv_mul if vec else m_mul
    sub = v_sub if vec else m_sub
    bp, rp, det = [B[0]], [rhs[0]], m_det(B[0])
    for i in range(1, k):
        m = m_mul(A[i], m_inv(bp[i - 1]))
        bp.append(m_sub(B[i], m_mul(m, U[i - 1])))
        rp.append(sub(rhs[i], mul(m, rp[i - 1])))
        det = det * m_det(bp[i])
    x = [None] * k
    x[k - 1] = mul(m_inv(bp[k - 1]), rp[k - 1])
    for i in range(k - 2, -1, -1):
        x[i] = mul(m_inv(bp[i]), sub(rp[i], mul(U[i], x[i + 1])))
    return x, det


def chain_geometry(omega, dist, verts, y, eta, kinds=None):
    """``G``: irradiance at ``x0`` perpendicular to ``-omega`` per unit intensity through the chain (docstring).

    Returns ``(G, C, aux)``; ``G`` is 0 where ``dC/dX`` is singular. The etendue argument holds for
    any kinds of vertices between ``x0`` (index ``eta``) and the light (index 1).
    """
    C, A, B, U, aux = chain_blocks(omega, dist, verts, y, eta, kinds)
    k = len(verts)
    e1, e2 = mi.coordinate_system(aux["wb"][-1])
    s, t = aux["frames"][-1]
    eb = typed_indices(kinds or alternating(k), eta)[-1][1]
    db = aux["db"][-1]
    # dC_k / dy_perp: the light moving by e _|_ w_b turns w_b by e / |y - x_k|.
    d_last = (eb * dr.dot(e1, s) / db, eb * dr.dot(e2, s) / db, eb * dr.dot(e1, t) / db, eb * dr.dot(e2, t) / db)
    zero = (mi.Float(0.0),) * 4
    rhs = [zero] * (k - 1) + [d_last]
    z, det = solve_tridiagonal(A, B, U, rhs)
    area = dr.norm(dr.cross(verts[0][3], verts[0][4]))
    ng1 = verts[0][2]
    g = dr.square(eta) * dr.abs(dr.dot(ng1, omega)) / dr.square(dist) * dr.abs(m_det(z[0])) * area
    return dr.select(dr.abs(det) > MIN_DET, g, 0.0), C, aux


def chain_fresnel(verts, aux, eta, kinds=None):
    """``prod_i``: the unpolarised Fresnel transmittance ``1 - F_i`` at a refraction (cosine on the air side)
    and the reflectance ``F_i`` at a reflection (from inside: total internal reflection included);
    ``kinds`` as in :func:`chain_blocks`."""
    tf = mi.Float(1.0)
    kinds = kinds or alternating(len(verts))
    for i, (kind, inside) in enumerate(zip(kinds, sides(kinds))):
        n = verts[i][1]
        if kind == "T":
            # leaving the medium (inside before it), the air is on the light's side
            w_air = aux["wb"][i] if inside else aux["wa"][i]
            fr, _, _, _ = mi.fresnel(dr.abs(dr.dot(n, w_air)), eta)
            tf = tf * (1.0 - fr)
        else:
            cos = dr.abs(dr.dot(n, aux["wa"][i]))
            fr, _, _, _ = mi.fresnel(-cos if inside else cos, eta)
            tf = tf * fr
    return tf


def residual(C):
    """Largest ``|C_i|`` over the chain."""
    r = mi.Float(0.0)
    for c in C:
        r = dr.maximum(r, dr.sqrt(dr.square(c[0]) + dr.square(c[1])))
    return r


# --------------------------------------------------------------------------- seeds and the walk

def vertex_of(si):
    """The surface data a walk carries: ``[p, n, ng, dp_du, dp_dv, dn_du, dn_dv]``."""
    return [mi.Point3f(si.p), mi.Vector3f(si.sh_frame.n), mi.Vector3f(si.n), mi.Vector3f(si.dp_du),
            mi.Vector3f(si.dp_dv), mi.Vector3f(si.dn_du), mi.Vector3f(si.dn_dv)]


def _oriented(inside, si, d):
    """A vertex is reached from the right side: from inside the medium (``inside``) the ray meets the surface
    along its outward normals, from outside against them."""
    sign = 1.0 if inside else -1.0
    return (sign * dr.dot(si.n, d) > 0) & (sign * dr.dot(si.sh_frame.n, d) > 0)


def seed_chain(scene, x0, direction, k, shape_id, active):
    """The k crossings of the straight ray from ``x0`` along ``direction``: ``(verts, dist, ok)``.

    ``ok`` where all k hits lie on ``shape_id`` and are crossed in alternating sense.
    """
    ray = mi.Ray3f(x0, direction)
    ok = mi.Bool(active)
    verts = []
    dist = None
    for i in range(k):
        si = scene.ray_intersect(ray, WALK_FLAGS, ok)
        ok &= si.is_valid() & (dr.reinterpret_array(mi.UInt32, si.shape) == shape_id) & _oriented(i % 2 == 0, si,
                                                                                                 direction)
        verts.append(vertex_of(si))
        if i == 0:
            dist = mi.Float(si.t)
        ray = si.spawn_ray(direction)
    return verts, dist, ok


def _project(scene, x0, omega, dist, verts, steps, beta, shape_id, y, active, inside):
    """The tangent-plane update ``x_i - beta delta_i`` projected onto the surface, vertex after vertex
    (``inside``: :func:`sides` of the chain's kinds)."""
    rel = dist * omega - beta * steps[0]
    ray = mi.Ray3f(x0, dr.normalize(rel))
    ray.maxt = 2.0 * dr.norm(rel)
    ok = mi.Bool(active)
    new = []
    omega_new, dist_new = ray.d, None
    for i in range(len(verts)):
        if i > 0:
            prev = dr.zeros(mi.Interaction3f)
            prev.p, prev.n, prev.t = new[i - 1][0], new[i - 1][2], 0.0
            target = verts[i][0] - beta * steps[i]
            ray = prev.spawn_ray_to(target)
            ray.maxt = 2.0 * dr.norm(target - prev.p)
        si = scene.ray_intersect(ray, WALK_FLAGS, ok)
        ok &= si.is_valid() & (dr.reinterpret_array(mi.UInt32, si.shape) == shape_id) & _oriented(inside[i], si, ray.d)
        if i == 0:
            dist_new = mi.Float(si.t)
        new.append(vertex_of(si))
    last = new[-1]
    wo = y - last[0]
    ok &= (dr.dot(last[2], wo) > 0) & (dr.dot(last[1], wo) > 0)
    return new, omega_new, dist_new, ok


@dr.syntax
def walk_chain(scene, x0, y, verts, omega0, dist0, eta, shape_id, iterations, tolerance, active, kinds=None):
    """Newton walk of a k-vertex chain from its seed (module docstring): ``(converged, verts, omega, dist)``.

    ``kinds`` (default: all refractions) as in :func:`chain_blocks`.

    Converged when every vertex's ``|C_i|`` is below ``tolerance`` plus the light side's
    float32 floor (as the single-vertex walk of :mod:`harness.reference.mnee`).
    """
    k = len(verts)
    kinds = kinds or alternating(k)
    inside = sides(kinds)
    omega = mi.Vector3f(omega0)
    dist = mi.Float(dist0)
    beta = mi.Float(1.0)
    iteration = mi.UInt32(0)
    converged = mi.Bool(False)
    walking = mi.Bool(active)
    while dr.hint(walking, label="mnee chain walk"):
        C, A, B, U, aux = chain_blocks(omega, dist, verts, y, eta, kinds)
        floor = POSITION_EPS * dr.maximum(dr.max(dr.abs(verts[-1][0])), 1.0) / aux["db"][-1]
        done = walking & (residual(C) < tolerance + floor)
        converged |= done
        walking &= ~done & (iteration < iterations)
        delta, det = solve_tridiagonal(A, B, U, C)
        walking &= dr.abs(det) > MIN_DET
        steps = [delta[i][0] * verts[i][3] + delta[i][1] * verts[i][4] for i in range(k)]
        new, omega_new, dist_new, ok = _project(scene, x0, omega, dist, verts, steps, beta, shape_id, y, walking,
                                                inside)
        for i in range(k):
            for j in range(7):
                verts[i][j][ok] = new[i][j]
        omega[ok] = omega_new
        dist[ok] = dist_new
        beta = dr.select(ok, dr.minimum(1.0, 2.0 * beta), 0.5 * beta)
        iteration += 1
        walking &= beta >= MIN_STEP
    return converged, verts, omega, dist
