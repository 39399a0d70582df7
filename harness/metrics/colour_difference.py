"""CIEDE2000 colour difference of HDR images normalised to a stated white."""

import numpy as np

from harness.metrics.result import MetricResult, luminance, masked_map, prepare

#: Percentile of the reference's masked luminance that becomes the white.
WHITE_PERCENTILE = 99.0
#: Normalised channel values are clamped to [0, CLAMP] before conversion.
CLAMP = 1.0


def srgb_to_lab(rgb):
    """Linear sRGB (white = 1) -> CIE L*a*b* with the D65 white, via CIE XYZ (colour-science).

    ``rgb`` is ``(..., 3)``; ``(1, 1, 1)`` becomes ``L* = 100, a* = b* = 0``.
    """
    import colour

    cs = colour.RGB_COLOURSPACES["sRGB"]
    xyz = colour.RGB_to_XYZ(np.asarray(rgb, dtype=np.float64), cs)
    return colour.XYZ_to_Lab(xyz, cs.whitepoint)


def delta_e_2000(lab_test, lab_ref):
    """CIEDE2000 colour difference of two ``(..., 3)`` L*a*b* arrays (Sharma, Wu, Dalal 2005; colour-science)."""
    import colour

    return colour.delta_E(np.asarray(lab_test, dtype=np.float64), np.asarray(lab_ref, dtype=np.float64),
                          method="CIE 2000")


def delta_e_2000_map(test, ref, mask=None, *, white_percentile=WHITE_PERCENTILE, clamp=CLAMP):
    r"""Per-pixel CIEDE2000 map and the parameters used (shared by the two metrics).

    Both images are divided by the same white ``W``, the ``white_percentile``
    percentile of the reference's Rec. 709 luminance over the mask, clamped
    per channel to ``[0, clamp]``, then converted linear sRGB -> CIE XYZ ->
    CIE L*a*b* (D65 white, colour-science) and compared with CIEDE2000.
    A luminance of ``W`` becomes L* = 100.

    Returns
    -------
    delta_e : ndarray, (H, W)
    mask : ndarray of bool, (H, W)
    params : dict
    """
    x, y, m = prepare(test, ref, mask)
    white_percentile = float(white_percentile)
    if not 0.0 < white_percentile <= 100.0:
        raise ValueError(f"ciede2000: white_percentile must be in (0, 100], got {white_percentile}")
    clamp = float(clamp)
    if not (np.isfinite(clamp) and clamp > 0):
        raise ValueError(f"ciede2000: clamp must be a positive number, got {clamp}")
    white = float(np.percentile(luminance(y)[m], white_percentile))
    if not white > 0:
        raise ValueError(f"ciede2000: the reference's {white_percentile:g}th-percentile luminance "
                         "over the mask is 0; no white to normalise to")
    de = delta_e_2000(srgb_to_lab(np.clip(x / white, 0.0, clamp)), srgb_to_lab(np.clip(y / white, 0.0, clamp)))
    params = {"white": white, "white_from": f"{white_percentile:g}th percentile of the "
              "reference's Rec.709 luminance over the mask", "white_percentile": white_percentile,
              "clamp": [0.0, clamp], "colourspace": "linear sRGB -> XYZ -> Lab, D65",
              "method": "CIE 2000"}
    return de, m, params


def ciede2000_mean(test, ref, mask=None, *, white_percentile=WHITE_PERCENTILE, clamp=CLAMP):
    r"""Mean CIEDE2000 colour difference over the masked pixels.

    See :func:`delta_e_2000_map` for the normalisation: both images are
    divided by the reference's 99th-percentile luminance (over the mask) and
    clamped to ``[0, 1]``, then converted linear sRGB -> XYZ -> Lab (D65).
    A difference of about 1 is just noticeable, side by side.

    Parameters
    ----------
    test, ref : array_like, (H, W, 3)
        Linear RGB test and reference images.
    mask : array_like of bool, (H, W), optional
        Pixels to pool over (and to take the white from); ``None`` means all.
    white_percentile : float, default 99
        Percentile of the reference's luminance that maps to white (L* = 100).
    clamp : float, default 1.0
        Upper clamp of the normalised channel values.

    Returns
    -------
    MetricResult
        ``error_map`` is the per-pixel Delta E 2000; ``params["white"]`` the
        white used.

    References
    ----------
    .. [1] G. Sharma, W. Wu, E. N. Dalal, "The CIEDE2000 color-difference
       formula: implementation notes, supplementary test data, and
       mathematical observations", Color Research & Application 30(1), 2005.

    Examples
    --------
    >>> import numpy as np
    >>> ref = np.random.default_rng(0).random((8, 8, 3))
    >>> ciede2000_mean(ref, ref).value
    0.0
    """
    de, m, params = delta_e_2000_map(test, ref, mask, white_percentile=white_percentile,
                                     clamp=clamp)
    return MetricResult("ciede2000_mean", float(de[m].mean()), None, params,
                        masked_map(de, m), higher_is_better=False, target=0.0)


def ciede2000_p95(test, ref, mask=None, *, white_percentile=WHITE_PERCENTILE, clamp=CLAMP,
                  percentile=95.0):
    r"""95th percentile of the CIEDE2000 colour difference over the masked pixels.

    The same map as :func:`ciede2000_mean`, pooled by a percentile
    (``numpy.percentile``, linear interpolation) to expose local colour errors
    that the mean hides.

    Parameters
    ----------
    test, ref : array_like, (H, W, 3)
        Linear RGB test and reference images.
    mask : array_like of bool, (H, W), optional
        Pixels to pool over; ``None`` means all.
    white_percentile, clamp : float
        As in :func:`ciede2000_mean`.
    percentile : float, default 95
        The percentile reported.

    Returns
    -------
    MetricResult

    References
    ----------
    .. [1] G. Sharma, W. Wu, E. N. Dalal, Color Research & Application 30(1), 2005.

    Examples
    --------
    >>> import numpy as np
    >>> ref = np.random.default_rng(0).random((8, 8, 3))
    >>> ciede2000_p95(ref, ref).value
    0.0
    """
    percentile = float(percentile)
    if not 0.0 <= percentile <= 100.0:
        raise ValueError(f"ciede2000_p95: percentile must be in [0, 100], got {percentile}")
    de, m, params = delta_e_2000_map(test, ref, mask, white_percentile=white_percentile,
                                     clamp=clamp)
    params["percentile"] = percentile
    return MetricResult("ciede2000_p95", float(np.percentile(de[m], percentile)), None, params,
                        masked_map(de, m), higher_is_better=False, target=0.0)
