"""NumPy twin of the atlas gather's three GL passes (Carr, Hall & Hart 2003, Sec. 4.2.2-4.2.4), in float64.

.. list-table::
   :header-rows: 1

   * - function
     - GL pass
     - what
   * - :func:`radiosity_map`
     - ``irradiance.comp`` over the texels, ``atlas_radiosity.comp``, MIP-mapping
     - per texel the transmitted flux ``E_t a`` (:func:`dipole_gl.twin.irradiance`, summed over
       lights), and every MIP level as the mean of 2 x 2 texels of the level below
   * - :func:`gather`
     - ``gather_atlas.comp``
     - per texel ``B_b = sum_k G_k mip[level_k][v_k, u_k]`` (Eq. 9)
   * - :func:`shade`
     - ``atlas_shade.vert/frag``
     - ``T(w_o)/pi B`` with ``B`` looked up bilinearly at the fragment's atlas coordinates
"""

from __future__ import annotations

import numpy as np

from sslpv_gl.optics import fresnel_transmittance

from . import links as links_mod

__all__ = ["radiosity_map", "gather", "bilinear", "shade"]


def radiosity_map(atlas, flux):
    """``flux`` (L, P, 3) per light and texel -> the MIP levels, level 0 first, each (n, n, 3)."""
    level = np.asarray(flux, np.float64).sum(axis=0).reshape(atlas.size, atlas.size, 3)
    out = [level]
    while level.shape[0] > 1:
        n = level.shape[0] // 2
        level = level.reshape(n, 2, n, 2, 3).mean(axis=(1, 3))
        out.append(level)
    return out


def gather(lk, mips, texels=None):
    """The scattered irradiance ``B`` (P', 3) at flat texel indices ``texels`` (all by default)."""
    rows = np.arange(lk.node.shape[0]) if texels is None else np.asarray(texels)
    node, g = lk.node[rows], lk.g[rows]
    level, u, v = links_mod.decode(np.maximum(node, 0))
    val = np.zeros(node.shape + (3,))
    for lv in np.unique(level):
        sel = (level == lv) & (node >= 0)
        val[sel] = mips[lv][v[sel], u[sel]]
    return np.einsum("pkc,pkc->pc", g, val)


def bilinear(image, uv):
    """GL's bilinear lookup (clamp to edge) of ``image`` (n, n, 3) at ``uv`` (M, 2) in [0, 1]."""
    n = image.shape[0]
    x = np.asarray(uv, np.float64) * n - 0.5
    x0 = np.floor(x).astype(np.int64)
    f = x - x0
    out = 0.0
    for dx in (0, 1):
        for dy in (0, 1):
            w = (f[:, 0] if dx else 1.0 - f[:, 0]) * (f[:, 1] if dy else 1.0 - f[:, 1])
            xi = np.clip(x0[:, 0] + dx, 0, n - 1)
            yi = np.clip(x0[:, 1] + dy, 0, n - 1)
            out = out + w[:, None] * image[yi, xi]
    return out


def footprint(size, uv):
    """The flat texel indices a bilinear lookup at ``uv`` (M, 2) reads."""
    x0 = np.floor(np.asarray(uv, np.float64) * size - 0.5).astype(np.int64)
    idx = [np.clip(x0[:, 1] + dy, 0, size - 1) * size + np.clip(x0[:, 0] + dx, 0, size - 1)
           for dx in (0, 1) for dy in (0, 1)]
    return np.unique(np.concatenate(idx))


def shade(scatter, uv, pos, nrm, cam_pos, eta):
    """Pass 3 at fragments (atlas coordinates ``uv``, points, normals) -> radiance (M, 3)."""
    b = bilinear(scatter, uv)
    wo = np.asarray(cam_pos, np.float64) - pos
    n = nrm / np.linalg.norm(nrm, axis=-1, keepdims=True)
    cos_o = np.sum(wo * n, axis=-1) / np.linalg.norm(wo, axis=-1)
    return b / np.pi * fresnel_transmittance(np.clip(cos_o, 0.0, 1.0), eta)[:, None]
