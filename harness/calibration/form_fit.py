"""The regression of a calibration form (:mod:`sslpv_gl.material_form`, Eq. F1) on per-scene optima.

Pure functions on arrays, no renderer. For one budget, scene ``i`` has its own best
``(s_i, r_i)`` (the calibration's *oracle*, :mod:`harness.calibration.run`) and the scene-level
terms ``x_i`` (the mean of each term of (F1) over the scene's inside cells and colours,
:func:`sslpv_gl.material_form.mean_numbers`). Because (F1) is linear in the terms, the mean
``ln s`` over the scene's cells is ``a0 + a . x_i``, so the form is fitted by ridge regression::

    min_{a0, a}  sum_i (ln s_i - a0 - a . x_i)^2 + lam |D a|^2                             (F5)

with ``D`` the terms' standard deviations over the training scenes (the penalty is on the
standardised coefficients; ``a0`` is not penalised), the same for ``ln r``. ``lam`` is chosen
from :data:`LAMBDAS` by leave-one-out on the training scenes alone (:func:`choose_lambda`),
so a held-out scene never enters its own fit, not even through ``lam``. A term that is
constant over the training scenes (``ln_eta`` on an index-matched suite) is not identifiable:
its coefficient is 0. With ``testable`` (the conditional form, Eq. F7, uses it) so is the coefficient of a
term that leave-one-out cannot test: one whose spread vanishes when some single training scene is left out,
i.e. one scene alone sets it apart (:func:`loo_testable_terms`). Standardising divides that term by its small
spread, so its slope may be steep enough to fit that one scene at any penalty; a scene beyond it then
extrapolates far.

The form's level can instead be anchored to the family's scalar pair ``(s*, r*)`` fitted on the
render loss (C2) of the same training scenes (:func:`fit_form` ``anchor``)::

    a0 = ln s* - a . mean_i(x_i),   b0 = ln r* - b . mean_i(x_i)                             (F6)

so that the scenes' own optima, which scatter along the loss's valley in ``(ln s, ln r)``, set only
the slopes; with every slope 0 the form is the scalar calibration, bit for bit.

Limits: (F5) fits the oracle's parameters, not the render loss (C2); an oracle at the edge
of the scanned range (``at_bound``) is a censored value and enters as it is. The held-out
figures of :mod:`harness.calibration.form` come from renders, never from (F5).
"""

from __future__ import annotations

import numpy as np

__all__ = ["LAMBDAS", "loo_testable_terms", "ridge", "choose_lambda", "fit_form", "predict", "predictive_power"]

#: The ridge penalties (F5) that leave-one-out chooses from.
LAMBDAS = (1e-3, 1e-2, 0.1, 0.3, 1.0, 3.0, 10.0, 100.0)
#: A term whose standard deviation over the training scenes is below this is not identifiable.
MIN_SPREAD = 1e-9


def loo_testable_terms(X):
    """The terms (k,) bool that leave-one-out can test: their spread over the scenes ``X`` (n, k) stays above
    :data:`MIN_SPREAD` with any one scene left out (at least three distinct values, or two values each taken
    by two scenes or more). ``X`` (n, m, k): ``m`` rows per scene (its colour channels), left out together."""
    X = np.asarray(X, dtype=np.float64)
    k = X.shape[-1]
    use = X.reshape(-1, k).std(axis=0) > MIN_SPREAD
    for i in range(X.shape[0]):
        use &= np.delete(X, i, axis=0).reshape(-1, k).std(axis=0) > MIN_SPREAD
    return use


def ridge(X, y, lam, testable=False):
    """Eq. (F5) -> ``(a0, a)``: ``X`` (n, k) scene-level terms, ``y`` (n,) targets, ``lam`` >= 0; ``testable``:
    only the terms of :func:`loo_testable_terms` get a slope (else every term that is not constant)."""
    X, y = np.asarray(X, dtype=np.float64), np.asarray(y, dtype=np.float64)
    mx, my = X.mean(axis=0), y.mean()
    sd = X.std(axis=0)
    use = loo_testable_terms(X) if testable else sd > MIN_SPREAD
    a = np.zeros(X.shape[1])
    if use.any():
        Z = (X[:, use] - mx[use]) / sd[use]
        c = np.linalg.solve(Z.T @ Z + lam * np.eye(Z.shape[1]), Z.T @ (y - my))
        a[use] = c / sd[use]
    return float(my - mx @ a), a


def predict(a0, a, X):
    return a0 + np.asarray(X, dtype=np.float64) @ np.asarray(a, dtype=np.float64)


def _loo_error(X, y, lam, testable=False):
    err = 0.0
    for i in range(len(y)):
        keep = np.arange(len(y)) != i
        a0, a = ridge(X[keep], y[keep], lam, testable)
        err += float((predict(a0, a, X[i:i + 1])[0] - y[i]) ** 2)
    return err / len(y)


def predictive_power(X, y, lam, testable=False):
    """How well the terms predict a target: ``{"sd", "loo_rmse"}``, the targets' standard deviation and the
    root mean square leave-one-out error of (F5) at ``lam`` (a ``loo_rmse`` near ``sd`` predicts nothing
    beyond the mean). A diagnostic of the regression; no held-out figure comes from it."""
    X, y = np.asarray(X, dtype=np.float64), np.asarray(y, dtype=np.float64)
    return {"sd": float(y.std()), "loo_rmse": float(np.sqrt(_loo_error(X, y, lam, testable)))}


def choose_lambda(X, Ys, lambdas=LAMBDAS, testable=False):
    """The ``lam`` of :data:`LAMBDAS` with the least leave-one-out squared error, summed over the targets
    ``Ys`` (here ``ln s`` and ``ln r``), on these scenes alone (``testable`` as in :func:`ridge`)."""
    X = np.asarray(X, dtype=np.float64)
    errs = [sum(_loo_error(X, np.asarray(y, dtype=np.float64), lam, testable) for y in Ys) for lam in lambdas]
    return float(lambdas[int(np.argmin(errs))])


def fit_form(X, ln_s, ln_r, anchor=None, lambdas=LAMBDAS):
    """Eq. (F5) for ``ln s`` and ``ln r`` with one ``lam`` chosen by :func:`choose_lambda` -> dict with
    ``sigma`` and ``radiance`` (each ``[a0, *a]``) and ``lam``.

    ``anchor = (ln s*, ln r*)``, the scalar pair fitted on the render loss (C2) of the same scenes, sets
    the form's value at the scenes' mean terms (Eq. F6): ``a0 = ln s* - a . mean(x)``. The slopes come
    from (F5) and the level from the loss, so ``lam -> inf`` is the scalar calibration itself.
    """
    X = np.asarray(X, dtype=np.float64)
    lam = choose_lambda(X, (ln_s, ln_r), lambdas) if len(ln_s) >= 3 else float(lambdas[-1])
    s0, sa = ridge(X, ln_s, lam)
    r0, ra = ridge(X, ln_r, lam)
    if anchor is not None:                                                            # (F6)
        mx = X.mean(axis=0)
        s0, r0 = float(anchor[0] - mx @ sa), float(anchor[1] - mx @ ra)
    return {"sigma": [s0, *map(float, sa)], "radiance": [r0, *map(float, ra)], "lam": lam}
