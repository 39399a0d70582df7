"""Per-pixel error metrics on linear HDR RGB: RMSE, relMSE, MAE, SMAPE, energy
ratio and scale-invariant relMSE.

All of them compare the raw linear values (no tone mapping), pool over the masked
pixels and the three channels, and return the per-channel values as well.
"""

import numpy as np

from harness.metrics.result import MetricResult, floats, masked_map, prepare

#: Default epsilon of relMSE and scale-invariant relMSE (Rousselle et al. 2011).
RELMSE_EPS = 1e-2
#: Default epsilon of SMAPE, added to the denominator to keep black pixels finite.
SMAPE_EPS = 1e-2


def _pool(err, mask):
    """Mean over masked pixels per channel (3,), and the per-pixel channel mean."""
    per_channel = err[mask].mean(axis=0)
    return per_channel, err.mean(axis=-1)


def rmse(test, ref, mask=None):
    r"""Root-mean-square error.

    .. math:: \mathrm{RMSE} = \sqrt{\tfrac{1}{3N}\sum_{p,c} (x_{pc} - y_{pc})^2}

    over the ``N`` masked pixels ``p`` and channels ``c``.

    Parameters
    ----------
    test, ref : array_like, (H, W, 3)
        Linear RGB test and reference images.
    mask : array_like of bool, (H, W), optional
        Pixels to pool over; ``None`` means all.

    Returns
    -------
    MetricResult
        ``value`` is the RMSE over all masked pixels and channels (so *not* the
        mean of ``per_channel``, which holds each channel's own RMSE);
        ``error_map`` is the per-pixel squared error averaged over channels.

    Examples
    --------
    A constant offset of 0.5 has an RMSE of 0.5:

    >>> import numpy as np
    >>> ref = np.full((4, 4, 3), 1.0, np.float32)
    >>> rmse(ref + 0.5, ref).value
    0.5
    """
    x, y, m = prepare(test, ref, mask)
    mse_c, sq_map = _pool((x - y) ** 2, m)
    return MetricResult("rmse", float(np.sqrt(mse_c.mean())), floats(np.sqrt(mse_c)), {},
                        masked_map(sq_map, m), higher_is_better=False, target=0.0)


def relmse(test, ref, mask=None, *, eps=RELMSE_EPS):
    r"""Relative mean-square error.

    .. math:: \mathrm{relMSE} = \tfrac{1}{3N}\sum_{p,c}
              \frac{(x_{pc} - y_{pc})^2}{y_{pc}^2 + \varepsilon}

    ``eps`` is absolute, in the images' radiance units, so it matters only
    where the reference is darker than about ``sqrt(eps)``.

    Parameters
    ----------
    test, ref : array_like, (H, W, 3)
        Linear RGB test and reference images.
    mask : array_like of bool, (H, W), optional
        Pixels to pool over; ``None`` means all.
    eps : float, default 1e-2
        Added to the squared reference (Rousselle et al. 2011).

    Returns
    -------
    MetricResult
        ``value`` is the mean of ``per_channel``; ``error_map`` is the
        per-pixel relative squared error averaged over channels.

    References
    ----------
    .. [1] F. Rousselle, C. Knaus, M. Zwicker, "Adaptive sampling and
       reconstruction using greedy error minimization", ACM TOG 30(6), 2011.

    Examples
    --------
    A test at twice a reference of 1 gives ``1 / (1 + 0.01)``:

    >>> import numpy as np
    >>> ref = np.ones((4, 4, 3), np.float32)
    >>> round(relmse(2 * ref, ref).value, 6)
    0.990099
    """
    eps = _positive("relmse", "eps", eps)
    x, y, m = prepare(test, ref, mask)
    per_c, err_map = _pool((x - y) ** 2 / (y ** 2 + eps), m)
    return MetricResult("relmse", float(per_c.mean()), floats(per_c), {"eps": eps},
                        masked_map(err_map, m), higher_is_better=False, target=0.0)


def mae(test, ref, mask=None):
    r"""Mean absolute error, :math:`\tfrac{1}{3N}\sum_{p,c} |x_{pc} - y_{pc}|`.

    Parameters
    ----------
    test, ref : array_like, (H, W, 3)
        Linear RGB test and reference images.
    mask : array_like of bool, (H, W), optional
        Pixels to pool over; ``None`` means all.

    Returns
    -------
    MetricResult
        ``value`` is the mean of ``per_channel``.

    Examples
    --------
    >>> import numpy as np
    >>> ref = np.ones((2, 2, 3), np.float32)
    >>> mae(ref - 0.25, ref).value
    0.25
    """
    x, y, m = prepare(test, ref, mask)
    per_c, err_map = _pool(np.abs(x - y), m)
    return MetricResult("mae", float(per_c.mean()), floats(per_c), {},
                        masked_map(err_map, m), higher_is_better=False, target=0.0)


