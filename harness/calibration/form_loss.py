"""A calibration form fitted on the render loss itself (Eqs. F8, F9), through the scan's interpolated images.

Pure functions on arrays, no renderer. The forms (F5) and (F7) regress targets: the scenes' own optima,
or each scene's best radiance scale at a fixed ``sigma_scale``. (F8) fits the form's coefficients on the
calibration's loss (C2 of :mod:`harness.calibration.fit`) directly. For scene ``i`` with scene-level terms
``x_i`` (:func:`harness.calibration.form.scene_terms`) the form gives ``u_i = ln s_i = a0 + a . x_i`` and
``v_i = ln r_i = b0 + b . x_i``, and::

    min_{a0, a, b0, b}  sum_i ln relMSE_i(u_i, v_i) + lam (|D a|^2 + |D b|^2)                 (F8)

with ``D`` the terms' standard deviations over the training scenes (standardised slopes, as in F5) and
``relMSE_i(u, v) = A_i(u) r^2 - 2 B_i(u) r + C_i`` (Eq. C1). A render per optimiser step is not needed:
``I_i(s)`` is known at the scan's samples and interpolated between them by the calibration's own cubic
spline of the image (:class:`~harness.calibration.fit.SceneSamples`). :func:`scene_table` evaluates
``(A_i, B_i, C_i)`` once on a fine grid of ``u`` (:func:`scan_grid`) from those images; between its points they are
interpolated linearly, which keeps ``A C >= B^2`` (a convex combination of quadratics in ``r`` that are
never negative is never negative).

With every slope 0, (F8) is the scalar calibration (C2), so ``lam -> inf`` gives it back; the levels
``a0, b0`` need no anchor (F6). The optimiser (L-BFGS with the analytic gradient; Powell's method where its
line search fails on a kink of the interpolated loss) starts there (the scalar optimum on the table's grid),
so the result is the local minimum nearest the scalar fit. ``lam`` is chosen from
:data:`~harness.calibration.form_fit.LAMBDAS` by leave-one-out on the training scenes alone: each training
scene's ``ln relMSE`` at the ``(u, v)`` the others' fit predicts for it (:func:`choose_lambda_loss`). Only
the terms that leave-one-out can test get a slope
(:func:`~harness.calibration.form_fit.loo_testable_terms`).

**Each colour channel at its own terms (F9).** SSLPV propagates each colour channel alone (``sigma_lpv``, the
grids and the shading are per colour) and a form's scales are per cell and channel, so channel ``c`` of a
scene's image depends on ``(s_ic, r_ic)`` only (``tests/test_calibrated_form_channels.py`` checks it on the
renderer), and the relMSE (C1) is the mean of the channels' (every channel has the same pixels)::

    min  sum_i ln( (1/3) sum_c relMSE_ic(a0 + a . x_ic, b0 + b . x_ic) ) + lam (|D a|^2 + |D b|^2)      (F9)

with ``x_ic`` each term's mean over the scene's inside cells in channel ``c`` and ``(A, B, C)_ic`` from that
channel's pixels (:func:`scene_table_channels`; their mean over the channels is :func:`scene_table`). A scene's
channels share its geometry, lights and extent and differ in ``sigma_tr dx`` and absorption, so a dependence on
those terms is seen within every scene, not only between scenes. Leave-one-out leaves a scene's channels out
together. With one row per scene (F9) is (F8); the same functions fit both (``X`` (n, k) or (n, m, k)).

Limits:

* a scene whose material varies (``jade_veins``) enters at its mean terms (per channel for F9), as though rendered at one
  ``(s, r)``; the form varies per cell, so its render differs. The held-out figures come from renders;
* ``u`` is clamped to the scanned range (beyond it the loss is flat), so a slope cannot be fitted past the
  scan, and a prediction beyond it is judged, in leave-one-out, as at the scan's end;
* the loss is not convex in ``u``: the fit is a local minimum.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize

from harness.calibration.fit import V_BOUNDS, relmse_coefficients
from harness.calibration.form_fit import LAMBDAS, loo_testable_terms

__all__ = ["U_POINTS", "scan_grid", "scene_table", "scene_table_channels", "table_loss", "fit_loss_form",
           "choose_lambda_loss", "loss_power"]

#: Points of the fine ``u`` grid (:func:`scan_grid`) on which :func:`scene_table` evaluates (A, B, C).
U_POINTS = 193
#: relMSE below this is taken as this (the log stays finite).
Q_FLOOR = 1e-12
#: ln relMSE where ``r = exp(v)`` overflows the float range (an optimiser's trial step): above any real loss.
L_OVERFLOW = 1e3


def scan_grid(sigma_scan, points=U_POINTS):
    """The fine grid of ``u = ln s`` (``points`` values) spanning the scan's ``sigma_scale`` samples."""
    return np.linspace(np.log(min(sigma_scan)), np.log(max(sigma_scan)), points)


