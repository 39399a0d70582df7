"""The vertex math of one refraction: the half-vector constraint, its derivatives, the geometry term.

Part of ``mneevolpath`` (:mod:`harness.reference.mnee`, whose docstring states the method,
steps 2-3, and its limits); the chains of several vertices are :mod:`harness.reference.mnee_chain`.
"""

from harness.reference.llvm import ensure_libllvm

try:  # must precede ``import mitsuba`` (as in harness.reference.mnee)
    ensure_libllvm()
except RuntimeError:
    pass

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

MIN_DET = 1e-12            # |det J| below this is treated as singular
POSITION_EPS = 1e-6        # float32 error of a surface point's position (relative to max(|x1|, 1)), ~8 ulp
PLANE_SWITCH = 0.05        # |C| above which a walk step solves the tangent-plane refraction instead


# --------------------------------------------------------------------------- vertex math

def _frame(n, dp_du):
    """Unit tangent s (dp_du projected onto the tangent plane of n), t = n x s, and |s~|."""
    s_ = dp_du - n * dr.dot(n, dp_du)
    ls = dr.norm(s_)
    s = s_ / ls
    return s, dr.cross(n, s), s_, ls


def half_vector_constraint(wi, d0, y, p, n, dp_du, dp_dv, dn_du, dn_dv, eta):
    """The constraint ``C = (h.s, h.t)`` at surface point ``p`` and its derivative ``J = dC/d(u, v)``.

    ``wi`` (unit) and ``d0`` give the medium vertex as ``x0 = p + d0 wi``: the walk keeps
    them as the direction and distance of the ray cast from ``x0`` (exact in float32 even
    when ``x0`` lies a hair below the surface, where ``p - x0`` would lose all digits).

    ``h = eta wi + wo`` is the (unnormalised) generalized half vector of a refraction from
    ``y`` (outside, index 1) to ``x0`` (inside, relative index ``eta``); Snell's law
    holds iff its tangential part vanishes, ``C = 0``. ``|C| = |eta sin(theta_i) -
    sin(theta_o)|`` in the plane of incidence. Hanika et al. normalise ``h``; without the
    normalisation the constraint stays well posed as ``eta -> 1`` (where ``|h| -> 0`` on
    every straight line and the normalised form loses all float precision), and the
    geometry term, a ratio of two derivatives of ``C`` at a root, is the same.
    ``(s, t)`` is the tangent frame of the shading normal ``n`` (:func:`_frame`); ``(u, v)``
    the triangle's barycentric parameters, along which the position moves by
    ``dp_du, dp_dv`` and the unit normal by ``dn_du, dn_dv``. Returns
    ``(C0, C1, J00, J01, J10, J11, aux)`` with ``aux`` the quantities the geometry term
    reuses.
    """
    wo_ = y - p
    d1 = dr.norm(wo_)
    wo = wo_ / d1
    h = eta * wi + wo
    s, t, s_, ls = _frame(n, dp_du)

    def d_c(dp, dn):
        # d(wi)/dq = -(I - wi wi^T) dp / d0, likewise wo.
        dh = -eta * (dp - wi * dr.dot(wi, dp)) / d0 - (dp - wo * dr.dot(wo, dp)) / d1
        # dp_du is constant on a triangle; only n moves the frame.
        ds_ = -(dn * dr.dot(n, dp_du) + n * dr.dot(dn, dp_du))
        ds = (ds_ - s * dr.dot(s, ds_)) / ls
        dt = dr.cross(dn, s) + dr.cross(n, ds)
        return dr.dot(dh, s) + dr.dot(h, ds), dr.dot(dh, t) + dr.dot(h, dt)

    j00, j10 = d_c(dp_du, dn_du)
    j01, j11 = d_c(dp_dv, dn_dv)
    aux = {"wi": wi, "wo": wo, "d0": d0, "d1": d1, "s": s, "t": t}
    return dr.dot(h, s), dr.dot(h, t), j00, j01, j10, j11, aux


