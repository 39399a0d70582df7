"""The two diffusion kernels of SSLPV's classical rivals, in NumPy (the reference the GLSL mirrors).

.. list-table::
   :header-rows: 1

   * - function
     - source
     - meaning
   * - :func:`material`
     - Jensen et al. 2001, Sec. 2.4; Frisvad et al. 2014
     - the derived coefficients of one medium (per colour)
   * - :func:`rd_dipole`
     - Jensen et al. 2001, Eq. 4; Hao & Varshney 2004, Sec. 2.2
     - standard dipole diffuse reflectance ``R_d(r)`` (``docs/dipole_rivals.md``, Eq. (K1))
   * - :func:`rd_total`
     - Jensen et al. 2001, Sec. 2.4 (the closed form of ``int R_d 2 pi r dr``)
     - Eq. (K2)
   * - :func:`dirpole_sd`
     - Frisvad, Hachisuka & Kjeldsen 2014 (ACM TOG 34(1))
     - directional dipole ``S_d(x_i, w_i; x_o)`` without the two Fresnel transmittances, Eqs. (K3)-(K7)
   * - :func:`ray_source_term`
     - the same paper
     - ``S'_d(x, w, r)``: one ray source in an infinite medium, Eq. (K4)
   * - :func:`plane_standard`, :func:`plane_directional`
     - the two above
     - either kernel's exitance on the plane ``z = 0`` (normal ``+z``) at ``(r cos phi, r sin phi, 0)`` for a
       pencil beam entering at the origin: ``f(r, phi)``, channel 0 (the half-space the random walk checks)

Coefficients (per colour): ``sigma_s' = sigma_s (1 - g)``, ``sigma_t' = sigma_a + sigma_s'``,
``alpha' = sigma_s' / sigma_t'``, ``D = 1 / (3 sigma_t')``, ``sigma_tr = sqrt(sigma_a / D)``.
The boundary terms come from the scene's ``eta = n_inside / n_outside``: the standard dipole
uses ``A(eta) = (1 + F_dr) / (1 - F_dr)`` (:func:`sslpv_gl.boundary.a_of_eta`, quadrature);
the directional dipole its own ``C_phi(eta) = (1 - 2 C_1) / 4``, ``C_E(eta) = (1 - 3 C_2) / 2``
and ``A = (1 - C_E) / (2 C_phi)`` from the Fresnel moments ``C_n``
(:func:`sslpv_gl.boundary.fresnel_moment`, quadrature instead of d'Eon's polynomial fits).
At ``eta = 1`` both ``A`` are exactly 1.

Directions: ``w_i`` points from the surface towards the light; ``w_12`` is its refracted
travel direction into the medium (Snell, :func:`sslpv_gl.optics.refract`). Normals point outward.
"""

from __future__ import annotations

import numpy as np

from sslpv_gl.boundary import a_of_eta, fresnel_moment
from sslpv_gl.optics import refract

__all__ = ["material", "rd_dipole", "rd_total", "c_phi", "c_e", "ray_source_term", "dirpole_sd",
           "plane_standard", "plane_directional", "DE_FACTOR"]

#: ``d_e = 2.131 D / sqrt(alpha')``, the extrapolation distance of the directional dipole
#: (Frisvad et al. 2014, after Davison's boundary condition).
DE_FACTOR = 2.131


def c_phi(eta):
    """``C_phi(eta) = (1 - 2 C_1(eta)) / 4`` (Frisvad et al. 2014; ``2 C_1 = F_dr``)."""
    return 0.25 * (1.0 - 2.0 * fresnel_moment(eta, 1))


def c_e(eta):
    """``C_E(eta) = (1 - 3 C_2(eta)) / 2`` (Frisvad et al. 2014)."""
    return 0.5 * (1.0 - 3.0 * fresnel_moment(eta, 2))


