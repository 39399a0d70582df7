"""Surface optics for SSLPV: refraction, Fresnel, shadow-map texel solid angles, GGX.

Conventions
-----------
* ``eta = n_inside / n_outside`` (Mitsuba's ``int_ior / ext_ior``); the
  normal points outward (towards the lower index for ``eta > 1``).
* ``refract`` takes the *incident* direction, pointing towards the surface
  (light travelling), and returns the transmitted direction, also travelling.
* ``fresnel_*`` take ``cos_i`` measured on the incident side: ``cos_i > 0``
  means the light arrives from outside (Mitsuba's ``fresnel()`` convention);
  ``cos_i < 0`` means it arrives from inside, and ``eta`` is inverted.
* ``ggx_reflection`` takes ``wi`` and ``wo`` both pointing AWAY from the
  surface (Mitsuba's BSDF convention).

Functions
---------

.. list-table::
   :header-rows: 1

   * - function
     - source
     - meaning
   * - ``refract(incident_dir, normal, eta)``
     - Snell's law (Eq. 1 "refracted direction obtained from Snell's law")
     - transmitted direction, NaN rows on total internal reflection
   * - ``fresnel_reflectance(cos_i, eta)``
     - unpolarised dielectric Fresnel
     - ``R = (R_s + R_p)/2``, 1 on TIR, 0 when ``eta == 1``
   * - ``fresnel_transmittance(cos_i, eta)``
     - ``T`` of Eq. 1 and Eq. 4
     - ``1 - R``
   * - ``texel_solid_angles(nx, ny, fov_y_deg, aspect, near)``
     - Sec. 3.1 with the authors' correction
     - ``dOmega_p = A_p cos^3(theta_p) / near^2``, (ny, nx), row 0 at the top
   * - ``frustum_solid_angle(fov_x_deg, fov_y_deg)``
     - exact
     - solid angle of a rectangular pyramid, ``4 asin(sin a sin b)``
   * - ``ggx_reflection(wi, wo, n, alpha, eta)``
     - Walter et al. 2007; Mitsuba ``roughdielectric`` (GGX)
     - reflection BRDF ``D F G / (4 cos_i cos_o)``, separable Smith ``G``

Limits
------
* Dielectric only (real ``eta``); no conductors, no polarisation.
* ``ggx_reflection`` is the reflection half of ``roughdielectric``; the
  transmission half is not needed (SSLPV's Eq. 1 lobe replaces it).
  ``alpha`` is clamped to ``>= 1e-4`` as Mitsuba does; a smooth interface
  (alpha = 0) is a delta and must be handled by the caller.
* ``texel_solid_angles`` is the paper's small-texel approximation (Sec. 3.1),
  accurate to ``O(1/N^2)``; ``frustum_solid_angle`` is exact.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "refract",
    "fresnel_reflectance",
    "fresnel_transmittance",
    "texel_solid_angles",
    "frustum_solid_angle",
    "ggx_ndf",
    "smith_g1",
    "ggx_reflection",
]


def _normalize(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def refract(incident_dir, normal, eta):
    """Snell refraction of a travelling direction -> (..., 3) unit.

    ``incident_dir`` points towards the surface, ``normal`` outward,
    ``eta = n_inside / n_outside``. Light arriving from inside
    (``incident . normal > 0``) is refracted outwards with ``1/eta``.
    Rows with total internal reflection are NaN. ``eta == 1`` returns the
    incident direction unchanged.
    """
    d = _normalize(incident_dir)
    n = _normalize(normal)
    eta = np.asarray(eta, dtype=np.float64)
    cos_i = -np.sum(d * n, axis=-1)
    outside = cos_i >= 0.0
    # orient the normal against the incident direction and pick n1/n2
    n_eff = np.where(outside[..., None], n, -n)
    rel = np.where(outside, 1.0 / eta, eta)          # n_incident / n_transmitted
    cos_i = np.abs(cos_i)
    sin2_t = rel**2 * (1.0 - cos_i**2)
    with np.errstate(invalid="ignore"):
        cos_t = np.sqrt(1.0 - sin2_t)                # NaN on TIR, on purpose
    t = rel[..., None] * d + (rel * cos_i - cos_t)[..., None] * n_eff
    t = np.where((sin2_t > 1.0)[..., None], np.nan, t)
    with np.errstate(invalid="ignore"):
        return _normalize(t)


def fresnel_reflectance(cos_i, eta):
    """Unpolarised dielectric Fresnel reflectance ``R = (R_s + R_p)/2``.

    ``cos_i`` on the incident side (negative: light arrives from inside, so
    ``eta`` is inverted). 1 on total internal reflection; 0 when ``eta == 1``
    (index-matched boundary, Mitsuba's ``null`` BSDF); 1 at grazing incidence
    otherwise.
    """
    cos_i = np.asarray(cos_i, dtype=np.float64)
    eta = np.asarray(eta, dtype=np.float64)
    cos_i, eta = np.broadcast_arrays(cos_i, eta)
    outside = cos_i >= 0.0
    eta_it = np.where(outside, eta, 1.0 / eta)       # n_t / n_i
    ci = np.minimum(np.abs(cos_i), 1.0)
    cos_t2 = 1.0 - (1.0 - ci**2) / eta_it**2
    ct = np.sqrt(np.maximum(cos_t2, 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        a_s = (ci - eta_it * ct) / (ci + eta_it * ct)
        a_p = (eta_it * ci - ct) / (eta_it * ci + ct)
        r = 0.5 * (a_s**2 + a_p**2)
    index_matched = eta == 1.0
    r = np.where(ci == 0.0, 1.0, r)                  # grazing: 0/0 above
    r = np.where(cos_t2 <= 0.0, 1.0, r)              # total internal reflection
    r = np.where(index_matched, 0.0, r)
    return r


def fresnel_transmittance(cos_i, eta):
    """``T = 1 - R`` (Eq. 1 and Eq. 4); 1 everywhere when ``eta == 1``."""
    return 1.0 - fresnel_reflectance(cos_i, eta)


def texel_solid_angles(nx, ny, fov_y_deg, aspect, near=1.0):
    """Solid angle of each shadow-map texel seen from the light -> (ny, nx).

    Sec. 3.1, ``dOmega_p = A_p cos(theta_p) / |r_p|^2 = A_p cos^3(theta_p) /
    near^2``, with the authors' correction: ``A_p`` is the area of the
    shadow-map plane at distance ``near`` divided by ``nx * ny`` (the printed
    formula assumes ``near = 1``). ``fov_y_deg`` is the full vertical field
    of view, ``aspect = width / height`` (the camera convention of
    ``docs/conventions.md``). The result is symmetric, so row order does not
    matter; row 0 is the top by convention. Flux per texel is
    ``Phi_p = I * dOmega_p``.
    """
    nx, ny = int(nx), int(ny)
    near = float(near)
    half_h = near * np.tan(np.radians(fov_y_deg) / 2.0)
    half_w = aspect * half_h
    area_p = (2.0 * half_w) * (2.0 * half_h) / (nx * ny)
    u = ((np.arange(nx) + 0.5) / nx * 2.0 - 1.0) * half_w
    v = (1.0 - (np.arange(ny) + 0.5) / ny * 2.0) * half_h
    uu, vv = np.meshgrid(u, v)                       # (ny, nx)
    cos_theta = near / np.sqrt(near**2 + uu**2 + vv**2)
    return area_p * cos_theta**3 / near**2


def frustum_solid_angle(fov_x_deg, fov_y_deg):
    """Exact solid angle of a rectangular pyramid with full angles in degrees.

    ``Omega = 4 asin(sin(a) sin(b))`` with ``a``, ``b`` the half angles.
    """
    a = np.radians(fov_x_deg) / 2.0
    b = np.radians(fov_y_deg) / 2.0
    return 4.0 * np.arcsin(np.sin(a) * np.sin(b))


def ggx_ndf(cos_h, alpha):
    """GGX normal distribution ``D(h) = a^2 / (pi ((n.h)^2 (a^2 - 1) + 1)^2)``.

    Walter et al. 2007, Eq. 33; zero for ``n.h <= 0``.
    """
    cos_h = np.asarray(cos_h, dtype=np.float64)
    a2 = np.asarray(alpha, dtype=np.float64) ** 2
    denom = cos_h**2 * (a2 - 1.0) + 1.0
    return np.where(cos_h > 0.0, a2 / (np.pi * denom**2), 0.0)


def smith_g1(cos_v, cos_vh, alpha):
    """Smith masking for GGX, ``2 / (1 + sqrt(1 + a^2 tan^2))`` (Walter Eq. 34).

    ``cos_v = n.v``, ``cos_vh = v.h``; zero when ``v`` sees the back of the
    microfacet (``(v.h)(v.n) <= 0``), as Mitsuba's ``smith_g1``.
    """
    cos_v = np.asarray(cos_v, dtype=np.float64)
    a2 = np.asarray(alpha, dtype=np.float64) ** 2
    c2 = np.clip(cos_v**2, 1e-300, 1.0)
    tan2 = (1.0 - c2) / c2
    g = 2.0 / (1.0 + np.sqrt(1.0 + a2 * tan2))
    return np.where(cos_vh * cos_v > 0.0, g, 0.0)


def ggx_reflection(wi, wo, n, alpha, eta):
    """GGX rough-dielectric reflection BRDF ``f_r(wi, wo)`` -> (...).

    ``f_r = D(h) F(wi.h) G(wi, wo) / (4 cos_i cos_o)`` with ``h`` the
    half vector, ``F`` the unpolarised Fresnel reflectance with
    ``eta = n_inside / n_outside``, ``G = G1(wi) G1(wo)`` (separable Smith),
    i.e. the reflection part of Mitsuba's ``roughdielectric`` with
    ``distribution="ggx"`` and ``alpha`` (Walter et al. 2007, Eq. 20).
    ``wi``, ``wo`` point away from the surface; zero unless both lie above
    it. The cosine factor of the rendering equation is NOT included.
    """
    wi = _normalize(wi)
    wo = _normalize(wo)
    n = _normalize(n)
    alpha = np.maximum(np.asarray(alpha, dtype=np.float64), 1e-4)
    cos_i = np.sum(wi * n, axis=-1)
    cos_o = np.sum(wo * n, axis=-1)
    h = wi + wo
    h_len = np.linalg.norm(h, axis=-1, keepdims=True)
    h = h / np.where(h_len > 0.0, h_len, 1.0)
    cos_h = np.sum(h * n, axis=-1)
    cos_ih = np.sum(wi * h, axis=-1)
    cos_oh = np.sum(wo * h, axis=-1)
    d = ggx_ndf(cos_h, alpha)
    f = fresnel_reflectance(cos_ih, eta)
    g = smith_g1(cos_i, cos_ih, alpha) * smith_g1(cos_o, cos_oh, alpha)
    valid = (cos_i > 0.0) & (cos_o > 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        val = d * f * g / (4.0 * cos_i * cos_o)
    return np.where(valid, val, 0.0)
