"""Per-cell LPV material from a scene's medium (Borlum et al. 2011, Sec. 3.2).

SSLPV needs, per LPV cell and colour, an extinction ``sigma_lpv`` for the
Beer attenuation between neighbouring cells (Sec. 3.2.1), a dimensionless
scattering fraction ``sigma_s_prime`` in ``[0, 1]`` for Eq. 2-3
(Sec. 3.2.2), and the HG asymmetry ``g``. The paper leaves open how these
relate to the physical ``sigma_t``, albedo and ``g`` of a medium; this module
makes that choice explicit and selectable.

Parameters of :func:`lpv_material`
----------------------------------

.. list-table::
   :header-rows: 1

   * - parameter
     - default
     - meaning
   * - ``medium``
     - --
     - ``harness.scene.Medium`` (or a ``Scene``, whose ``.medium`` is used):
       ``bbox_min``, ``bbox_max``, float32 grids ``sigma_t``, ``albedo``,
       ``g`` of shape ``(nz, ny, nx, 3)``
   * - ``inside_mask``
     - --
     - ``(N, N, N)`` bool ``[z, y, x]``: LPV cell centre inside the mesh, or
       ``None`` (every cell counts as inside)
   * - ``N``
     - --
     - LPV resolution per axis
   * - ``mapping``
     - ``"collision"``
     - ``"literal"`` or ``"collision"`` (:data:`MAPPINGS`)
   * - ``resample``
     - ``"box"``
     - ``"box"`` (exact overlap average) or ``"point"`` (trilinear at the
       cell centre)
   * - ``outside``
     - ``"vacuum"``
     - ``"vacuum"``: cells outside the mesh get ``sigma_lpv = sigma_s' = 0``;
       ``"material"``: they keep the medium's values

Mappings
--------
``literal``
    ``sigma_lpv = sigma_t``, ``sigma_s' = albedo``: the paper's Sec. 3.2.1
    read word for word (its ``sigma_t`` is the attenuation per cell width)
    and ``sigma_s'`` taken as the single-scattering albedo.
``collision``
    One propagation step crosses a cell width ``dx``. A photon collides with
    probability ``P = 1 - exp(-sigma_t dx)``; absorbed photons are lost and
    scattered ones stay in the step's flux, so the step keeps
    ``exp(-sigma_lpv dx) = exp(-sigma_t dx) + P a`` of the flux, and the kept
    flux that was redirected is ``sigma_s' = P a / (1 - P (1 - a))``. As
    ``dx -> 0``: ``sigma_lpv -> sigma_a`` and ``sigma_s' -> sigma_s dx``.

Resampling (medium grid -> LPV grid)
------------------------------------
Both methods are linear operators ``R`` applied separably per axis, with the
voxel-centre convention of ``docs/conventions.md``. Weighted quantities keep
the physics of a mixture: ``sigma_t = R(sigma_t)``,
``albedo = R(sigma_t a) / R(sigma_t)`` (scattering-weighted),
``g = R(sigma_t a g) / R(sigma_t a)``; where a denominator is 0 the plain
``R(a)`` / ``R(g)`` is used.

Limits
------
* The LPV cells must be cubes (one ``dx`` per step, as the paper's grid);
  a non-cubic medium box raises ``InputError``.
* ``g`` outside cells is kept; it has no effect once ``sigma_s' = 0``.
"""

from __future__ import annotations

import numpy as np

from harness.errors import InputError

__all__ = [
    "MAPPINGS",
    "RESAMPLERS",
    "OUTSIDE_MODES",
    "resample",
    "resample_medium",
    "map_material",
    "lpv_material",
]


# ---------------------------------------------------------------- resampling

def _box_weights(n_src, n_dst):
    """(n_dst, n_src) exact overlap fractions of source cells in each LPV cell."""
    edges_s = np.linspace(0.0, 1.0, n_src + 1)
    edges_d = np.linspace(0.0, 1.0, n_dst + 1)
    lo = np.maximum(edges_d[:-1, None], edges_s[None, :-1])
    hi = np.minimum(edges_d[1:, None], edges_s[None, 1:])
    w = np.clip(hi - lo, 0.0, None)
    return w / w.sum(axis=1, keepdims=True)


def _point_weights(n_src, n_dst):
    """(n_dst, n_src) linear-interpolation weights at LPV cell centres."""
    # LPV centre (I+0.5)/N sits at continuous source index u*n - 0.5
    x = (np.arange(n_dst) + 0.5) / n_dst * n_src - 0.5
    x = np.clip(x, 0.0, n_src - 1)                   # clamp to the outer centres
    i0 = np.minimum(np.floor(x).astype(np.int64), n_src - 1)
    i1 = np.minimum(i0 + 1, n_src - 1)
    f = x - i0
    w = np.zeros((n_dst, n_src))
    rows = np.arange(n_dst)
    np.add.at(w, (rows, i0), 1.0 - f)
    np.add.at(w, (rows, i1), f)
    return w


RESAMPLERS = {"box": _box_weights, "point": _point_weights}


def _check_choice(value, registry, setting):
    if value not in registry:
        raise InputError(
            f"--{setting}", setting, f"unknown {setting} '{value}'",
            "use one of: " + ", ".join(registry),
        )


