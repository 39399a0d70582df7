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
     - ``"literal"``, ``"collision"``, ``"diffusion"`` or ``"transport"`` (:data:`MAPPINGS`)
   * - ``resample``
     - ``"box"``
     - ``"box"`` (exact overlap average) or ``"point"`` (trilinear at the
       cell centre)
   * - ``outside``
     - ``"vacuum"``
     - ``"vacuum"``: cells outside the mesh get ``sigma_lpv = sigma_s' = 0``;
       ``"material"``: they keep the medium's values; ``"absorb"`` and
       ``"extrapolated"``: sink cells; ``"interior"``: no light moves between
       two outside cells (:mod:`sslpv_gl.boundary`, which documents all five)
   * - ``eta``
     - ``1.0``
     - the boundary's relative index (``extrapolated``: ``z_b = 2 A(eta) D``)
   * - ``sigma_scale``
     - ``1.0``
     - multiplies the mapped ``sigma_lpv`` (a calibrated free parameter)
   * - ``phase_scaling``
     - ``"none"``
     - ``"none"`` (the paper) or ``"delta-eddington"`` (:func:`delta_eddington`,
       applied to the resampled medium before the mapping)
   * - ``form``
     - ``None``
     - a :class:`sslpv_gl.material_form.Form`: per-cell factors on ``sigma_lpv`` and on the
       radiance scale from each cell's dimensionless numbers (Eq. F1 there; a calibrated
       mapping of version 3)

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
``diffusion``
    Matches diffusion theory (``docs/diffusion_mapping.md``, Eq. (14)-(21);
    :func:`sslpv_gl.diffusion.diffusion_mapping`): with ``sigma_tr =
    sqrt(3 sigma_a sigma_t')``, ``sigma_t' = sigma_a + sigma_s (1 - g)``,
    ``sigma_lpv = ln(1 + D_lpv (sigma_tr dx)^2) / dx`` makes the lattice's
    steady-state diffusion length ``1 / sigma_tr`` at every ``dx``
    (Eq. (16)); ``sigma_s' = 1`` and the LATTICE ``g = k1 = -1`` (Eq. (17),
    the most isotropic lattice; the medium's ``g`` enters only through
    ``sigma_t'``). It is the only mapping with a ``radiance_scale`` other
    than 1 (Eq. (21)).
``transport`` (an extension: not the paper's)
    One propagation step is one cell of the light's path, in time as well as in space
    (``docs/diffusion_mapping.md`` Sec. 11). The lattice moves every light by one cell per step,
    but its band-1 part keeps only ``b k1`` (``b = 0.4026``) of a beam's direction per hop, so at
    the paper's ``k1 <= 1`` it diffuses at most ``D_lpv(1) = 0.2258`` cells^2 per step (Eq. (9)),
    while light in a medium whose reduced mean free path is ``l_tr`` cells diffuses
    ``D = l_tr / 3`` cells^2 per cell of path. ``transport`` sets ``sigma_lpv = sigma_a`` (a step
    survives ``exp(-sigma_a dx)``, what a cell of path does), ``sigma_s' = 1`` and the LATTICE
    ``g = k1`` with

        D_lpv(k1) = 1 / (3 sigma_t (1 - albedo g) dx)                                   (T1)

    (Eq. (10) inverts (9)), clipped to ``[-1, TRANSPORT_K1_MAX]``: ``k1 > 1`` gives back the
    direction that the lattice's own hop forgets. Diffusion then takes as many steps as cells of
    path, and the steady state's diffusion length is the medium's. It needs cells outside the
    mesh that take light out of the propagation (:data:`TRANSPORT_OUTSIDE`): with ``vacuum``,
    ``material`` or ``extrapolated`` the amplified band 1 carries light round the object and
    rings into negative radiance.

Forward-peaked media: delta-Eddington scaling
---------------------------------------------
The lattice's Eq. 3 carries the phase function through one band-1 factor, which a
forward-peaked lobe (g -> 1) does not fit. ``phase_scaling = "delta-eddington"`` treats the
forward peak as unscattered light (Joseph, Wiscombe & Weinman 1976, Eq. 2-5): with
``f = g^2``,

    sigma_t* = sigma_t (1 - a f),   a* = a (1 - f) / (1 - a f),   g* = (g - f) / (1 - f) = g / (1 + g),

which keeps the absorption ``sigma_a`` and the reduced scattering ``sigma_s (1 - g)`` (so the
``diffusion`` mapping, which depends on them only, is unchanged) and moves the rest into the
unscattered beam. It is applied where ``g > 0`` only (a backward lobe has no forward peak to
remove). Limit: f = g^2 matches the HG phase function's second moment, not its whole lobe.

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
* ``diffusion``: exact for a homogeneous medium far from boundaries; in a
  heterogeneous medium it is applied cell by cell, which is exact where
  ``sigma_t'`` is constant (``sigma_a`` may vary) but not across jumps of
  ``D`` (docs Sec. 6). ``transport``: ``l_tr`` above ``3 D_lpv(TRANSPORT_K1_MAX) = 19.7`` cells
  (``sigma_t' dx`` below 0.051) or below ``3 D_lpv(-1) = 0.42`` cells is clipped, so such a
  medium diffuses slower, or faster, per step than per cell of path. Vacuum cells (``sigma_t = 0``) get a zero
  ``radiance_scale``. Under ``outside = absorb``, ``extrapolated`` and ``interior``
  the cells without the medium (sinks, empty cells) get ``radiance_scale = 1``: they
  hold flux that left the medium, not the lattice's fluence
  (``docs/diffusion_mapping.md`` Sec. 7).
"""

from __future__ import annotations

import numpy as np

from harness.errors import InputError

from . import boundary, diffusion, lattice
from .material_form import cell_numbers, extent_cells

__all__ = [
    "MAPPINGS",
    "RESAMPLERS",
    "OUTSIDE_MODES",
    "resample",
    "resample_medium",
    "map_material",
    "map_material_full",
    "lpv_material",
    "PHASE_SCALINGS",
    "EXITANCES",
    "check_exitance",
    "delta_eddington",
    "transport_k1",
    "medium_diffusion",
    "lattice_diffusion",
    "TRANSPORT_K1_MAX",
    "TRANSPORT_OUTSIDE",
    "check_transport_outside",
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


def _diffusion(sigma_t, albedo, dx, g=0.0):
    # Eq. (16)-(17) of docs/diffusion_mapping.md; Eq. 3's k1 needs the lattice g
    # that map_material_full returns (sigma_s' = 1, g = k1)
    m = diffusion.diffusion_mapping(sigma_t, albedo, g, dx)
    return m["sigma_lpv"], m["sigma_s_prime"]


#: Band-1 factor bounds of ``transport``: a step's band-1 eigenvalue ``b k1`` stays below
#: ``a = 1`` (docs Eq. (4); 0.986 at 2.45, where ``D_lpv`` = 6.55 cells^2 per step) and ``k1 >= -1``.
TRANSPORT_K1_MAX = 2.45
TRANSPORT_K1_MIN = -1.0
#: ``outside`` modes ``transport`` supports: empty cells take light out of the propagation.
TRANSPORT_OUTSIDE = ("absorb", "interior")


def check_transport_outside(mapping, outside):
    """One line when ``transport`` is combined with an ``outside`` mode it does not support."""
    if mapping == "transport" and outside not in TRANSPORT_OUTSIDE:
        raise InputError("--outside", "outside", f"mapping transport needs cells outside the mesh that take light out "
                         f"of the propagation, got {outside!r}", "use --outside " + " or ".join(TRANSPORT_OUTSIDE))


def medium_diffusion(sigma_t, albedo, g, dx):
    """The medium's diffusion coefficient in cells^2 per cell of path: ``D = l_tr / 3 = 1 / (3 sigma_t (1 -
    albedo g) dx)`` (docs Sec. 11); ``inf`` where the reduced extinction is 0."""
    reduced = np.asarray(sigma_t, dtype=np.float64) * (1.0 - np.asarray(albedo, dtype=np.float64)
                                                       * np.asarray(g, dtype=np.float64))
    with np.errstate(divide="ignore"):
        return np.where(reduced > 0.0, 1.0 / (3.0 * np.maximum(reduced, 1e-300) * float(dx)), np.inf)


def lattice_diffusion(sigma_t, albedo, g, dx, mapping="collision"):
    """The diffusion coefficient ``D_lpv`` (cells^2 per step, Eq. (9)) of the lattice ``mapping`` makes of the
    medium, through Eq. 3's band-1 factor ``k1 = (1 - sigma_s') + sigma_s' g``."""
    m = map_material_full(sigma_t, albedo, g, dx, mapping)
    return lattice.d_lpv((1.0 - m["sigma_s_prime"]) + m["sigma_s_prime"] * m["g"])