def scene_table(samples, u_grid, ref="full"):
    """(A, B, C) of one scene's :class:`~harness.calibration.fit.SceneSamples` at each ``u`` of ``u_grid`` -> (P, 3),
    from the spline of its images; a ``u`` beyond the scene's own samples (a failed render at the scan's end)
    takes the value at its nearest sample. Each scene's table depends on its own renders alone."""
    lo, hi = samples.u_range
    return np.array([samples.coefficients(float(min(max(x, lo), hi)), ref) for x in u_grid])


def scene_table_channels(samples, u_grid, ref="full", channels=3):
    """Eq. (F9): (A, B, C) of each colour channel of one scene at each ``u`` of ``u_grid`` -> (channels, P, 3), as
    :func:`scene_table` (the same spline, the same clamping) on that channel's pixels alone. A masked image
    flattens pixel by pixel, so channel ``c`` is every ``channels``-th value from ``c``; every channel has the
    same pixels, so the mean over the channels is :func:`scene_table`."""
    lo, hi = samples.u_range
    R = samples.refs[ref]
    out = np.empty((channels, len(u_grid), 3))
    for j, x in enumerate(u_grid):
        img = samples.image_at(float(min(max(x, lo), hi)))
        for c in range(channels):
            out[c, j] = relmse_coefficients(img[c::channels], R[c::channels])
    return out


def _losses(u_grid, T, u, v):
    """Eq. (C1) on the tables ``T`` (n, m, P, 3): ``m`` rows per scene (one, or one per colour channel, Eq. F9) at
    ``u``, ``v`` (n, m) -> ``(ln relMSE, d/du, d/dv)``, (n,), (n, m), (n, m); a scene's relMSE is the mean of its rows'.
    (A, B, C) are interpolated linearly in ``u``, which is clamped to the grid (there d/du is 0)."""
    n, m, P = T.shape[:3]
    T = T.reshape(n * m, P, 3)
    u, v = np.asarray(u, dtype=np.float64).ravel(), np.asarray(v, dtype=np.float64).ravel()
    uc = np.clip(u, u_grid[0], u_grid[-1])
    j = np.clip(np.searchsorted(u_grid, uc) - 1, 0, len(u_grid) - 2)
    h = u_grid[j + 1] - u_grid[j]
    t = ((uc - u_grid[j]) / h)[:, None]
    rows = np.arange(T.shape[0])
    lo, hi = T[rows, j], T[rows, j + 1]
    val = lo * (1.0 - t) + hi * t
    der = (hi - lo) / h[:, None] * ((u > u_grid[0]) & (u < u_grid[-1]))[:, None]
    with np.errstate(over="ignore", invalid="ignore"):          # an optimiser's trial step far out in v
        r = np.exp(v)
        q = (val[:, 0] * r * r - 2.0 * val[:, 1] * r + val[:, 2]).reshape(n, m).mean(axis=1)
        dq_du = (der[:, 0] * r * r - 2.0 * der[:, 1] * r + der[:, 2]).reshape(n, m) / m
        dq_dv = (2.0 * val[:, 0] * r * r - 2.0 * val[:, 1] * r).reshape(n, m) / m
    finite = np.isfinite(q)
    ok = finite & (q > Q_FLOOR)
    qs = np.where(ok, q, 1.0)
    # relMSE grows as r^2 beyond the float range: there the loss is the largest, never the floor's
    L = np.where(ok, np.log(qs), np.where(finite, np.log(Q_FLOOR), L_OVERFLOW))
    return L, np.where(ok[:, None], dq_du / qs[:, None], 0.0), np.where(ok[:, None], dq_dv / qs[:, None], 0.0)


