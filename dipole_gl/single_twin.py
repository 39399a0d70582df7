"""NumPy twin of ``single.comp``: Jensen et al. 2001's single-scattering term S^(1), in float64.

:func:`single_scattering` evaluates the pass of :mod:`dipole_gl.single` at given exit points,
from the light atlas that GL rendered (read back with :func:`dipole_gl.single.read_atlas`): the
same march, the same bilinear lookup of the entry point, the same formulas (the module
docstring of :mod:`dipole_gl.single` states them). :func:`halfspace` is the closed form of the
same estimator on a flat half-space under a distant light, the independent route of the tests.
"""

from __future__ import annotations

import numpy as np

from sslpv_gl.optics import fresnel_transmittance, refract

from .medium import lookup
from .single import N_MARCH

__all__ = ["single_scattering", "hg", "exit_material", "halfspace"]


def hg(cos_t, g):
    """Henyey-Greenstein ``p = (1 - g^2) / (4 pi (1 + g^2 - 2 g cos)^(3/2))``, broadcast over colours."""
    d = 1.0 + g * g - 2.0 * g * cos_t
    return (1.0 - g * g) / (4.0 * np.pi * d * np.sqrt(d))


def exit_material(mat, points, normals):
    """``(sigma_s, sigma_t, g)`` (P, 3) at exit points: the GL pass's float32 textures, read as it does."""
    sp, sa, st = (np.asarray(a, np.float32).astype(np.float64) for a in
                  lookup(mat, np.asarray(points, np.float32).astype(np.float64),
                         np.asarray(normals, np.float32).astype(np.float64)))
    ss = st - sa
    return ss, st, 1.0 - sp / ss


def _entry(x, light_pos, vp, tile, atlas_pos, atlas_nrm, size):
    """Bilinear lookup of the light atlas at points ``x`` (N, 3): ``(ok, d_i, n_i)`` as ``single.comp``."""
    h = np.concatenate([x, np.ones((len(x), 1))], axis=1) @ np.asarray(vp, np.float32).astype(np.float64).T
    w = h[:, 3]
    ok = w > 0.0
    uv = h[:, :2] / np.where(ok, w, 1.0)[:, None] * 0.5 + 0.5
    ok &= np.all((uv >= 0.0) & (uv <= 1.0), axis=1)
    f = uv * size - 0.5
    i0 = np.floor(f).astype(np.int64)
    t = f - i0
    wsum = np.zeros(len(x))
    dsum = np.zeros(len(x))
    nsum = np.zeros((len(x), 3))
    for ox, oy in ((0, 0), (1, 0), (0, 1), (1, 1)):
        qx = np.clip(i0[:, 0] + ox, 0, size - 1) + tile * size
        qy = np.clip(i0[:, 1] + oy, 0, size - 1)
        p = atlas_pos[qy, qx].astype(np.float64)
        valid = p[:, 3] >= 0.5
        wt = np.where(valid, (t[:, 0] if ox else 1.0 - t[:, 0]) * (t[:, 1] if oy else 1.0 - t[:, 1]), 0.0)
        wsum += wt
        dsum += wt * np.linalg.norm(p[:, :3] - light_pos, axis=1)
        nsum += wt[:, None] * atlas_nrm[qy, qx, :3].astype(np.float64)
    nl = np.linalg.norm(nsum, axis=1)
    ok &= (wsum > 0.0) & (nl > 0.0)
    d_i = dsum / np.where(ok, wsum, 1.0)
    n_i = nsum / np.where(ok, nl, 1.0)[:, None]
    return ok, d_i, n_i


