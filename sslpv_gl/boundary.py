"""What SSLPV does with light that crosses the object's surface outwards.

The paper propagates light through every cell of the grid, inside the mesh or
not, and names removing the light that leaves the object as future work (Fig. 8
caption: "our model does not currently remove light which is leaving the object
from the propagation grid"). This module makes that choice explicit. Each mode
gives, per cell and colour, two masks used by the propagation's transfer rule
(``docs/conventions.md``; ``docs/diffusion_mapping.md`` for the boundary)::

    c_d += M_s @ (emit[s] * exp(-0.5 (sigma[s] + sigma[d]) dx) * S(s) c_s)

* ``material``: where the cell carries the medium's ``sigma_lpv``, ``sigma_s'``
  (elsewhere both are 0: vacuum);
* ``emit``: 1 where a cell passes on what it received, 0 where it is a *sink*
  that records what entered it (the accumulation grid still sums it, so shading
  can read the escaped flux) but sends nothing on. Sinks act from the second
  step on: the first step carries the injected light, which has crossed the
  surface inwards even where the cell holding the surface point has its centre
  outside the mesh (otherwise a thin object, whose lit cells are all
  outside-centred, would lose all its light).

Modes
-----

.. list-table::
   :header-rows: 1

   * - ``outside``
     - material
     - emit
     - meaning
   * - ``vacuum`` (default, the paper)
     - inside cells
     - every cell
     - light leaves the object and keeps propagating through empty cells,
       possibly re-entering it elsewhere
   * - ``material``
     - every cell
     - every cell
     - the medium fills the whole grid box
   * - ``absorb``
     - inside cells
     - inside cells
     - outside cells remove what enters them (the paper's Fig. 8 future work)
   * - ``extrapolated``
     - inside cells, the layer of outside cells within ``z_b`` of the surface,
       and one partial sink beyond it
     - 1 in the same cells but the partial sink's ``f`` (Eq. (B4))
     - diffusion theory's extrapolated boundary: the fluence vanishes at
       ``z_b = 2 A(eta) D`` beyond the surface (Eq. (B3) below), with the
       Fresnel-dependent ``A(eta)`` the dipole uses
   * - ``interior``
     - inside cells
     - every cell
     - light never moves between two empty cells: an outside cell exchanges light
       with its inside neighbours only (``empty`` mask, below), so light that leaves
       the medium is removed unless it steps straight back into it, and cannot go
       round the object through the empty cells

The ``interior`` mode needs a third mask, ``empty`` (1 in outside cells), applied
to each PAIR: the transfer from ``s`` to ``d`` is multiplied by
``1 - empty[s] empty[d]``. Unlike ``absorb``, the surface cells (outside-centred
cells that hold the surface points the shading reads) keep sending light back into
the medium, so a front-lit object keeps its light; unlike ``vacuum``, the empty
cells carry nothing round the object. The rule acts at every step, the first too.

Equations (cited as "Eq. (Bn)")
-------------------------------
(B1) ``F_dr(eta) = 2 int_0^1 R(-mu; eta) mu dmu``: the diffuse Fresnel
     reflectance of the boundary for light arriving from INSIDE a medium of
     relative index ``eta`` (Lambertian angular distribution), computed here by
     Gauss-Legendre quadrature of :func:`sslpv_gl.optics.fresnel_reflectance`.
     Jensen et al. 2001 use Egan and Hilgeman's fit
     ``-1.440/eta^2 + 0.710/eta + 0.668 + 0.0636 eta``; the test checks the two.
(B2) ``A(eta) = (1 + F_dr) / (1 - F_dr)`` (Jensen et al. 2001, Sec. 2.4;
     Hao & Varshney 2004, Sec. 2).
(B3) ``z_b = 2 A D`` with ``D = 1 / (3 sigma_t')``, ``sigma_t' = sigma_a + sigma_s (1 - g)``.
(B4) The lattice's own zero. A plain sink cell puts the zero of the lattice's
     fluence not at its face but about at its centre, and whole cells would place
     it only to half a cell. An outside cell whose centre lies ``t = 1/2 + z_b/dx
     - d`` cells short of the zero (``d`` its distance to the nearest inside centre,
     the surface lying half a cell past that centre) is a full layer cell where
     ``t >= o(1)``, a sink where ``t < o(0)``, and between them a *partial sink*
     that keeps the medium and passes on ``f = o^-1(t)`` of what it receives, with
     ``o(f)`` the zero's distance beyond such a cell measured on the lattice itself
     (:func:`sslpv_gl.bounded.partial_sink_offsets`, Eq. (D4); ``o`` runs from about
     -0.07 to 0.93 cells). ``o`` is the ``diffusion`` lattice's, the one lattice matched
     to diffusion theory, so only the ``diffusion`` mapping gets partial sinks
     (:func:`sslpv_gl.material.lpv_material`). The other mappings keep the layer by
     whole cells, every outside cell whose centre lies within ``z_b`` of the surface:
     their lattices' zero is not measured, and the collision family calibrated with
     partial sinks was measured worse against the truth (``docs/diffusion_mapping.md``
     Sec. 7).

Limits
------
* Distances to the surface are measured between cell centres on the grid
  (Euclidean distance transform of the inside mask): exact for a face normal to a
  grid axis, approximate where the surface is oblique to the grid. Below ``z_b`` of
  about 0.43 cells (``-o(0) + 1/2``; half a cell by whole cells) the layer is empty
  and the mode equals ``absorb``.
* ``z_b`` varies with colour (``D`` does); the masks are per colour.
"""