def _rows(X, tabs):
    """``(X, T)`` with ``m`` rows per scene: ``X`` (n, m, k) and ``T`` (n, m, P, 3), from ``X`` (n, k) with ``tabs``
    of (P, 3) (one row per scene, Eq. F8) or ``X`` (n, m, k) with ``tabs`` of (m, P, 3) (Eq. F9)."""
    T = np.stack([np.asarray(tb, dtype=np.float64) for tb in tabs])
    X = np.asarray(X, dtype=np.float64)
    if T.ndim == 3:
        T = T[:, None]
    if X.ndim == 2:
        X = X[:, None, :]
    return X, T


def table_loss(u_grid, tab, u, v):
    """``(ln relMSE, d/du, d/dv)`` of one scene (its table ``tab``, (P, 3)) at ``(u, v)`` (Eq. C1)."""
    L, du, dv = _losses(u_grid, np.asarray(tab, dtype=np.float64)[None, None], [u], [v])
    return float(L[0]), float(du[0, 0]), float(dv[0, 0])


def _scene_loss(u_grid, tab, u, v):
    """ln relMSE of one scene with ``m`` rows (``tab`` (P, 3) or (m, P, 3)) at ``u``, ``v`` (scalars or (m,))."""
    T = np.asarray(tab, dtype=np.float64)
    T = T[None, None] if T.ndim == 2 else T[None]
    m = T.shape[1]
    return float(_losses(u_grid, T, np.broadcast_to(u, (m,))[None], np.broadcast_to(v, (m,))[None])[0][0])