def smape(test, ref, mask=None, *, eps=SMAPE_EPS):
    r"""Symmetric mean absolute percentage error.

    .. math:: \mathrm{SMAPE} = \tfrac{1}{3N}\sum_{p,c}
              \frac{2\,|x_{pc} - y_{pc}|}{|x_{pc}| + |y_{pc}| + \varepsilon}

    It lies in ``[0, 2)``. Some rendering papers (e.g. Vogels et al. 2018)
    drop the factor 2 and get ``[0, 1)``; halve this value to compare.

    Parameters
    ----------
    test, ref : array_like, (H, W, 3)
        Linear RGB test and reference images.
    mask : array_like of bool, (H, W), optional
        Pixels to pool over; ``None`` means all.
    eps : float, default 1e-2
        Added to the denominator, so that black pixels stay finite.

    Returns
    -------
    MetricResult
        ``value`` is the mean of ``per_channel``.

    References
    ----------
    .. [1] T. Vogels et al., "Denoising with kernel prediction and asymmetric
       loss functions", ACM TOG 37(4), 2018.

    Examples
    --------
    >>> import numpy as np
    >>> ref = np.ones((2, 2, 3))
    >>> round(smape(3 * ref, ref, eps=0.0).value, 6)
    1.0
    """
    eps = _positive("smape", "eps", eps, allow_zero=True)
    x, y, m = prepare(test, ref, mask)
    den = np.abs(x) + np.abs(y) + eps
    num = 2.0 * np.abs(x - y)
    # 0/0 (both black with eps = 0) is a perfect match.
    err = np.divide(num, den, out=np.zeros_like(num), where=den > 0)
    per_c, err_map = _pool(err, m)
    return MetricResult("smape", float(per_c.mean()), floats(per_c), {"eps": eps},
                        masked_map(err_map, m), higher_is_better=False, target=0.0)


def energy_ratio(test, ref, mask=None):
    r"""Ratio of total energies, :math:`\sum_p x_{pc} / \sum_p y_{pc}` per channel.

    1 is ideal: above 1 the test is too bright, below too dark. ``value`` is
    the mean of the three channel ratios; ``target`` is 1 and
    ``higher_is_better`` is False, so rank by ``abs(value - 1)``.

    Parameters
    ----------
    test, ref : array_like, (H, W, 3)
        Linear RGB test and reference images.
    mask : array_like of bool, (H, W), optional
        Pixels to sum over; ``None`` means all.

    Returns
    -------
    MetricResult
        No error map.

    Raises
    ------
    ValueError
        If a channel of the reference sums to zero (or less) over the mask.

    Examples
    --------
    >>> import numpy as np
    >>> ref = np.ones((2, 2, 3))
    >>> energy_ratio(2 * ref, ref).per_channel
    (2.0, 2.0, 2.0)
    """
    x, y, m = prepare(test, ref, mask)
    sx, sy = x[m].sum(axis=0), y[m].sum(axis=0)
    if np.any(sy <= 0):
        bad = ", ".join("RGB"[c] for c in np.flatnonzero(sy <= 0))
        raise ValueError(f"energy_ratio: the reference's {bad} channel sums to {sy.min():g} "
                         "over the mask; the ratio is undefined")
    ratio = sx / sy
    return MetricResult("energy_ratio", float(ratio.mean()), floats(ratio), {},
                        None, higher_is_better=False, target=1.0)


def si_relmse(test, ref, mask=None, *, eps=RELMSE_EPS):
    r"""Scale-invariant relMSE: relMSE after the best per-channel scale of the test.

    For each channel the scale

    .. math:: s_c = \arg\min_s \sum_p \frac{(s\,x_{pc} - y_{pc})^2}{y_{pc}^2+\varepsilon}
              = \frac{\sum_p x_{pc} y_{pc} / (y_{pc}^2+\varepsilon)}
                     {\sum_p x_{pc}^2 / (y_{pc}^2+\varepsilon)}

    is applied before :func:`relmse`. It separates errors in the *shape* of the
    image from an overall energy (calibration) error, which ``energy_ratio``
    and ``params["scales"]`` report. A channel whose test is black over the
    mask gets ``s = 1`` (every scale gives the same error).

    Parameters
    ----------
    test, ref : array_like, (H, W, 3)
        Linear RGB test and reference images.
    mask : array_like of bool, (H, W), optional
        Pixels to pool over (and fit the scales on); ``None`` means all.
    eps : float, default 1e-2
        As in :func:`relmse`.

    Returns
    -------
    MetricResult
        ``params["scales"]`` holds ``(s_R, s_G, s_B)``.

    Examples
    --------
    >>> import numpy as np
    >>> ref = np.linspace(0.1, 1.0, 12).reshape(2, 2, 3)
    >>> r = si_relmse(2 * ref, ref)
    >>> round(r.value, 12), r.params["scales"]
    (0.0, (0.5, 0.5, 0.5))
    """
    eps = _positive("si_relmse", "eps", eps)
    x, y, m = prepare(test, ref, mask)
    w = 1.0 / (y ** 2 + eps)
    xm, ym, wm = x[m], y[m], w[m]
    num, den = (xm * ym * wm).sum(axis=0), (xm ** 2 * wm).sum(axis=0)
    scales = np.where(den > 0, num / np.where(den > 0, den, 1.0), 1.0)
    per_c, err_map = _pool((scales * x - y) ** 2 * w, m)
    return MetricResult("si_relmse", float(per_c.mean()), floats(per_c),
                        {"eps": eps, "scales": floats(scales)},
                        masked_map(err_map, m), higher_is_better=False, target=0.0)


def _positive(metric, name, value, allow_zero=False):
    v = float(value)
    if not np.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{metric}: {name} must be a finite number {bound}, got {value!r}")
    return v
