"""The metric registry and its front doors.

``METRICS`` maps each name to its pure function; :func:`compute` validates the
name, the images, the mask and the parameters before dispatching, and
:func:`compare_images` is what the command line and the sweep call.
"""

import inspect


from harness.metrics.colour_difference import ciede2000_mean, ciede2000_p95
from harness.metrics.perceptual import flip, ssim
from harness.metrics.pixel import energy_ratio, mae, relmse, rmse, si_relmse, smape
from harness.metrics.result import as_image, as_mask, prepare

#: name -> metric function ``f(test, ref, mask=None, **params) -> MetricResult``.
METRICS = {
    "rmse": rmse,
    "relmse": relmse,
    "mae": mae,
    "smape": smape,
    "energy_ratio": energy_ratio,
    "si_relmse": si_relmse,
    "ssim": ssim,
    "flip": flip,
    "ciede2000_mean": ciede2000_mean,
    "ciede2000_p95": ciede2000_p95,
}


def _metric(name):
    try:
        return METRICS[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown metric {name!r}; known metrics: {', '.join(METRICS)}") from None


def metric_params(name):
    """The keyword parameters that metric ``name`` accepts, with their defaults."""
    sig = inspect.signature(_metric(name))
    return {p.name: p.default for p in sig.parameters.values() if p.kind is p.KEYWORD_ONLY}


def compute(name, test, ref, mask=None, **params):
    """Compute one metric by name.

    Parameters
    ----------
    name : str
        A key of :data:`METRICS`.
    test, ref : array_like, (H, W, 3)
        Linear RGB images of the same shape, finite.
    mask : array_like of bool, (H, W), optional
        Pixels to pool over; ``None`` means all.
    **params
        The metric's keyword parameters (see :func:`metric_params`).

    Returns
    -------
    MetricResult

    Raises
    ------
    ValueError
        For an unknown name (the message lists the known ones), an unknown
        parameter, mismatched shapes (both are named), NaN/Inf values, or a
        bad mask.

    Examples
    --------
    >>> import numpy as np
    >>> ref = np.ones((4, 4, 3))
    >>> compute("rmse", ref + 0.5, ref).value
    0.5
    >>> compute("psnr", ref, ref)
    Traceback (most recent call last):
    ...
    ValueError: unknown metric 'psnr'; known metrics: rmse, relmse, mae, smape, energy_ratio, si_relmse, ssim, flip, ciede2000_mean, ciede2000_p95
    """
    fn = _metric(name)
    accepted = metric_params(name)
    unknown = sorted(set(params) - set(accepted))
    if unknown:
        raise ValueError(f"{name}: unknown parameter(s) {', '.join(unknown)}; accepted: "
                         f"{', '.join(accepted) or 'none'}")
    x, y, m = prepare(test, ref, mask)
    return fn(x, y, m, **params)


def compute_all(test, ref, mask=None, names=None):
    """Compute several metrics (all of :data:`METRICS` by default) with default parameters.

    Returns
    -------
    dict of str to MetricResult
        In the order of ``names`` (or of the registry).
    """
    names = list(METRICS) if names is None else list(names)
    for n in names:
        _metric(n)
    x, y, m = prepare(test, ref, mask)
    return {n: compute(n, x, y, m) for n in names}


def noise_floor(half_a, half_b, mask=None, names=None):
    """Each metric between two independent halves of a reference render.

    ``half_a`` plays the test and ``half_b`` the reference (relMSE, SMAPE and
    the energy ratio are not symmetric). It estimates how much of a metric is
    Monte Carlo noise rather than error: a test image whose metric against the
    full reference is near the floor is as good as the reference can tell.

    The floor is conservative, and is stored as computed, not rescaled: each
    half has twice the variance of the full reference (sqrt(2) more noise),
    so the difference of the halves has four times the variance that an exact
    image compared with the full reference would show (for noise-dominated
    pixels RMSE doubles, MSE-type metrics quadruple). No one factor fits the
    non-linear metrics, so none is applied.

    Returns
    -------
    dict of str to MetricResult
    """
    return compute_all(half_a, half_b, mask, names)


def compare_images(test, ref, mask=None, half_a=None, half_b=None, names=None):
    """All metrics of ``test`` against ``ref``, with noise floors when the halves are given.

    Parameters
    ----------
    test, ref : array_like, (H, W, 3)
        Linear RGB images.
    mask : array_like of bool, (H, W), optional
    half_a, half_b : array_like, (H, W, 3), optional
        Two independent halves of the reference; give both or neither.
    names : sequence of str, optional
        Metrics to compute; all by default.

    Returns
    -------
    list of dict
        One row per metric: ``metric``, ``value``, ``per_channel`` (tuple or
        None), ``noise_floor`` (float or None), ``params``, ``higher_is_better``
        and ``target``.
    """
    if (half_a is None) != (half_b is None):
        raise ValueError("compare_images: give both half_a and half_b, or neither")
    y = as_image(ref, "ref")
    results = compute_all(test, y, mask, names)
    floors = {}
    if half_a is not None:
        a, b = as_image(half_a, "half_a"), as_image(half_b, "half_b")
        for what, h in (("half_a", a), ("half_b", b)):
            if h.shape != y.shape:
                raise ValueError(f"{what} shape {h.shape} differs from ref shape {y.shape}")
        floors = noise_floor(a, b, as_mask(mask, y.shape), list(results))
    return [{"metric": n, "value": r.value, "per_channel": r.per_channel,
             "noise_floor": floors[n].value if n in floors else None, "params": r.params,
             "higher_is_better": r.higher_is_better, "target": r.target}
            for n, r in results.items()]