def _scalar_start(u_grid, tabs, v_points=201):
    """The scalar calibration on the table: ``(u, v)`` minimising the mean ln relMSE (C2) over the ``u`` grid and
    a grid of ``v`` spanning the scenes' own best ``ln(B / A)`` (the optimiser refines it)."""
    T = np.stack([np.asarray(tb, dtype=np.float64) for tb in tabs])
    if T.ndim == 4:                                              # rows of a scene (F9) at one (u, v): their mean
        T = T.mean(axis=1)
    A, B, C = T[..., 0], T[..., 1], T[..., 2]                    # (n, P)
    ok = (A > 0) & (B > 0)
    if not ok.any():
        return float(u_grid[len(u_grid) // 2]), 0.0
    best_v = np.log(B[ok] / A[ok])
    v = np.linspace(max(best_v.min(), V_BOUNDS[0]), min(best_v.max(), V_BOUNDS[1]) + 1e-9, v_points)
    r = np.exp(v)[None, None, :]
    q = A[..., None] * r * r - 2.0 * B[..., None] * r + C[..., None]
    L = np.log(np.maximum(q, Q_FLOOR)).mean(axis=0)              # (P, V)
    j, i = np.unravel_index(int(np.argmin(L)), L.shape)
    return float(u_grid[j]), float(v[i])


def fit_loss_form(X, u_grid, tabs, lam, start=None):
    """Eq. (F8) on the scenes of ``X`` (n, k) with tables ``tabs`` (n of (P, 3)), or Eq. (F9) on ``X`` (n, m, k) with
    ``tabs`` (n of (m, P, 3)) -> ``(sigma, radiance)``, each ``[const, *slopes]`` on the raw terms (a slope 0 for a
    term that leave-one-out cannot test)."""
    X, T = _rows(X, tabs)
    n, m, k = X.shape
    use = loo_testable_terms(X) if n >= 3 else np.zeros(k, bool)
    flat = X.reshape(n * m, k)
    mx, sd = flat.mean(axis=0), flat.std(axis=0)
    Z = (X[..., use] - mx[use]) / sd[use]                        # (n, m, k_use)
    q = Z.shape[2]
    u0, v0 = start if start is not None else _scalar_start(u_grid, tabs)

    def f(theta):
        a0, al, b0, be = theta[0], theta[1:1 + q], theta[1 + q], theta[2 + q:]
        L, du, dv = _losses(u_grid, T, a0 + Z @ al, b0 + Z @ be)
        grad = np.concatenate([[du.sum()], np.einsum("imk,im->k", Z, du) + 2.0 * lam * al,
                               [dv.sum()], np.einsum("imk,im->k", Z, dv) + 2.0 * lam * be])
        return float(L.sum() + lam * (al @ al + be @ be)), grad

    theta0 = np.concatenate([[u0], np.zeros(q), [v0], np.zeros(q)])
    theta, best = theta0, f(theta0)[0]
    res = minimize(f, theta0, jac=True, method="L-BFGS-B", options={"maxiter": 500})
    if res.fun < best:
        theta, best = res.x, float(res.fun)
    if not res.success:             # a line search that fails on a kink of the interpolated loss: no gradients
        res = minimize(lambda th: f(th)[0], theta, method="Powell", options={"maxiter": 4000, "xtol": 1e-6})
        if res.fun < best:
            theta = res.x
    out = []
    for c0, c in ((theta[0], theta[1:1 + q]), (theta[1 + q], theta[2 + q:])):
        raw = np.zeros(k)
        raw[use] = c / sd[use]
        out.append([float(c0 - mx @ raw), *map(float, raw)])
    return out[0], out[1]


def _predict(coeffs, x):
    """(F1) at a scene's terms ``x``: (k,) -> a float, (m, k) -> (m,)."""
    return coeffs[0] + np.asarray(x, dtype=np.float64) @ np.asarray(coeffs[1:], dtype=np.float64)


def _loo_starts(u_grid, tabs):
    """For each scene, the scalar calibration of the others on the table (:func:`_scalar_start`): the start of
    its leave-one-out fit at every ``lam``, and the scalar's own leave-one-out prediction."""
    return [_scalar_start(u_grid, [t for j, t in enumerate(tabs) if j != i]) for i in range(len(tabs))]


def _loo_losses(X, u_grid, tabs, lam, starts):
    """Each scene's ln relMSE at the ``(u, v)`` that (F8) on the others predicts for it (``lam = None``: every
    slope 0, the scalar calibration of the others); ``starts`` from :func:`_loo_starts`."""
    X = np.asarray(X, dtype=np.float64)
    out = []
    for i in range(len(tabs)):
        keep = [j for j in range(len(tabs)) if j != i]
        if lam is None:
            u, v = starts[i]
        else:
            s, r = fit_loss_form(X[keep], u_grid, [tabs[j] for j in keep], lam, start=starts[i])
            u, v = _predict(s, X[i]), _predict(r, X[i])
        out.append(_scene_loss(u_grid, tabs[i], u, v))
    return out


def choose_lambda_loss(X, u_grid, tabs, lambdas=LAMBDAS):
    """The ``lam`` of ``lambdas`` with the least summed leave-one-out ln relMSE on these scenes alone."""
    starts = _loo_starts(u_grid, tabs)
    errs = [sum(_loo_losses(X, u_grid, tabs, lam, starts)) for lam in lambdas]
    return float(lambdas[int(np.argmin(errs))])


def loss_power(X, u_grid, tabs, lam):
    """How much the terms help, in the loss itself: ``{"form", "scalar"}``, the mean leave-one-out ln relMSE
    of (F8) at ``lam`` and of the scalar calibration (every slope 0). A diagnostic; no held-out figure
    comes from it."""
    starts = _loo_starts(u_grid, tabs)
    return {"form": float(np.mean(_loo_losses(X, u_grid, tabs, lam, starts))),
            "scalar": float(np.mean(_loo_losses(X, u_grid, tabs, None, starts)))}