from __future__ import annotations

import numpy as np

from .optics import fresnel_reflectance

__all__ = ["OUTSIDE_MODES", "empty_mask", "diffuse_fresnel_reflectance", "fresnel_moment", "egan_hilgeman_fdr", "a_of_eta",
           "extrapolation_distance", "outside_masks"]

#: ``outside`` choices, in the order of the table above.
OUTSIDE_MODES = ("vacuum", "material", "absorb", "extrapolated", "interior")


def _moment_nodes(eta, order):
    """Gauss-Legendre nodes on ``[mu_c, 1]`` for the Fresnel moments of light arriving from inside.

    Returns ``(mu_c, mu, r, wts)``: the critical cosine ``sqrt(1 - 1/eta^2)`` (0 for
    ``eta <= 1``), the nodes, ``R(-mu; eta)`` there and the weights, each with a
    leading node axis and then ``eta``'s shape.
    """
    x, w = np.polynomial.legendre.leggauss(int(order))
    eta = np.asarray(eta, dtype=np.float64)
    mu_c = np.sqrt(np.clip(1.0 - 1.0 / eta**2, 0.0, 1.0))
    half = 0.5 * (1.0 - mu_c)
    mu = mu_c[None] + half[None] * (x.reshape((-1,) + (1,) * eta.ndim) + 1.0)   # nodes on [mu_c, 1]
    r = fresnel_reflectance(-mu, eta[None])          # negative cos: light from inside
    wts = w.reshape((-1,) + (1,) * eta.ndim) * half[None]
    return mu_c, mu, r, wts


def diffuse_fresnel_reflectance(eta, order=64):
    """Eq. (B1): ``F_dr`` for light arriving from inside a medium of relative index ``eta``.

    ``F_dr = 2 int_0^1 R(-mu) mu dmu``. Below the critical cosine
    ``mu_c = sqrt(1 - 1/eta^2)`` the light is totally reflected (``R = 1``), which
    contributes ``mu_c^2`` exactly; the smooth rest, on ``[mu_c, 1]``, is
    integrated by Gauss-Legendre quadrature with ``order`` nodes (splitting at the
    kink makes it accurate to ~1e-12). 0 for ``eta == 1``.
    """
    mu_c, mu, r, wts = _moment_nodes(eta, order)
    return mu_c**2 + np.sum(wts * 2.0 * mu * r, axis=0)


def fresnel_moment(eta, n, order=64):
    """``C_n(eta) = int_0^1 R(-mu; eta) mu^n dmu``, the n-th Fresnel moment for light from inside.

    The same split quadrature as :func:`diffuse_fresnel_reflectance` (``F_dr = 2 C_1``);
    the totally reflected part ``[0, mu_c]`` contributes ``mu_c^(n+1) / (n+1)``.
    The directional dipole (Frisvad et al. 2014) uses ``C_1`` and ``C_2``
    (``dipole_gl.kernels``).
    """
    mu_c, mu, r, wts = _moment_nodes(eta, order)
    return mu_c ** (n + 1) / (n + 1) + np.sum(wts * mu**n * r, axis=0)


def egan_hilgeman_fdr(eta):
    """The polynomial fit of ``F_dr`` that Jensen et al. 2001 quote (for comparison only)."""
    eta = np.asarray(eta, dtype=np.float64)
    return -1.440 / eta**2 + 0.710 / eta + 0.668 + 0.0636 * eta


