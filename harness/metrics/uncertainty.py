r"""Paired differences of a metric against one noisy reference, with their standard errors.

Two *deterministic* test images (an old and a new SSLPV render) compared with the
*same* path-traced reference ``y`` share that reference's Monte Carlo noise. In

.. math:: \Delta = b(\mathrm{new}, y) - b(\mathrm{old}, y), \qquad b = |m - m^\ast|

(``b`` the metric's distance from its ideal value ``m*``, its *badness*) most of that
noise cancels; what is left is propagated from the reference's per-pixel standard
error ``se`` (``std(ddof=1)/sqrt(K)`` over ``K`` independent seeds,
:mod:`harness.reference.render`). Two routes:

**Delta method** (:data:`GRADIENTS`: relMSE, scale-invariant relMSE, energy ratio,
RMSE, MAE). With ``G = dDelta/dy`` (analytic, per pixel and channel) and
pixels independent (Mitsuba's box filter gives each sample to one pixel),

.. math:: \mathrm{Var}\,\Delta \approx \sum_p G_p^\top C_p G_p
          \le \sum_p \Big(\sum_c |G_{pc}|\, se_{pc}\Big)^2 ,

and the right-hand side is what is used: Mitsuba's RGB variants trace one path for
all three channels, so the channels of a pixel are strongly correlated (0.5 to
1.0 in the suite's references, measured from their independent halves), and the
bound (Cauchy-Schwarz: correlation 1 with the worst signs) holds for any correlation
without estimating it. Its degrees of freedom are Welch-Satterthwaite's,
``nu = (sum a_p)^2 / sum(a_p^2 / (K - 1))`` with ``a_p`` the pixel terms, each
estimated from ``K`` seeds.

**Resampling** (every other metric, FLIP among them, which has no cheap gradient):
``draws`` parametric resamples of the reference, ``y_b = y + se * zeta_b`` with one
standard normal ``zeta_b`` per pixel shared by its three channels (the fully
correlated case again, the largest luminance noise for a given ``se``), the same
draws for both images; ``SE = std_b(Delta_b)`` with ``nu = draws - 1``.

Both routes are checked against the spread of ``Delta`` over independently noisy
references in ``tests/test_uncertainty.py`` (synthetic) and
``benchmarks/accuracy_sensitivity.py`` (re-seeded Mitsuba references).
"""

from dataclasses import dataclass, field

import math

import numpy as np

from harness.metrics.pixel import RELMSE_EPS
from harness.metrics.registry import METRICS, compute
from harness.metrics.result import as_image, as_mask, prepare

#: Parametric resamples of the reference per paired difference without a gradient.
DEFAULT_DRAWS = 16


def badness(value, target):
    """Distance of a metric value from its ideal (``target``): ``|value - target|``."""
    return abs(float(value) - float(target))


# --------------------------------------------------------------------------- gradients

def _n(m):
    return 3.0 * float(m.sum())


def relmse_gradient(test, ref, mask, *, eps=RELMSE_EPS):
    r"""``d relMSE / d ref``: :math:`\frac{1}{3N}\left[-\frac{2(x-y)}{y^2+\varepsilon}
    - \frac{2y(x-y)^2}{(y^2+\varepsilon)^2}\right]` on the mask, 0 elsewhere."""
    x, y, m = prepare(test, ref, mask)
    w = 1.0 / (y * y + eps)
    r = x - y
    g = (-2.0 * r * w - 2.0 * y * r * r * w * w) / _n(m)
    return np.where(m[..., None], g, 0.0)


def si_relmse_gradient(test, ref, mask, *, eps=RELMSE_EPS):
    r"""``d si_relMSE / d ref``. The per-channel scale ``s_c`` minimises the error, so its
    own change does not enter (envelope theorem): the relMSE gradient with ``s_c x``."""
    from harness.metrics.pixel import si_relmse

    x, y, m = prepare(test, ref, mask)
    s = np.asarray(si_relmse(x, y, m, eps=eps).params["scales"])
    return relmse_gradient(s * x, y, m, eps=eps)