def transport_k1(sigma_t, albedo, g, dx):
    """The lattice ``g = k1`` of ``transport`` (Eq. (T1)): ``D_lpv(k1) = l_tr / 3``, ``l_tr`` in cells, clipped."""
    d_min, d_max = float(lattice.d_lpv(TRANSPORT_K1_MIN)), float(lattice.d_lpv(TRANSPORT_K1_MAX))
    # Eq. (10) is monotonic between the bounds only (it has a pole below D_lpv(-1)): clip D first
    k1 = lattice.k1_for_d_lpv(np.clip(medium_diffusion(sigma_t, albedo, g, dx), d_min, d_max))
    return np.clip(k1, TRANSPORT_K1_MIN, TRANSPORT_K1_MAX)


def _transport(sigma_t, albedo, dx, g=0.0):
    sigma_a = np.asarray(sigma_t, dtype=np.float64) * (1.0 - np.asarray(albedo, dtype=np.float64))
    return sigma_a, np.ones_like(sigma_a)


MAPPINGS = {"literal": _literal, "collision": _collision, "diffusion": _diffusion, "transport": _transport}


def map_material(sigma_t, albedo, dx, mapping="collision", g=None):
    """Physical ``(sigma_t, albedo)`` -> LPV ``(sigma_lpv, sigma_s_prime)``, float64.

    See the module docstring for the mappings. ``dx`` is the LPV cell
    width in scene units. ``g`` (the medium's, default 0) is used only by
    ``diffusion``, whose Eq. 3 factor also needs the lattice ``g`` of
    :func:`map_material_full` (as does ``transport``'s). Unknown ``mapping`` raises ``InputError``.
    """
    _check_choice(mapping, MAPPINGS, "mapping")
    if mapping == "diffusion":
        return _diffusion(sigma_t, albedo, float(dx), 0.0 if g is None else g)
    return MAPPINGS[mapping](sigma_t, albedo, float(dx))


