"""The calibration's loss and its minimisation: pure functions on rendered images, no renderer.

A mapping family has two free parameters per budget ``(N, steps)``: ``s``, a factor on
``sigma_lpv``, and ``r``, a global factor on the subsurface radiance. For scene ``i``
rendered at ``s`` the subsurface image is ``r I_i(s)`` (shading is linear in the
accumulated grid, so ``r`` needs no render), and its relMSE against the reference ``R_i``
(:func:`harness.metrics.relmse`, over the reference's mask and the three channels) is
a quadratic in ``r``::

    relMSE_i(s, r) = A_i(s) r^2 - 2 B_i(s) r + C_i                                   (C1)
    A_i = <I^2 w>,  B_i = <I R w>,  C_i = <R^2 w>,  w = 1 / (R^2 + eps)

with ``<.>`` the mean over masked pixels and channels. The loss of a set of scenes is the
mean of the log relMSE (every scene counts by its relative error, whatever its own level)::

    L(s, r) = (1 / n) sum_i ln relMSE_i(s, r)                                          (C2)

It is minimised over ``u = ln s`` and ``v = ln r``. ``I_i(s)`` is known at the sampled
``s`` of a scan (GL renders); between samples each pixel is interpolated by a cubic
spline in ``u`` (:class:`SceneSamples`), which keeps ``A C >= B^2`` (so relMSE >= 0)
because the loss is evaluated on an interpolated *image*, not on interpolated
coefficients. For a given ``u`` the best ``v`` is a one-dimensional problem
(:func:`best_scale`); the outer problem is bounded Brent (``scipy.optimize.minimize_scalar``)
in the bracket of the best sample (:func:`fit`). The caller renders the optimum
again to check the interpolation (:mod:`harness.calibration.run`).

Uncertainty (C3): refitting against each of the reference's two independent halves
gives ``theta_a`` and ``theta_b``; the full reference is their mean, so with the fit
locally linear in the reference noise, ``SE(theta) = |theta_a - theta_b| / 2`` (a
one-degree-of-freedom estimate: ``var(theta_a - theta_b) = 2 var_half`` and
``var(theta) = var_half / 2``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.optimize import minimize_scalar

from harness.metrics.pixel import RELMSE_EPS

__all__ = ["SceneSamples", "Fit", "relmse_coefficients", "best_scale", "fit", "fit_refined", "halves_se",
           "V_BOUNDS"]

#: Bounds of ``v = ln r``: the file format's scale range (sslpv_gl.calibrated.SCALE_RANGE).
V_BOUNDS = (math.log(1e-4), math.log(1e4))
REFS = ("full", "half_a", "half_b")


def relmse_coefficients(image, ref, eps=RELMSE_EPS):
    """``(A, B, C)`` of Eq. (C1) for flattened masked pixel-channels ``image`` and ``ref``."""
    image = np.asarray(image, dtype=np.float64)
    ref = np.asarray(ref, dtype=np.float64)
    w = 1.0 / (ref * ref + eps)
    return float(np.mean(image * image * w)), float(np.mean(image * ref * w)), float(np.mean(ref * ref * w))


@dataclass
class SceneSamples:
    """One scene at one budget: the subsurface image (masked, flattened) at each sampled ``s``.

    ``refs`` holds the reference's flattened masked pixels for ``full``, ``half_a`` and
    ``half_b``. Samples may be added in any order (:meth:`add`); the spline is rebuilt
    lazily.
    """

    scene: str
    refs: dict
    u: list = field(default_factory=list)          # ln s of each sample
    images: list = field(default_factory=list)     # (P,) float64 each
    _spline: object = field(default=None, repr=False)

    def add(self, s, image):
        u = math.log(float(s))
        if any(abs(u - x) < 1e-12 for x in self.u):
            return
        self.u.append(u)
        self.images.append(np.asarray(image, dtype=np.float64).ravel())
        self._spline = None

    @property
    def u_range(self):
        return min(self.u), max(self.u)

    def image_at(self, u):
        """The subsurface image at ``u = ln s``: a sample exactly, else the cubic spline."""
        for x, img in zip(self.u, self.images):
            if abs(u - x) < 1e-12:
                return img
        if self._spline is None:
            order = np.argsort(self.u)
            self._spline = CubicSpline(np.asarray(self.u)[order], np.stack(self.images)[order], axis=0,
                                       bc_type="natural")
        return self._spline(u)

    def coefficients(self, u, ref="full"):
        return relmse_coefficients(self.image_at(u), self.refs[ref])

    def energy(self, u, ref="full"):
        """``sum I / sum R`` at unit radiance scale (the energy ratio is ``r`` times this)."""
        return float(np.sum(self.image_at(u)) / np.sum(self.refs[ref]))


def _log_relmse(coeffs, v):
    r = math.exp(v)
    out = []
    for A, B, C in coeffs:
        q = A * r * r - 2.0 * B * r + C
        out.append(math.log(max(q, 1e-300)))
    return out


def best_scale(coeffs, bounds=V_BOUNDS):
    """``(v, L)``: the ``v = ln r`` minimising Eq. (C2) for fixed images, and the loss there.

    Each term is the log of a quadratic in ``r`` with its minimum at ``r_i = B_i / A_i``; the
    mean's minimum lies between the smallest and the largest ``r_i``, where Brent's bounded
    method searches it.
    """
    rs = [B / A for A, B, _ in coeffs if A > 0 and B > 0]
    if not rs:
        v = 0.0
        return v, float(np.mean(_log_relmse(coeffs, v)))
    lo = max(bounds[0], math.log(min(rs)) - 1e-9)
    hi = min(bounds[1], math.log(max(rs)) + 1e-9)
    if hi - lo < 1e-9:
        v = min(max(math.log(rs[0]), bounds[0]), bounds[1])
        return v, float(np.mean(_log_relmse(coeffs, v)))
    res = minimize_scalar(lambda v: float(np.mean(_log_relmse(coeffs, v))), bounds=(lo, hi), method="bounded",
                          options={"xatol": 1e-7})
    return float(res.x), float(res.fun)


@dataclass
class Fit:
    """A fitted ``(s, r)`` for a set of scenes, with the loss (C2) and the per-scene figures."""

    scenes: tuple
    ref: str
    s: float
    r: float
    loss: float
    at_bound: bool                   # s at the edge of the sampled range: the optimum may lie beyond
    relmse: dict                     # scene -> relMSE at (s, r), from the samples
    energy: dict                     # scene -> energy ratio at (s, r), from the samples

    def as_dict(self):
        return {"scenes": list(self.scenes), "ref": self.ref, "s": self.s, "r": self.r, "loss": self.loss,
                "at_bound": self.at_bound, "relmse": self.relmse, "energy_ratio": self.energy}


def _loss_at(samples, u, ref):
    coeffs = [smp.coefficients(u, ref) for smp in samples]
    v, L = best_scale(coeffs)
    return v, L


def fit(samples, ref="full"):
    """Minimise Eq. (C2) over ``(u, v)`` for the scenes of ``samples`` -> :class:`Fit`.

    The ``u`` sampled for every scene are searched first; then Brent's bounded method
    refines ``u`` between the neighbours of the best sample, with the best ``v``
    (:func:`best_scale`) for each ``u``. Between samples the images, so also ``r`` and the
    loss, are interpolated: :func:`fit_refined` renders the fitted ``s`` and refits.
    """
    samples = list(samples)
    if not samples:
        raise ValueError("fit: no scenes")
    grid = sorted(set.intersection(*(set(round(u, 12) for u in smp.u) for smp in samples)))
    if len(grid) < 3:
        raise ValueError("fit: fewer than 3 sampled sigma scales shared by every scene")
    values = [_loss_at(samples, u, ref)[1] for u in grid]
    k = int(np.argmin(values))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    res = minimize_scalar(lambda u: _loss_at(samples, u, ref)[1], bounds=(lo, hi), method="bounded",
                          options={"xatol": 1e-5})
    u, L = (float(res.x), float(res.fun)) if res.fun <= values[k] else (grid[k], values[k])
    v, L = _loss_at(samples, u, ref)
    r = math.exp(v)
    # Brent ends within xatol of a bound when the optimum lies beyond it
    at_bound = (k == 0 and u - grid[0] < 1e-3) or (k == len(grid) - 1 and grid[-1] - u < 1e-3)
    rel, en = {}, {}
    for smp in samples:
        A, B, C = smp.coefficients(u, ref)
        rel[smp.scene] = float(A * r * r - 2 * B * r + C)
        en[smp.scene] = r * smp.energy(u, ref)
    return Fit(tuple(s.scene for s in samples), ref, math.exp(u), r, float(L), bool(at_bound), rel, en)


def fit_refined(samples, render, ref="full", rounds=4, u_tol=0.01):
    """:func:`fit`, then ``render(s)`` at the optimum and refit, until ``ln s`` moves by less than ``u_tol``.

    ``render(s)`` must add the exact image at ``s`` to every scene of ``samples``
    (:meth:`SceneSamples.add`). At the end the optimum is rendered once more and ``r``, the
    loss and the per-scene figures are those of the exact images there (no interpolation).
    Returns ``(Fit, interpolated_loss)``: the second is the last fit's loss before its own
    render, a measure of the interpolation error.
    """
    samples = list(samples)
    f = fit(samples, ref)
    interpolated = f.loss
    for _ in range(rounds):
        render(f.s)
        g = fit(samples, ref)
        settled = abs(math.log(g.s / f.s)) < u_tol
        interpolated, f = g.loss, g
        if settled:
            break
    render(f.s)
    u = math.log(f.s)
    coeffs = [smp.coefficients(u, ref) for smp in samples]
    v, L = best_scale(coeffs)
    r = math.exp(v)
    f.r, f.loss = r, L
    f.relmse = {smp.scene: float(A * r * r - 2 * B * r + C) for smp, (A, B, C) in zip(samples, coeffs)}
    f.energy = {smp.scene: r * smp.energy(u, ref) for smp in samples}
    return f, interpolated


def halves_se(fit_a, fit_b):
    """Eq. (C3): standard errors of ``s`` and ``r`` from the fits against the two halves."""
    return abs(fit_a.s - fit_b.s) / 2.0, abs(fit_a.r - fit_b.r) / 2.0