def single_scattering(exit_pos, exit_nrm, cam_pos, atlas, views, lights, mat, eta, size, n_march=N_MARCH):
    """S^(1) radiance (P, 3) at exit points, as ``single.comp`` computes it.

    ``atlas`` = (positions, normals) from :func:`dipole_gl.single.read_atlas`; ``views`` the
    lights' :class:`sslpv_gl.rsm.LightView` (their ``view_proj`` and ``tan_half``); ``size`` the
    atlas tile size.
    """
    xo = np.asarray(exit_pos, np.float64)
    no = np.asarray(exit_nrm, np.float64)
    no = no / np.linalg.norm(no, axis=1, keepdims=True)
    atlas_pos, atlas_nrm = atlas
    eta = float(eta)
    wo = np.asarray(cam_pos, np.float64) - xo
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    mu_o = np.sum(wo * no, axis=1)
    front = mu_o > 0.0
    d = np.where(front[:, None], refract(np.where(front[:, None], -wo, -no), no, eta), -no)   # the refracted view ray
    ss, st, g = exit_material(mat, xo, no)
    sref = st.min(axis=1)
    u = (np.arange(n_march) + 0.5) / n_march
    s = -np.log(1.0 - u)[None, :] / sref[:, None]              # (P, K)
    wk = np.exp(-(st[:, None, :] - sref[:, None, None]) * s[..., None]) / (n_march * sref[:, None, None])
    P, K = s.shape
    x = (xo[:, None, :] + s[..., None] * d[:, None, :]).reshape(-1, 3)
    back = np.repeat(-d, K, axis=0)
    ssx, stx, gx = (np.repeat(a, K, axis=0) for a in (ss, st, g))
    acc = np.zeros((P * K, 3))
    for li, (light, view) in enumerate(zip(lights, views)):
        y = np.asarray(light.position, np.float32).astype(np.float64)
        to = y - x
        dist = np.linalg.norm(to, axis=1)
        wi = to / dist[:, None]
        ok, d_i, n_i = _entry(x, y, view.view_proj, li, atlas_pos, atlas_nrm, size)
        cos_i = np.sum(wi * n_i, axis=1)
        ok &= cos_i > 0.0
        s_i = dist - d_i
        ok &= s_i >= 0.0                                        # x in front of the lit surface: outside
        s_i = np.maximum(s_i, 0.0)
        c = np.where(ok, cos_i, 1.0)
        cos_t = np.sqrt(np.maximum(1.0 - (1.0 - c * c) / eta**2, 0.0))
        sp_i = s_i * c / cos_t                                  # Jensen's s'_i
        with np.errstate(invalid="ignore", divide="ignore"):      # rows not ok are dropped below
            w12 = refract(-wi, np.where(ok[:, None], n_i, wi), eta)
        spread = (d_i + sp_i / eta) * (d_i + sp_i * c * c / (eta * cos_t * cos_t))
        e = fresnel_transmittance(c, eta) * (c / cos_t) / spread
        cos_ph = np.sum(w12 * back, axis=1)
        term = np.asarray(light.intensity, np.float64) * e[:, None] * ssx * hg(cos_ph[:, None], gx) \
            * np.exp(-stx * sp_i[:, None])
        acc += np.where(ok[:, None], term, 0.0)
    out = np.einsum("pkc,pkc->pc", wk, acc.reshape(P, K, 3))
    out *= (fresnel_transmittance(np.where(front, mu_o, 1.0), eta) / eta**2)[:, None]
    return np.where(front[:, None], out, 0.0)


def halfspace(sigma_s, sigma_t, g, eta, cos_view, cos_light, cos_phase, irradiance):
    """Closed form of the estimator on a flat half-space lit by a distant light (independent route).

    With depth ``z = s mu_o'`` along the refracted view ray and the light's refracted path
    ``s'_i = z / mu_i'`` (``mu'`` the refracted cosines), ``int_0^inf e^(-sigma_t s (1 + mu_o'/mu_i')) ds
    = 1 / (sigma_t (1 + mu_o'/mu_i'))``, so
    ``L1 = T(mu_o) T(mu_i) / eta^2 (mu_i / mu_i') sigma_s p / (sigma_t (1 + mu_o'/mu_i')) E``
    (``E`` the light's irradiance perpendicular to its direction, ``cos_phase`` the cosine
    between the two refracted travel directions).
    """
    mo = np.sqrt(1.0 - (1.0 - cos_view**2) / eta**2)
    mi = np.sqrt(1.0 - (1.0 - cos_light**2) / eta**2)
    t = fresnel_transmittance(cos_view, eta) * fresnel_transmittance(cos_light, eta)
    return t / eta**2 * (cos_light / mi) * sigma_s * hg(cos_phase, g) / (sigma_t * (1.0 + mo / mi)) * irradiance
