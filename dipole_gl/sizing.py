"""The per-scene sizing rule of the rivals' gathers (``fit = coarsen``): the finest setting that fits the budget.

Each gather has a budget that bounds its cost, and a setting over it is refused with one line
(``fit = refuse``, the default). With ``fit = coarsen`` the renderer instead takes the given
setting as the finest wanted and coarsens it just enough to fit; the value used is recorded in
the result (``info["spacing_used"]``, ``info["density_used"]``), so the store and the report
show it. On a scene where the setting fits, the rule returns it unchanged.

Dense gather (``spacing``, in reduced mean free paths ``l'``): the samples ``S(h)`` of
:func:`dipole_gl.sampling.sample_count` must satisfy ``S <= MAX_SAMPLES`` and
``pixels x S <= MAX_FRAME_PAIRS``. ``S(h)`` is a non-increasing step function of ``h``
(``m = ceil(e/h)`` per triangle), so :func:`dense_spacing` finds the smallest spacing that
fits by bisection and rounds it *up* to three significant digits (the count is exact, the
rounding keeps it fitting).

Vertex gather (``density``, vertices per ``l'^2``; the range is kept): the neighbourhood table
must hold at most ``MAX_PAIRS`` pairs. Before remeshing, the table is estimated from the
mesh's area ``A``: ``V = A density / l'^2`` vertices (a uniform triangulation gives each vertex
``l'^2 / density`` of area, :func:`dipole_gl.vertex.edge_length`), each with
``min(V, pi R^2 density / l'^2)`` neighbours (``R = range / sigma_tr``; on a sphere the cap
within a chord ``R`` has area exactly ``pi R^2``). Both factors grow as ``density``, so the
estimate grows as ``density^2`` and :func:`vertex_density` scales the density by
``sqrt(FIT_SHARE MAX_PAIRS / estimate)`` (``FIT_SHARE`` = 0.5), rounded *down* to three significant digits.
When the remeshed table still exceeds ``MAX_PAIRS`` (a surface far from flat within ``R``),
the renderer lowers the density by :data:`RETRY_FACTOR` and remeshes, at most
:data:`RETRIES` times.

Limits: the rule never goes beyond the parameters' own ranges (spacing at most 10 ``l'``,
density at least 0.01); a scene that needs more is refused with the one-line error. A
coarser setting is a less accurate gather (the near-field radius ``3 h`` grows with the
spacing, ``docs/dipole_rivals.md`` Sec. 3): the recorded value says by how much.
"""

from __future__ import annotations

import math

import numpy as np

from harness.errors import InputError

from .sampling import MAX_FRAME_PAIRS, MAX_SAMPLES, sample_count
from .vertex import MAX_PAIRS

__all__ = ["dense_spacing", "vertex_density", "estimated_pairs", "mesh_area", "check_density", "FIT_SHARE", "RETRY_FACTOR", "RETRIES",
           "MAX_SPACING", "MIN_DENSITY"]

#: The share of ``MAX_PAIRS`` that the estimated neighbourhood table is sized to. The remeshed table came out
#: 1.06x the estimate on marble_sphere at density 0.0675 and over 1.25x at 0.0844 (refused at a share of 0.8,
#: a retry that cost a second remeshing): half leaves room for that.
FIT_SHARE = 0.5
#: The density factor of each retry when the remeshed table still exceeds ``MAX_PAIRS``.
RETRY_FACTOR = 0.8
#: Retries after the estimate.
RETRIES = 4
#: The parameters' own bounds (:class:`dipole_gl.params.DipoleParams`).
MAX_SPACING = 10.0
MIN_DENSITY = 0.01


def _round(x, up):
    """``x`` to three significant digits, rounded up or down."""
    step = 10.0 ** (math.floor(math.log10(x)) - 2)
    return round((math.ceil(x / step - 1e-9) if up else math.floor(x / step + 1e-9)) * step, 12)


def dense_spacing(mesh, mfp, spacing, pixels=None):
    """The smallest spacing ``>= spacing`` (in ``l' = mfp``) whose samples fit the gather's budgets: the dense
    gather's (``pixels`` given: samples and pixel-sample pairs per frame) or the hierarchical gather's (``pixels``
    None: the samples alone)."""
    limit = MAX_SAMPLES if pixels is None else min(MAX_SAMPLES, MAX_FRAME_PAIRS // max(int(pixels), 1))

    def fits(s):
        return sample_count(mesh, s * mfp) <= limit

    if fits(spacing):
        return float(spacing)
    if not fits(MAX_SPACING):
        over = (f"over the {limit:,} samples the octree takes" if pixels is None
                else f"over {limit:,} for {int(pixels):,} pixels")
        fix = "use --gather vertex or atlas" if pixels is None else "render a smaller image or use --gather hierarchical"
        raise InputError("--fit", "fit", f"even a spacing of {MAX_SPACING:g} l' gives "
                         f"{sample_count(mesh, MAX_SPACING * mfp):,} surface samples ({over})", fix)
    lo, hi = float(spacing), MAX_SPACING
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if fits(mid) else (mid, hi)
    out = min(_round(hi, up=True), MAX_SPACING)
    while not fits(out):                                  # rounding cannot cross a step downwards, but be exact
        out = min(out + 10.0 ** (math.floor(math.log10(out)) - 2), MAX_SPACING)
    return float(out)


def mesh_area(mesh):
    v = np.asarray(mesh.vertices, dtype=np.float64)
    tri = v[np.asarray(mesh.faces, dtype=np.int64)]
    return float(0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum())


def estimated_pairs(area, mfp, diffusion_length, density, range_):
    """The neighbourhood table's estimated size (pairs) at ``density`` and ``range_`` (module docstring)."""
    v = area * density / mfp ** 2
    radius = range_ * diffusion_length
    per_vertex = v if not math.isfinite(radius) else min(v, math.pi * radius ** 2 * density / mfp ** 2)
    return v * per_vertex


def vertex_density(mesh, mfp, diffusion_length, density, range_):
    """The largest density ``<= density`` whose estimated neighbourhood table fits ``FIT_SHARE MAX_PAIRS``."""
    est = estimated_pairs(mesh_area(mesh), mfp, diffusion_length, density, range_)
    target = FIT_SHARE * MAX_PAIRS
    if est <= target:
        return float(density)
    return check_density(_round(density * math.sqrt(target / est), up=False))


def check_density(density):
    """``density`` if the parameters allow it, else the one-line refusal."""
    if density < MIN_DENSITY:
        raise InputError("--fit", "fit", f"the neighbourhood table fits only below {MIN_DENSITY:g} vertices per "
                         f"l'^2 (density {density:.3g})", "lower --range or use --gather dense")
    return float(density)
