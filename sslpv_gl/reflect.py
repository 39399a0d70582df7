"""``boundary_reflect``: the dielectric boundary's internal reflection in SSLPV's lattice.

Borlum et al. (HPG 2011) weight the light entering the object by the Fresnel transmittance
(Eq. 1) and the light leaving it by the transmittance towards the eye (Eq. 4), but every
bit of light that reaches the surface from inside leaves the medium: the lattice has no
internal reflection. Behind a smooth interface of relative index ``eta`` a diffuse flux
reaching the surface from inside is reflected back with the diffuse internal reflectance

    R_dr(eta) = 2 int_0^1 R(-mu; eta) mu dmu                                       (R1)

(:func:`sslpv_gl.boundary.diffuse_fresnel_reflectance`, Eq. (B1) there: 0.651 at
``eta = 1.6``). Diffusion theory turns (R1) into the extrapolated boundary condition
(``z_b = 2 A D``, ``A = (1 + R_dr) / (1 - R_dr)``; ``outside = extrapolated``); here it acts
on the lattice itself.

Options
-------
.. list-table::
   :header-rows: 1

   * - ``boundary_reflect``
     - meaning
   * - ``none`` (default, the paper)
     - all light that crosses from an inside cell into an outside cell leaves the medium
   * - ``rdr``
     - a fraction ``R_dr(eta)`` of it is reflected back into the inside cell (below)

The rule
--------
A *surface face* is the face between an inside cell ``s`` (cell centre inside the mesh) and
an outside cell ``n = s + o`` (``o`` one of the six axial offsets; a neighbour beyond the
grid counts as outside). In one step the paper's rule sends from ``s`` to ``n``
(``docs/conventions.md``)::

    T_{s->n} = h_s h_n M_{-o} S(s) c_s,      h = exp(-sigma_lpv dx / 2)          (R2)

(``M_{-o}``: the propagation matrix whose source lies at ``-o`` seen from the destination
``n``). With ``rdr`` that transfer is multiplied by ``1 - R_dr``, and ``s`` receives
in the same step the reflected part, as from its mirror image across the face::

    T_{s->n} <- (1 - R_dr) T_{s->n}
    c'_s     += R_dr h_s^2 M_{+o} F_o S(s) c_s                                     (R3)

``F_o = diag`` of ``+1`` except ``-1`` on the band-1 coefficient along the axis of ``o``
(coefficient order ``(c00, c1-1, c10, c11) ~ (1, y, z, x)``): the lobe mirrored about the
face, whose normal is that axis. (R3) is the method of images: a mirror image of ``s``
placed at ``n`` holding ``F_o c_s`` sends ``M_{+o} F_o S c_s`` to ``s``, and by the
lattice's mirror symmetry ``M_{+o} F_o = F_o M_{-o}``, so the reflected lobe is the
transmitted lobe of (R2) mirrored. The path is half a cell to the face and half back in
``s``: ``h_s^2 = exp(-sigma_lpv[s] dx)``. Band 0 is unchanged by ``F_o``, so the flux
(``sqrt(4 pi) c00``) that reached the face splits exactly into ``R_dr`` back into the
medium and ``1 - R_dr`` out of it (``tests/test_boundary_reflect.py``).

Why mirrored and not a cosine lobe: the mirror keeps the reflected light's direction
along the face (a flux grazing the surface keeps grazing it, as at a smooth interface), it
needs no renormalisation (``F_o`` preserves band 0 exactly, whereas a clamped-cosine lobe
in two SH bands has to be scaled to carry the same flux), and it is the lattice's own
operator, so the GL shader and the twin apply one 4x4 matrix per face. ``R_dr`` itself is
the angular average for a diffuse (Lambertian) flux, the assumption of the extrapolated
boundary condition; the angular dependence of ``R(mu)`` is not resolved by two SH bands.

Which steps: every step, the first too (the injected light in an inside cell that moves
outwards meets the surface from inside). The emit mask of the source (sink cells) applies
to the reflected part as to the transmitted one; inside cells always emit.

Limits
------
* Needs an inside/outside split at the surface: ``outside = material`` (the medium
  everywhere) has none, and ``outside = extrapolated`` already models the same
  reflection by diffusion theory's extrapolated layer (using both counts the boundary
  twice), so both are refused (:func:`check`). ``vacuum``, ``absorb`` and ``interior``
  are supported.
* ``eta`` must lie in :data:`ETA_RANGE`, where (R1) is checked against a second route
  (``tests/test_boundary.py``). ``eta = 1`` gives ``R_dr = 0``: exactly the paper.
* A rough interface (``roughness > 0``) is treated as smooth: its diffuse reflectance is
  close to, not equal to, (R1).
* Shading is unchanged (Eq. 4 with the transmittance towards the eye): a surface point
  whose cell lies outside the mesh reads the flux that has already crossed the face with
  ``1 - R_dr``, and Eq. 4's transmittance is applied to it again.
* The reflected part re-enters the same cell in the same step: ``P`` gains a block
  diagonal, so the red/black reduction of the steady solve keeps it
  (:class:`sslpv_gl.transfer._Split`).
"""