def map_material_full(sigma_t, albedo, g, dx, mapping="collision"):
    """Everything a mapping sets -> dict of float64 arrays (broadcast shape).

    Keys ``sigma_lpv``, ``sigma_s_prime``, ``g`` (the ``g`` Eq. 3 is to use:
    the medium's for ``literal``/``collision``, the lattice's ``k1`` for
    ``diffusion``) and ``radiance_scale`` (the factor on the shaded
    subsurface radiance, Eq. (21) of ``docs/diffusion_mapping.md``; 1 for
    ``literal``/``collision``).
    """
    _check_choice(mapping, MAPPINGS, "mapping")
    if mapping == "diffusion":
        m = diffusion.diffusion_mapping(sigma_t, albedo, g, float(dx))
        return {k: m[k] for k in ("sigma_lpv", "sigma_s_prime", "g", "radiance_scale")}
    sigma_lpv, sp = MAPPINGS[mapping](sigma_t, albedo, float(dx))
    if mapping == "transport":                       # the lattice g is k1 (Eq. (T1)), with sigma_s' = 1
        g = transport_k1(sigma_t, albedo, g, float(dx))
    shape = np.broadcast(np.asarray(sigma_lpv), np.asarray(sp), np.asarray(g)).shape
    return {
        "sigma_lpv": np.broadcast_to(sigma_lpv, shape).astype(np.float64),
        "sigma_s_prime": np.broadcast_to(sp, shape).astype(np.float64),
        "g": np.broadcast_to(np.asarray(g, dtype=np.float64), shape).copy(),
        "radiance_scale": np.ones(shape),
    }


# ------------------------------------------------------------- front door

#: ``outside`` choices of :func:`lpv_material` (:mod:`sslpv_gl.boundary`).
OUTSIDE_MODES = boundary.OUTSIDE_MODES


#: ``phase_scaling`` choices of :func:`lpv_material`.
PHASE_SCALINGS = ("none", "delta-eddington")
#: How the shading reads a ``diffusion`` cell: its isotropic part (Eq. (21)) or the exitance at the
#: extrapolated boundary (Eq. (D5) of :mod:`sslpv_gl.bounded`).
EXITANCES = ("isotropic", "boundary")


