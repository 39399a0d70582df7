"""A calibration that depends on the material: ``sigma_scale`` and ``radiance_scale`` per cell.

A calibrated mapping (:mod:`sslpv_gl.calibrated`) of version 2 holds one ``sigma_scale`` ``s``
and one ``radiance_scale`` ``r`` per budget ``(N, steps)``. A *form* (version 3) makes both
smooth functions of each LPV cell's dimensionless numbers, one coefficient vector per budget::

    ln s = a0 + sum_k a_k x_k,     ln r = b0 + sum_k b_k x_k                            (F1)

with the terms ``x_k`` of :data:`TERMS`, evaluated per cell and colour channel (each channel
is its own transport problem in SSLPV: ``sigma_lpv`` is per colour) from the medium as the
mapping sees it (resampled onto the LPV grid, after any ``phase_scaling``):

======================  ==========================================================================
term                    ``x``
======================  ==========================================================================
``ln_sigma_tr_dx``      ``ln(sigma_tr dx)``, ``sigma_tr = sqrt(3 sigma_a sigma_t')``,
                        ``sigma_t' = sigma_a + sigma_s (1 - g)`` (the diffusion length in cells)  (F2)
``ln_absorption``       ``ln(1 - alpha')``, the reduced albedo ``alpha' = sigma_s (1 - g) / sigma_t'`` (F3)
``g``                   the cell's HG asymmetry
``ln_eta``              ``ln eta``, the boundary's relative index (0 when index-matched)
``ln_extent_per_step``  ``ln(E / K)``: ``E`` the object's extent in cells (the largest side of the
                        bounding box of the cells inside the mesh), ``K`` the budget's step count;
                        not defined for ``steps = steady`` (a form there must not use it)       (F4)
======================  ==========================================================================

``a0`` and ``b0`` (the term ``const``) are applied exactly as the scalar ``sigma_scale =
exp(a0)`` and ``radiance_scale = exp(b0)`` of a version 2 budget, and the rest as a per-cell
factor ``exp(sum_k a_k x_k)`` on ``sigma_lpv`` (and on the cell's radiance scale). A form
whose non-constant coefficients are all 0 is therefore the scalar budget itself, bit for bit.
Because (F1) is linear in the ``x_k``, the mean of ``ln s`` over a scene's cells and channels
is (F1) at the mean of the ``x_k`` (:func:`mean_numbers`): the scene-level value a fit regresses.

Limits
------
* ``sigma_tr dx`` and ``1 - alpha'`` are floored at :data:`FLOOR` before the log: a cell without
  absorption (or without medium) has ``ln(sigma_tr dx) = -inf``. Such a cell's ``sigma_lpv``
  is 0 or carries no absorption; its scale is finite but set by the floor.
* The form is fitted on the suite's scenes; outside their range of ``x_k`` it extrapolates.
* The CPU twin (:mod:`sslpv_gl.twin`) and the bounded lattice (:mod:`sslpv_gl.bounded`) take
  scalar scales only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["TERMS", "CONST", "FLOOR", "Form", "cell_numbers", "extent_cells", "mean_numbers", "log_scale"]

CONST = "const"
#: The non-constant terms of (F1), in the order a file lists them.
TERMS = ("ln_sigma_tr_dx", "ln_absorption", "g", "ln_eta", "ln_extent_per_step")
#: Floor of ``sigma_tr dx`` and ``1 - alpha'`` before their logs.
FLOOR = 1e-6


@dataclass(frozen=True)
class Form:
    """The per-cell part of (F1) for one budget: ``terms`` with their ``sigma`` and ``radiance``
    coefficients (the constants live in the budget's scalar scales), and the budget's step count."""

    terms: tuple                     # names of TERMS
    sigma: tuple                     # a_k, one per term
    radiance: tuple                  # b_k, one per term
    steps: int | str                 # K of (F4), or "steady"

    def factors(self, numbers):
        """``(exp(sum a_k x_k), exp(sum b_k x_k))`` per cell and colour, float64."""
        return (np.exp(log_scale(dict(zip(self.terms, self.sigma)), numbers)),
                np.exp(log_scale(dict(zip(self.terms, self.radiance)), numbers)))


def extent_cells(inside_mask, N):
    """``E`` of (F4): the largest side, in cells, of the bounding box of the inside cells (``N`` when
    ``inside_mask`` is None or empty)."""
    if inside_mask is None:
        return float(N)
    m = np.asarray(inside_mask, dtype=bool)
    if not m.any():
        return float(N)
    sides = []
    for axis in range(3):
        idx = np.flatnonzero(m.any(axis=tuple(a for a in range(3) if a != axis)))
        sides.append(int(idx[-1] - idx[0] + 1))
    return float(max(sides))


def cell_numbers(sigma_t, albedo, g, dx, eta=1.0, extent=None, steps=None):
    """The terms of (F1) per cell and colour -> dict term -> float64 array (broadcast shape).

    ``sigma_t``, ``albedo``, ``g``: the medium on the LPV grid; ``dx``: the cell width; ``eta``:
    the boundary's relative index; ``extent``: ``E`` of (F4) in cells; ``steps``: ``K``.
    ``ln_extent_per_step`` is NaN where it is not defined (``steps`` not a positive count, or no
    ``extent``): a form that uses it there fails loudly instead of silently.
    """
    st, a, gg = (np.asarray(v, dtype=np.float64) for v in (sigma_t, albedo, g))
    st, a, gg = np.broadcast_arrays(st, a, gg)
    sigma_a = st * (1.0 - a)
    sigma_sr = st * a * (1.0 - gg)                   # reduced scattering sigma_s (1 - g)
    st_r = sigma_a + sigma_sr                        # sigma_t'
    sigma_tr = np.sqrt(np.maximum(3.0 * sigma_a * st_r, 0.0))                          # (F2)
    with np.errstate(invalid="ignore", divide="ignore"):
        absorption = np.where(st_r > 0.0, sigma_a / st_r, 1.0)                        # 1 - alpha', (F3)
    if isinstance(steps, int) and not isinstance(steps, bool) and steps > 0 and extent is not None:
        per_step = math.log(float(extent) / steps)                                     # (F4)
    else:
        per_step = math.nan
    return {
        "ln_sigma_tr_dx": np.log(np.maximum(sigma_tr * float(dx), FLOOR)),
        "ln_absorption": np.log(np.maximum(absorption, FLOOR)),
        "g": gg.copy(),
        "ln_eta": np.full(st.shape, math.log(float(eta))),
        "ln_extent_per_step": np.full(st.shape, per_step),
    }


def log_scale(coeffs, numbers):
    """``sum_k c_k x_k`` over the non-constant terms of ``coeffs`` (term -> coefficient); a zero
    coefficient contributes nothing (not even a NaN term's)."""
    shape = next(iter(numbers.values())).shape
    out = np.zeros(shape)
    for term, c in coeffs.items():
        if term == CONST or c == 0.0:
            continue
        out = out + float(c) * numbers[term]
    return out


def mean_numbers(numbers, inside=None):
    """Each term's mean over the inside cells (all cells when ``inside`` is None) and colours: the
    scene-level ``x_k`` whose (F1) is the mean ``ln s`` of the scene's cells (module docstring)."""
    out = {}
    for term, x in numbers.items():
        x = np.asarray(x, dtype=np.float64)
        if inside is not None and np.asarray(inside, dtype=bool).any():
            x = x[np.asarray(inside, dtype=bool)]
        out[term] = float(np.mean(x))
    return out