def energy_ratio_gradient(test, ref, mask):
    r"""``d energy_ratio / d ref``: :math:`-\frac{1}{3}\frac{\sum_p x_{pc}}{(\sum_p y_{pc})^2}`
    for every masked pixel of channel ``c``."""
    x, y, m = prepare(test, ref, mask)
    sx, sy = x[m].sum(axis=0), y[m].sum(axis=0)
    g = -sx / (3.0 * sy * sy)
    return np.where(m[..., None], g[None, None, :], 0.0)


def rmse_gradient(test, ref, mask):
    r"""``d RMSE / d ref``: :math:`-\frac{x - y}{3N\,\mathrm{RMSE}}` (0 where RMSE is 0)."""
    x, y, m = prepare(test, ref, mask)
    r = x - y
    value = np.sqrt((r[m] ** 2).mean())
    if value == 0:
        return np.zeros_like(x)
    return np.where(m[..., None], -r / (_n(m) * value), 0.0)


def mae_gradient(test, ref, mask):
    r"""``d MAE / d ref``: :math:`-\operatorname{sign}(x - y) / 3N`."""
    x, y, m = prepare(test, ref, mask)
    return np.where(m[..., None], -np.sign(x - y) / _n(m), 0.0)


#: metric name -> ``f(test, ref, mask) -> d value / d ref`` (H, W, 3), for the delta method.
GRADIENTS = {
    "relmse": relmse_gradient,
    "si_relmse": si_relmse_gradient,
    "energy_ratio": energy_ratio_gradient,
    "rmse": rmse_gradient,
    "mae": mae_gradient,
}


# --------------------------------------------------------------------------- paired difference

@dataclass(frozen=True)
class PairedDifference:
    """``badness(new) - badness(old)`` of one metric against one reference, with its standard error.

    Attributes
    ----------
    metric : str
    old, new : float
        The metric's values of the old and the new image against the reference.
    delta : float
        ``badness(new) - badness(old)``; positive is worse.
    se : float
        Standard error of ``delta`` from the reference's noise.
    dof : float
        Degrees of freedom of ``se`` (``inf`` when the reference's seed count is unknown).
    method : str
        ``"delta"``, ``"resampling"``, or ``"within-tolerance"`` (no standard error was needed).
    params : dict
        How ``se`` was obtained (draws, seed, seed count ``K``).
    """

    metric: str
    old: float
    new: float
    delta: float
    se: float
    dof: float
    method: str
    params: dict = field(default_factory=dict)


def _se_check(se, shape):
    if se is None:
        raise ValueError("paired_difference: the reference has no per-pixel standard error")
    s = np.asarray(se, dtype=np.float64)
    if s.shape != tuple(shape):
        raise ValueError(f"paired_difference: se shape {s.shape} differs from the images' {tuple(shape)}")
    if not np.all(np.isfinite(s)) or np.any(s < 0):
        raise ValueError("paired_difference: se must be finite and >= 0")
    return s


def delta_method_se(grad, se, mask, k=None):
    """``(SE, dof)`` of a difference whose gradient with respect to the reference is ``grad``.

    ``SE^2 = sum_p (sum_c |grad_pc| se_pc)^2`` over the masked pixels (the bound for any
    channel correlation, see the module docstring); ``dof`` by Welch-Satterthwaite
    from ``k`` seeds per pixel (``inf`` for ``k`` None).
    """
    g = np.asarray(grad, dtype=np.float64)
    s = _se_check(se, g.shape)
    m = as_mask(mask, g.shape)
    a = (np.abs(g) * s).sum(axis=-1)[m] ** 2
    var = float(a.sum())
    if var == 0.0 or not k or k < 2:
        return float(np.sqrt(var)), float("inf")
    return float(np.sqrt(var)), float(var * var / ((a * a).sum() / (k - 1)))