def check_exitance(family, outside, exitance):
    """One line when ``exitance = boundary`` is combined with a mapping or outside treatment it does not support."""
    if exitance not in EXITANCES:
        raise InputError("--exitance", "exitance", f"unknown exitance {exitance!r}", "use one of: " + ", ".join(EXITANCES))
    if exitance == "boundary" and (family != "diffusion" or outside != "extrapolated"):
        raise InputError("--exitance", "exitance", "boundary reads the exitance at diffusion theory's extrapolated "
                         f"boundary, which needs the diffusion mapping and outside extrapolated; got mapping "
                         f"{family!r}, outside {outside!r}",
                         "pass --mapping diffusion --outside extrapolated, or leave --exitance at isotropic")


def boundary_exitance_factor(sigma_t, albedo, g, zb_cells, dx):
    """Eq. (D5) in a render: the factor on Eq. (21)'s radiance scale that reads a cell as ``J / pi``.

    ``J = D phi / z`` with ``z`` where the lattice's fluence vanishes past the surface: ``z_b = 2 A D``
    (Eq. (B3); ``zb_cells`` is it in cells, as the ``extrapolated`` layer has it), or, where the layer
    cannot hold it (``z_b`` under ``1/2 + o(0)`` cells, Eq. (B4): the layer is empty and the zero lies just
    inside the first sink's centre), that distance. Eq. (21) reads ``phi / (4 pi)``, so the factor is
    ``4 D / z``: ``2 / A(eta)`` where the layer holds ``z_b``.
    """
    from .bounded import partial_sink_offsets

    _, sigma_tp, _ = diffusion.diffusion_coefficients(sigma_t, albedo, g)
    D = 1.0 / (3.0 * np.asarray(sigma_tp, dtype=np.float64))
    zb = np.asarray(zb_cells, dtype=np.float64) * float(dx)
    z_min = (0.5 + float(partial_sink_offsets()[1][0])) * float(dx)
    return 4.0 * D / np.maximum(zb, z_min)


def delta_eddington(sigma_t, albedo, g):
    """``(sigma_t*, albedo*, g*)``: delta-Eddington scaling with ``f = g^2`` where ``g > 0`` (module docstring)."""
    st, a, g = (np.asarray(v, dtype=np.float64) for v in (sigma_t, albedo, g))
    f = np.where(g > 0.0, g * g, 0.0)
    keep = 1.0 - a * f                               # the share of sigma_t that stays an interaction
    st_s = st * keep
    a_s = _ratio(a * (1.0 - f), keep, 0.0)
    g_s = np.where(g > 0.0, g / (1.0 + np.maximum(g, 0.0)), g)
    return st_s, a_s, g_s