def resample(grid, N, method="box"):
    """Resample a ``(nz, ny, nx, C)`` grid onto ``(N, N, N, C)`` -> float64.

    ``"box"``: average over each LPV cell with exact per-axis overlap weights
    (any ``n`` to any ``N``). ``"point"``: trilinear value at each LPV cell
    centre (clamped to the outermost voxel centres). Both are separable.
    """
    _check_choice(method, RESAMPLERS, "resample")
    g = np.asarray(grid, dtype=np.float64)
    nz, ny, nx = g.shape[:3]
    wz, wy, wx = (RESAMPLERS[method](n, int(N)) for n in (nz, ny, nx))
    return np.einsum("Kk,Jj,Ii,kji...->KJI...", wz, wy, wx, g, optimize=True)


def _ratio(num, den, fallback):
    with np.errstate(invalid="ignore", divide="ignore"):
        r = num / den
    return np.where(den > 0.0, r, fallback)


def resample_medium(medium, N, method="box"):
    """Medium grids on the LPV grid -> ``(sigma_t, albedo, g)``, each (N,N,N,3) float64.

    ``sigma_t`` is resampled directly, ``albedo`` weighted by ``sigma_t`` and
    ``g`` by ``sigma_t * albedo`` (the scattering coefficient), so that a cell
    mixing a dense and a thin voxel scatters like the mixture.
    """
    st = np.asarray(medium.sigma_t, dtype=np.float64)
    a = np.asarray(medium.albedo, dtype=np.float64)
    g = np.asarray(medium.g, dtype=np.float64)
    r_st = resample(st, N, method)
    r_ss = resample(st * a, N, method)
    albedo = _ratio(r_ss, r_st, resample(a, N, method))
    g_out = _ratio(resample(st * a * g, N, method), r_ss, resample(g, N, method))
    return r_st, albedo, g_out


# ------------------------------------------------------------------ mappings

def _literal(sigma_t, albedo, dx):
    return np.array(sigma_t, dtype=np.float64), np.array(albedo, dtype=np.float64)


def _collision(sigma_t, albedo, dx):
    st = np.asarray(sigma_t, dtype=np.float64)
    a = np.asarray(albedo, dtype=np.float64)
    p = -np.expm1(-st * dx)                          # collision probability per cell
    lost = p * (1.0 - a)                             # absorbed in one step
    with np.errstate(divide="ignore"):
        sigma_lpv = -np.log1p(-lost) / dx            # exp(-s dx) = exp(-st dx) + P a
    sigma_s_prime = _ratio(p * a, 1.0 - lost, 0.0)
    return sigma_lpv, sigma_s_prime


MAPPINGS = {"literal": _literal, "collision": _collision}


def map_material(sigma_t, albedo, dx, mapping="collision"):
    """Physical ``(sigma_t, albedo)`` -> LPV ``(sigma_lpv, sigma_s_prime)``, float64.

    See the module docstring for the two mappings. ``dx`` is the LPV cell
    width in scene units. Unknown ``mapping`` raises ``InputError``.
    """
    _check_choice(mapping, MAPPINGS, "mapping")
    return MAPPINGS[mapping](sigma_t, albedo, float(dx))


# ------------------------------------------------------------- front door

#: ``outside`` choices of :func:`lpv_material`.
OUTSIDE_MODES = ("vacuum", "material")


def lpv_material(medium, inside_mask, N, mapping="collision", resample="box", outside="vacuum"):
    """LPV material grids for Sec. 3.2 -> dict of float32 (N, N, N, 3).

    Keys ``sigma_lpv`` (per scene unit), ``sigma_s_prime`` (in ``[0, 1]``)
    and ``g``; arrays are indexed ``[z, y, x, colour]``. Parameters are
    described in the module docstring.
    """
    _check_choice(mapping, MAPPINGS, "mapping")
    _check_choice(resample, RESAMPLERS, "resample")
    _check_choice(outside, OUTSIDE_MODES, "outside")
    medium = getattr(medium, "medium", medium)       # accept a Scene too
    N = int(N)
    extent = np.asarray(medium.bbox_max, dtype=np.float64) - np.asarray(
        medium.bbox_min, dtype=np.float64)
    dxs = extent / N
    if not np.allclose(dxs, dxs[0], rtol=1e-6, atol=0.0):
        raise InputError(
            "medium", "bbox_min/bbox_max",
            f"LPV cells are not cubes (box extent {extent.tolist()})",
            "make the medium box a cube",
        )
    dx = float(dxs[0])

    sigma_t, albedo, g = resample_medium(medium, N, resample)
    sigma_lpv, sigma_s_prime = map_material(sigma_t, albedo, dx, mapping)
    sigma_s_prime = np.clip(sigma_s_prime, 0.0, 1.0)

    if outside == "vacuum" and inside_mask is not None:
        mask = np.asarray(inside_mask, dtype=bool)
        if mask.shape != (N, N, N):
            raise InputError(
                "inside_mask", "shape", f"expected {(N, N, N)}, got {mask.shape}",
                "pass the LPV grid's cell-centre inside mask",
            )
        # outside the mesh light travels in vacuum: no attenuation, no scattering
        sigma_lpv = np.where(mask[..., None], sigma_lpv, 0.0)
        sigma_s_prime = np.where(mask[..., None], sigma_s_prime, 0.0)

    return {
        "sigma_lpv": sigma_lpv.astype(np.float32),
        "sigma_s_prime": sigma_s_prime.astype(np.float32),
        "g": g.astype(np.float32),
    }