def _values(name, new, old, ref, mask):
    rn, ro = compute(name, new, ref, mask), compute(name, old, ref, mask)
    return rn, ro


def paired_difference(name, new, old, ref, se, mask=None, *, k=None, draws=DEFAULT_DRAWS, seed=0,
                      decided_within=None):
    """Paired difference of metric ``name`` for two test images against one reference.

    Parameters
    ----------
    name : str
        A metric of :data:`harness.metrics.METRICS`.
    new, old : array_like, (H, W, 3)
        The two test images.
    ref : array_like, (H, W, 3)
        The reference both are compared with.
    se : array_like, (H, W, 3)
        The reference's per-pixel standard error.
    mask : array_like of bool, (H, W), optional
    k : int, optional
        Seeds the standard error was estimated from (for the degrees of freedom).
    draws : int, default 16
        Resamples for a metric without a gradient (at least 2).
    seed : int, default 0
        Seed of the resamples (a verdict is reproducible).
    decided_within : float or callable, optional
        A tolerance (or a function of the old image's metric value that gives it) below which a
        verdict needs no standard error: when ``|delta|`` is at most this, the resamples are skipped (the costly part: ``2 draws`` evaluations of the metric)
        and ``se`` and ``dof`` are NaN, ``method`` ``"within-tolerance"``. A judge whose
        threshold is ``tolerance + t SE`` reaches the same verdict with any ``SE >= 0``.

    Returns
    -------
    PairedDifference

    Examples
    --------
    >>> import numpy as np
    >>> y = np.full((4, 4, 3), 1.0); se = np.full_like(y, 0.01)
    >>> d = paired_difference("energy_ratio", 1.2 * y, 1.1 * y, y, se)
    >>> round(d.delta, 6), d.method
    (0.1, 'delta')
    """
    if name not in METRICS:
        raise ValueError(f"unknown metric {name!r}; known metrics: {', '.join(METRICS)}")
    xn, y, m = prepare(new, ref, mask)
    xo = as_image(old, "old")
    if xo.shape != y.shape:
        raise ValueError(f"old and ref shapes differ: old {xo.shape}, ref {y.shape}")
    s = _se_check(se, y.shape)
    rn, ro = _values(name, xn, xo, y, m)
    target = rn.target
    delta = badness(rn.value, target) - badness(ro.value, target)
    if name in GRADIENTS:
        grad = GRADIENTS[name]
        sn, so = np.sign(rn.value - target), np.sign(ro.value - target)
        g = sn * grad(xn, y, m) - so * grad(xo, y, m)
        sd, dof = delta_method_se(g, s, m, k)
        return PairedDifference(name, float(ro.value), float(rn.value), float(delta), sd, dof, "delta",
                                {"K": k, "channels": "bound for any correlation"})
    draws = int(draws)
    if draws < 2:
        raise ValueError(f"paired_difference: draws must be >= 2, got {draws}")
    if callable(decided_within):
        decided_within = decided_within(ro.value)
    if decided_within is not None and abs(delta) <= float(decided_within):
        return PairedDifference(name, float(ro.value), float(rn.value), float(delta), math.nan, math.nan,
                                "within-tolerance", {"K": k, "decided_within": float(decided_within),
                                                     "resamples": "skipped: |delta| is within the tolerance"})
    rng = np.random.default_rng(seed)
    out = np.empty(draws)
    for b in range(draws):
        yb = y + s * rng.standard_normal(y.shape[:2])[..., None]
        out[b] = (badness(compute(name, xn, yb, m).value, target)
                  - badness(compute(name, xo, yb, m).value, target))
    return PairedDifference(name, float(ro.value), float(rn.value), float(delta), float(out.std(ddof=1)),
                            float(draws - 1), "resampling",
                            {"draws": draws, "seed": int(seed), "K": k,
                             "noise": "y + se * N(0, 1), one normal per pixel (channels fully correlated)"})