def material(sigma_s_prime, sigma_a, eta, sigma_t=None):
    """The derived coefficients of a medium, elementwise (colours last) -> dict of float64 arrays.

    ``sigma_t`` (the *unreduced* extinction) is used only by the directional dipole's
    back-lit real-source offset ``1 / (3 sigma_t)``; it defaults to ``sigma_t'``.
    Keys: ``sigma_s_prime``, ``sigma_a``, ``sigma_t_prime``, ``sigma_t``, ``alpha_prime``,
    ``D``, ``sigma_tr``, ``A`` (Jensen), ``z_r``, ``z_v`` (standard dipole), ``c_phi``,
    ``c_e``, ``c_phi_out`` (``C_phi(1/eta)``), ``A_dir``, ``d_e`` (directional dipole).
    """
    sp = np.asarray(sigma_s_prime, dtype=np.float64)
    sa = np.asarray(sigma_a, dtype=np.float64)
    stp = sp + sa
    st = stp if sigma_t is None else np.asarray(sigma_t, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        alpha = sp / stp
        D = 1.0 / (3.0 * stp)
        sigma_tr = np.sqrt(sa / D)
    eta = float(eta)
    A = float(a_of_eta(eta))
    z_r = 3.0 * D                                  # = 1 / sigma_t' (Jensen et al. 2001, Sec. 2.4)
    z_v = z_r + 4.0 * A * D                        # = z_r (1 + 4 A / 3)
    cp, ce, cpo = float(c_phi(eta)), float(c_e(eta)), float(c_phi(1.0 / eta))
    with np.errstate(divide="ignore", invalid="ignore"):
        d_e = DE_FACTOR * D / np.sqrt(alpha)
    return {"sigma_s_prime": sp, "sigma_a": sa, "sigma_t_prime": stp, "sigma_t": st, "alpha_prime": alpha,
            "D": D, "sigma_tr": sigma_tr, "A": A, "z_r": z_r, "z_v": z_v, "c_phi": cp, "c_e": ce,
            "c_phi_out": cpo, "A_dir": (1.0 - ce) / (2.0 * cp), "d_e": d_e, "eta": eta}


def rd_dipole(r, m):
    """Eq. (K1): the standard dipole's diffuse reflectance ``R_d(r)`` (per unit area, per unit flux).

    ``R_d = alpha'/(4 pi) [z_r (sigma_tr + 1/d_r) e^(-sigma_tr d_r) / d_r^2
    + z_v (sigma_tr + 1/d_v) e^(-sigma_tr d_v) / d_v^2]`` with ``d_{r,v} = sqrt(r^2 + z_{r,v}^2)``
    (Jensen et al. 2001, Eq. 4; Hao & Varshney 2004, Sec. 2.2). ``r`` broadcasts against the
    colour axis of ``m`` (give ``r[..., None]`` for several distances).
    """
    r = np.asarray(r, dtype=np.float64)
    s = m["sigma_tr"]
    out = 0.0
    for z in (m["z_r"], m["z_v"]):
        d = np.sqrt(r * r + z * z)
        out = out + z * (s + 1.0 / d) * np.exp(-s * d) / (d * d)
    return m["alpha_prime"] / (4.0 * np.pi) * out


def rd_total(alpha_prime, A):
    """Eq. (K2): ``int_0^inf R_d(r) 2 pi r dr = alpha'/2 (1 + e^(-4/3 A s)) e^(-s)``, ``s = sqrt(3 (1 - alpha'))``."""
    a = np.asarray(alpha_prime, dtype=np.float64)
    s = np.sqrt(3.0 * (1.0 - a))
    return 0.5 * a * (1.0 + np.exp(-4.0 / 3.0 * A * s)) * np.exp(-s)


def _dot(a, b):
    return np.sum(a * b, axis=-1)


def ray_source_term(x, w, r, n_o, m):
    """Eq. (K4): ``S'_d(x, w, r)``, one ray source of direction ``w`` seen from the exit point.

    ``x`` (..., 3) is the exit point minus the source, ``w`` (..., 3) the source direction,
    ``n_o`` (..., 3) the exit normal and ``r`` (..., C) the (corrected) distance used in the
    radial factors. Equals ``(C_phi phi + C_E E.n_o) / (4 pi C_phi(1/eta))`` with ``phi`` and
    ``E = -D grad phi`` the P1 fluence and flux of the ray source (``docs/dipole_rivals.md``).
    """
    D, s = m["D"], m["sigma_tr"]
    xw = _dot(x, w)[..., None]
    xn = _dot(x, n_o)[..., None]
    wn = _dot(w, n_o)[..., None]
    sr = s * r
    one = 1.0 + sr
    r2 = r * r
    t0 = np.exp(-sr) / (r * r2) / (4.0 * m["c_phi_out"] * 4.0 * np.pi**2)
    fluence = r2 / D + 3.0 * one * xw
    flux = 3.0 * D * one * wn - (one + 3.0 * D * (3.0 * one + sr * sr) / r2 * xw) * xn
    return t0 * (m["c_phi"] * fluence - m["c_e"] * flux)


def dirpole_sd(x_i, n_i, w_i, x_o, n_o, m, clamp=True):
    """Eqs. (K3)-(K7): the directional dipole ``S_d(x_i, w_i; x_o)`` -> (..., C).

    Real ray source at ``x_i`` along ``w_12`` (``w_i`` refracted), its mirror image across the
    modified tangent plane (normal ``n_i* = x/|x| x (n_i x x)/|n_i x x|``, ``x = x_o - x_i``) at
    ``x_v = x_i + 2 A d_e n_i*`` along ``w_v = w_12 - 2 (w_12.n_i*) n_i*``; the real source's
    distance is corrected to ``d_r^2 = r^2 + D mu_0 (D mu_0 - 2 d_e cos beta)`` when the exit
    point sees the source's front (``mu_0 = -n_o.w_12 > 0``) and ``r^2 + (1/(3 sigma_t))^2``
    otherwise. The Fresnel transmittances ``T(w_i) T(w_o)`` are NOT included. Negative values
    are clamped to 0 (as the authors' code does) unless ``clamp`` is False.
    """
    x_i, n_i, w_i, x_o, n_o = (np.asarray(a, dtype=np.float64) for a in (x_i, n_i, w_i, x_o, n_o))
    x = x_o - x_i
    r2 = _dot(x, x)[..., None]
    r = np.sqrt(r2)
    w12 = refract(-w_i, n_i, m["eta"])
    # modified tangent plane (x_o = x_i: the true normal)
    t = np.cross(n_i, x)
    tl = np.linalg.norm(t, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        n_star = np.cross(x / np.linalg.norm(x, axis=-1, keepdims=True), t / tl)
    degenerate = (tl[..., 0] < 1e-6 * r[..., 0]) | (r[..., 0] == 0)   # as kernels.glsl
    n_star = np.where(degenerate[..., None], n_i, n_star)
    # real source: corrected distance
    xw = _dot(x, w12)[..., None]
    mu0 = -_dot(n_o, w12)[..., None]
    de, D = m["d_e"], m["D"]
    cos_beta = -np.sqrt(np.maximum(r2 - xw * xw, 0.0) / (r2 + de * de))
    dr2 = np.where(mu0 > 0.0, r2 + D * mu0 * (D * mu0 - 2.0 * de * cos_beta),
                   r2 + (1.0 / (3.0 * m["sigma_t"])) ** 2)
    s_real = ray_source_term(x, w12, np.sqrt(dr2), n_o, m)
    # virtual source, per colour (its offset 2 A d_e differs per colour)
    wv = w12 - 2.0 * _dot(w12, n_star)[..., None] * n_star
    de_b = np.asarray(de)
    off = 2.0 * m["A_dir"] * np.broadcast_to(de_b, np.broadcast_shapes(r.shape[:-1] + de_b.shape[-1:], de_b.shape))
    s_virt = np.empty_like(s_real)
    for c in range(off.shape[-1]):
        xv = x - off[..., c:c + 1] * n_star
        dv = np.linalg.norm(xv, axis=-1, keepdims=True)
        mc = {k: (v[..., c:c + 1] if isinstance(v, np.ndarray) and v.ndim and v.shape[-1] == off.shape[-1]
                  else v) for k, v in m.items()}
        s_virt[..., c:c + 1] = ray_source_term(xv, wv, dv, n_o, mc)
    sd = s_real - s_virt
    return np.maximum(sd, 0.0) if clamp else sd


def plane_standard(m):
    """``f(r, phi) = R_d(r)`` (Eq. (K1)), channel 0, broadcast over ``r`` and ``phi``."""
    def f(r, phi):
        r = np.broadcast_to(r, np.broadcast_shapes(np.shape(r), np.shape(phi)))
        return rd_dipole(r[..., None], m)[..., 0]
    return f


def plane_directional(m, theta_deg):
    """``f(r, phi) = pi S_d`` (Eqs. (K3)-(K7)), channel 0, at ``(r cos phi, r sin phi, 0)`` on the plane with
    normal ``+z``, for light entering at the origin at ``theta_deg`` from the normal, travelling towards +x."""
    th = np.radians(theta_deg)
    w_i = np.array([-np.sin(th), 0.0, np.cos(th)])                 # towards the light
    normal = np.array([0.0, 0.0, 1.0])

    def f(r, phi):
        r, phi = np.broadcast_arrays(r, phi)
        x_o = np.stack([r * np.cos(phi), r * np.sin(phi), np.zeros_like(r)], axis=-1)
        n = np.broadcast_to(normal, x_o.shape)
        return np.pi * dirpole_sd(np.zeros_like(x_o), n, np.broadcast_to(w_i, x_o.shape), x_o, n, m)[..., 0]
    return f