from __future__ import annotations

import numpy as np

from harness.errors import InputError

from .boundary import diffuse_fresnel_reflectance
from .sh import neighbour_slices

__all__ = ["BOUNDARY_REFLECTS", "SUPPORTED_OUTSIDE", "ETA_RANGE", "AXIS_COEFF", "reflectance", "check",
           "surface_faces", "mirror"]

#: ``boundary_reflect`` choices, the paper's first.
BOUNDARY_REFLECTS = ("none", "rdr")
#: ``outside`` modes the reflection supports (module docstring, Limits).
SUPPORTED_OUTSIDE = ("vacuum", "absorb", "interior")
#: ``eta`` for which ``rdr`` is defined here: index-matched up to the scene model's maximum.
ETA_RANGE = (1.0, 3.0)
#: the band-1 coefficient along each axis (x, y, z): order (c00, c1-1, c10, c11) ~ (1, y, z, x)
AXIS_COEFF = (3, 1, 2)


def check(boundary_reflect, outside, eta=None):
    """One-line :class:`~harness.errors.InputError` for an unsupported combination; None when it is fine."""
    if boundary_reflect == "none":
        return
    if outside not in SUPPORTED_OUTSIDE:
        why = ("the medium fills the grid, so there is no surface to reflect at" if outside == "material" else
               "the extrapolated layer already models this reflection (it would count twice)")
        raise InputError("--boundary-reflect", "boundary_reflect",
                         f"boundary_reflect={boundary_reflect} does not support outside={outside}: {why}",
                         "use --outside " + " | ".join(SUPPORTED_OUTSIDE) + ", or --boundary-reflect none")
    if eta is not None and not ETA_RANGE[0] <= float(eta) <= ETA_RANGE[1]:
        raise InputError("--boundary-reflect", "boundary_reflect",
                         f"the scene's eta = {float(eta):g} is outside the range [{ETA_RANGE[0]:g}, {ETA_RANGE[1]:g}] "
                         "where R_dr(eta) is defined here", "use --boundary-reflect none for this scene")


def reflectance(boundary_reflect, eta):
    """``R_dr(eta)`` (R1) for ``rdr``, 0.0 for ``none``; exactly 0.0 for ``eta == 1``."""
    if boundary_reflect not in BOUNDARY_REFLECTS:
        raise ValueError(f"unknown boundary_reflect {boundary_reflect!r}; use one of {', '.join(BOUNDARY_REFLECTS)}")
    if boundary_reflect == "none" or float(eta) == 1.0:
        return 0.0
    return float(diffuse_fresnel_reflectance(float(eta)))


def surface_faces(inside, offset):
    """``(N, N, N)`` bool: cells ``s`` inside whose neighbour ``s + offset`` is outside (or beyond the grid).

    ``inside`` is ``[z, y, x]``; ``offset`` is ``(ox, oy, oz)``.
    """
    ins = np.asarray(inside, dtype=bool)
    nb = np.zeros_like(ins)
    dst, src = neighbour_slices(offset)
    nb[dst] = ins[src]                               # nb[s] = inside[s + offset]; False beyond the grid
    return ins & ~nb


def mirror(c, axis):
    """``F c``: ``c`` (``(..., 4)``) with the band-1 coefficient along ``axis`` (0 x, 1 y, 2 z) negated."""
    out = np.array(c, dtype=np.float64, copy=True)
    out[..., AXIS_COEFF[axis]] *= -1.0
    return out