def lpv_material(medium, inside_mask, N, mapping="collision", resample="box", outside="vacuum", eta=1.0,
                 sigma_scale=1.0, resampled=None, phase_scaling="none", form=None, exitance="isotropic"):
    """LPV material grids for Sec. 3.2 -> dict of float32 (N, N, N, 3).

    Keys ``sigma_lpv`` (per scene unit), ``sigma_s_prime`` (in ``[0, 1]``),
    ``g`` (Eq. 3's; the lattice's for ``diffusion``), ``radiance_scale``
    (multiplies the shaded subsurface radiance read from each cell, Eq. (21)
    of ``docs/diffusion_mapping.md``; all 1 except for ``diffusion``) and
    ``emit`` (0 in sink cells, :mod:`sslpv_gl.boundary`), and for ``outside =
    "interior"`` only, ``empty`` (1 in outside cells: no transfer between two of them); arrays are indexed
    ``[z, y, x, colour]``. ``outside`` is one of
    :data:`sslpv_gl.boundary.OUTSIDE_MODES`; ``eta`` (the boundary's index)
    sets the extrapolation distance of ``extrapolated``; ``sigma_scale``
    multiplies the mapped ``sigma_lpv`` (a calibrated free parameter,
    :mod:`sslpv_gl.calibrated`); ``resampled`` is ``resample_medium(medium, N,
    resample)`` when the caller already has it; ``phase_scaling`` one of :data:`PHASE_SCALINGS`;
    ``exitance = "boundary"`` (``diffusion`` with ``extrapolated`` only) multiplies the medium cells'
    radiance scale by :func:`boundary_exitance_factor` (Eq. (D5)); ``form`` (a
    :class:`~sslpv_gl.material_form.Form`) multiplies ``sigma_lpv`` by its per-cell
    sigma factor and adds ``radiance_factor`` (float64, its per-cell radiance factor, which
    :func:`sslpv_gl.steps._with_global_scale` folds into ``radiance_scale`` with the budget's
    scalar one). Other parameters: the module docstring.
    """
    _check_choice(mapping, MAPPINGS, "mapping")
    if inside_mask is not None:
        check_transport_outside(mapping, outside)
    if phase_scaling not in PHASE_SCALINGS:
        raise InputError("phase_scaling", "phase_scaling", f"unknown phase_scaling {phase_scaling!r}",
                         "use one of: " + ", ".join(PHASE_SCALINGS))
    _check_choice(resample, RESAMPLERS, "resample")
    _check_choice(outside, OUTSIDE_MODES, "outside")
    check_exitance(mapping, outside, exitance)
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

    sigma_t, albedo, g_medium = resampled if resampled is not None else resample_medium(medium, N, resample)
    if phase_scaling == "delta-eddington":
        sigma_t, albedo, g_medium = delta_eddington(sigma_t, albedo, g_medium)
    mapped = map_material_full(sigma_t, albedo, g_medium, dx, mapping)
    sigma_lpv, g = mapped["sigma_lpv"], mapped["g"]
    if sigma_scale != 1.0:
        sigma_lpv = sigma_lpv * float(sigma_scale)
    radiance_factor = None
    if form is not None:                             # Eq. (F1) of sslpv_gl.material_form, per cell
        numbers = cell_numbers(sigma_t, albedo, g_medium, dx, eta, extent_cells(inside_mask, N), form.steps)
        sigma_factor, radiance_factor = form.factors(numbers)
        sigma_lpv = sigma_lpv * sigma_factor
    sigma_s_prime = np.clip(mapped["sigma_s_prime"], 0.0, 1.0)
    emit = np.ones_like(sigma_lpv)
    empty = None
    radiance_scale = mapped["radiance_scale"]

    if inside_mask is not None:
        mask = np.asarray(inside_mask, dtype=bool)
        if mask.shape != (N, N, N):
            raise InputError(
                "inside_mask", "shape", f"expected {(N, N, N)}, got {mask.shape}",
                "pass the LPV grid's cell-centre inside mask",
            )
        zb_cells = offsets = None
        if outside == "extrapolated":                # Eq. (B3) of sslpv_gl.boundary, in cells
            zb_cells = boundary.extrapolation_distance(sigma_t, albedo, g_medium, eta) / dx
            if mapping == "diffusion":               # Eq. (B4): the diffusion lattice's zero, to a fraction of a cell
                from .bounded import partial_sink_offsets

                offsets = partial_sink_offsets()
        keep, emit = boundary.outside_masks(mask, outside, zb_cells, offsets)
        # where the medium is not kept, light travels in vacuum: no attenuation, no scattering
        sigma_lpv = np.where(keep > 0, sigma_lpv, 0.0)
        sigma_s_prime = np.where(keep > 0, sigma_s_prime, 0.0)
        emit = np.broadcast_to(emit, sigma_lpv.shape)
        empty = boundary.empty_mask(mask, outside)
        if mapping == "diffusion" and outside in ("absorb", "extrapolated", "interior"):
            # Eq. (21) turns the lattice's steady state U into fluence: it holds in medium cells
            # only. A sink (or an interior mode's empty cell) accumulates the flux that LEFT the
            # medium, which the paper's area-light estimate (Eq. 5-7, scale 1) already turns into
            # exitant radiance (exactly Phi / (pi A) for a clamped-cosine lobe). Scaling it by R
            # (~0.1 at sigma_t' dx ~ 0.5) was the main term of the back-lit deficit.
            radiance_scale = np.where(keep > 0, radiance_scale, 1.0)
            if exitance == "boundary":               # Eq. (D5): the medium's cells read as J / pi
                factor = boundary_exitance_factor(sigma_t, albedo, g_medium, zb_cells, dx)
                radiance_scale = np.where(keep > 0, radiance_scale * factor, radiance_scale)

    return {
        "sigma_lpv": sigma_lpv.astype(np.float32),
        "sigma_s_prime": sigma_s_prime.astype(np.float32),
        "g": g.astype(np.float32),
        # cells outside the mesh keep the scale of the medium there under vacuum and
        # material (a property of the material the light was mapped with); 1 in sinks
        # and empty cells (above)
        "radiance_scale": radiance_scale.astype(np.float32),
        "emit": emit.astype(np.float32),
    } | ({} if empty is None else {"empty": empty.astype(np.float32)}) | (
        {} if radiance_factor is None else {"radiance_factor": radiance_factor})