def light_derivative_det(aux):
    """``|det dC/d(y_perp)|``: the constraint's change when the light moves perpendicular to ``wo``."""
    e1, e2 = mi.coordinate_system(aux["wo"])
    s, t, d1 = aux["s"], aux["t"], aux["d1"]
    # d(h) = d(wo) = (I - wo wo^T) e / d1 = e / d1 for e _|_ wo.
    a00, a10 = dr.dot(e1, s) / d1, dr.dot(e1, t) / d1
    a01, a11 = dr.dot(e2, s) / d1, dr.dot(e2, t) / d1
    return dr.abs(a00 * a11 - a01 * a10)


def generalized_geometry(wi, d0, y, p, n, ng, dp_du, dp_dv, dn_du, dn_dv, eta):
    """``E / (I T Tr)``: irradiance at ``x0`` per unit light intensity through the refraction at ``p``.

    ``eta^2 |n_g . wi| / d0^2 * |det dC/dy_perp| / |det dC/d(u,v)| * |dp_du x dp_dv|``
    (module docstring, step 3), with ``wi, d0`` as in :func:`half_vector_constraint`.
    Tends to ``1 / |y - x0|^2`` when ``eta -> 1``.
    """
    c0, c1, j00, j01, j10, j11, aux = half_vector_constraint(wi, d0, y, p, n, dp_du, dp_dv, dn_du, dn_dv, eta)
    det_j = dr.abs(j00 * j11 - j01 * j10)
    area = dr.norm(dr.cross(dp_du, dp_dv))
    dA_dAy = light_derivative_det(aux) / det_j * area
    g = dr.square(eta) * dr.abs(dr.dot(ng, aux["wi"])) / dr.square(aux["d0"]) * dA_dAy
    return dr.select(det_j > MIN_DET, g, 0.0), aux


def plane_refraction_point(rel, rel_y, n, eta, iterations=12):
    """Exact refraction point through the plane with normal ``n`` through ``x0 + rel``, as an offset from ``x0``.

    ``rel_y = y - x0``. In the plane of incidence the problem is one-dimensional: with
    depth ``a`` of ``x0``, height ``b`` of ``y`` and horizontal distance ``D`` between
    their feet, the point at distance ``r`` from the foot of ``x0`` satisfies Snell's law
    when ``g(r) = eta r / sqrt(r^2 + a^2) - (D - r) / sqrt((D - r)^2 + b^2) = 0``; ``g``
    rises monotonically from ``g(0) < 0`` to ``g(D a / (a + b)) >= 0`` (the straight line's
    crossing), so Newton's method kept inside a shrinking bracket converges. Returns
    ``(offset, valid)``; invalid when ``x0`` is not below or ``y`` not above the plane.
    """
    a = dr.dot(rel, n)
    b = dr.dot(rel_y, n) - a
    horiz = rel_y - dr.dot(rel_y, n) * n
    big_d = dr.norm(horiz)
    e = horiz / dr.maximum(big_d, 1e-30)
    # Start from the straight line's direction bent by Snell's law at x0's depth (exact for a << b).
    r_straight = big_d * a / dr.maximum(a + b, 1e-30)
    lo, hi = mi.Float(0.0), mi.Float(r_straight)
    sin_o = big_d / dr.sqrt(dr.square(big_d) + dr.square(a + b))
    sin_i = dr.minimum(sin_o / eta, 0.999999)
    r = dr.minimum(a * sin_i / dr.sqrt(1.0 - dr.square(sin_i)), r_straight)
    for _ in range(iterations):
        q0 = dr.sqrt(dr.square(r) + dr.square(a))
        q1 = dr.sqrt(dr.square(big_d - r) + dr.square(b))
        g = eta * r / q0 - (big_d - r) / q1
        dg = eta * dr.square(a) / (q0 * q0 * q0) + dr.square(b) / (q1 * q1 * q1)
        lo = dr.select(g < 0, r, lo)
        hi = dr.select(g < 0, hi, r)
        r_newton = r - g / dg
        r = dr.select((r_newton > lo) & (r_newton < hi), r_newton, 0.5 * (lo + hi))
    return a * n + r * e, (a > 0) & (b > 0)