def a_of_eta(eta):
    """Eq. (B2): the boundary mismatch factor ``A = (1 + F_dr) / (1 - F_dr)``; 1 for ``eta == 1``."""
    f = diffuse_fresnel_reflectance(eta)
    return (1.0 + f) / (1.0 - f)


def extrapolation_distance(sigma_t, albedo, g, eta):
    """Eq. (B3): ``z_b = 2 A(eta) D`` in scene units, elementwise (inf where ``sigma_t' = 0``)."""
    st = np.asarray(sigma_t, dtype=np.float64)
    a = np.asarray(albedo, dtype=np.float64)
    gg = np.asarray(g, dtype=np.float64)
    st_prime = st * (1.0 - a) + st * a * (1.0 - gg)  # sigma_a + sigma_s (1 - g)
    with np.errstate(divide="ignore"):
        D = 1.0 / (3.0 * st_prime)
    return 2.0 * a_of_eta(eta) * D


def outside_masks(inside_mask, mode, zb_cells=None, offsets=None):
    """``(material, emit)`` masks of one outside mode -> two float64 ``(N, N, N, C)`` arrays.

    ``inside_mask`` is ``(N, N, N)`` bool ``[z, y, x]`` (cell centre inside the
    mesh) or None (every cell inside). ``zb_cells`` is ``z_b / dx``, shape
    ``(C,)`` or ``(N, N, N, C)`` (needed for ``extrapolated`` only; its value in
    the nearest inside cell is used). ``C`` is 3 (colours). ``offsets``: the lattice's
    ``(emit, o(emit))`` table of Eq. (B4), :func:`sslpv_gl.bounded.partial_sink_offsets`
    (``extrapolated`` only; passed in so that this module needs no lattice); None gives the
    layer by whole cells, every outside cell whose centre lies within ``z_b`` of the surface.
    """
    if mode not in OUTSIDE_MODES:
        raise ValueError(f"unknown outside mode {mode!r}; use one of {', '.join(OUTSIDE_MODES)}")
    if inside_mask is None:
        return np.ones((1, 1, 1, 3)), np.ones((1, 1, 1, 3))
    inside = np.asarray(inside_mask, dtype=bool)
    ins = np.repeat(inside[..., None], 3, axis=-1).astype(np.float64)
    ones = np.ones_like(ins)
    if mode == "vacuum":
        return ins, ones
    if mode == "material":
        return ones, ones
    if mode == "absorb":
        return ins, ins
    if mode == "interior":                           # the pair rule is empty_mask's
        return ins, ones
    # extrapolated: the medium continues past the surface; with the lattice's offsets its zero of the
    # fluence is put at z_b beyond it (Eq. (B4)): full layer cells, one partial sink, then sinks.
    from scipy.ndimage import distance_transform_edt

    if zb_cells is None:
        raise ValueError("outside mode 'extrapolated' needs zb_cells")
    if not inside.any():
        return ins, ins
    # distance (cells) from each outside centre to the nearest inside centre, and that centre's index
    dist, idx = distance_transform_edt(~inside, return_indices=True)
    zb = np.asarray(zb_cells, dtype=np.float64)
    if zb.ndim == 4:
        zb = zb[idx[0], idx[1], idx[2]]              # the nearest inside cell's z_b
    # the surface lies about half way between an inside and an outside centre; t: how far the
    # zero should lie beyond this cell's centre
    t = 0.5 + zb - dist[..., None]
    if offsets is None:                              # whole cells: the centre within z_b of the surface
        keep = (inside[..., None] | (t >= 0.0)).astype(np.float64)
        return keep, keep
    f_tab, o_tab = (np.asarray(v, dtype=np.float64) for v in offsets)
    full = inside[..., None] | (t >= o_tab[-1])
    part = ~full & (t >= o_tab[0])
    keep = (full | part).astype(np.float64)
    emit = np.where(full, 1.0, np.where(part, np.interp(t, o_tab, f_tab), 0.0))
    return keep, emit


def empty_mask(inside_mask, mode):
    """The ``empty`` mask of ``outside = interior`` -> float64 ``(N, N, N, 3)``, or None for the other modes.

    1 in the cells whose centre lies outside the mesh; the transfer between two such
    cells is cut (module docstring). None (no pair rule) for every other mode, and
    when there is no mask.
    """
    if mode != "interior" or inside_mask is None:
        return None
    out = ~np.asarray(inside_mask, dtype=bool)
    return np.repeat(out[..., None], 3, axis=-1).astype(np.float64)
