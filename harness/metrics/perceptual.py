"""Perceptual image metrics: SSIM on tone-mapped images, and HDR-FLIP."""

import functools

import numpy as np
from skimage.metrics import structural_similarity

from harness.metrics.result import MetricResult, floats, luminance, masked_map, prepare

#: SSIM settings of Wang et al. 2004: 11x11 Gaussian window, sigma 1.5,
#: population covariance, K1 = 0.01, K2 = 0.03.
SSIM_DEFAULTS = {"win_size": 11, "sigma": 1.5, "K1": 0.01, "K2": 0.03}

FLIP_TONEMAPPERS = ("ACES", "Hable", "Reinhard")
#: FLIP's default viewing condition: 0.7 m from a 0.7 m wide 3840-pixel display.
FLIP_DEFAULT_PPD = 67.02064514160156


def ssim(test, ref, mask=None, *, win_size=11, sigma=1.5, K1=0.01, K2=0.03):
    r"""Structural similarity of Reinhard tone-mapped images.

    Both images are scaled by one exposure ``k`` fixed from the reference,
    ``k = 1 / mean(Y_ref over the mask)`` (Rec. 709 luminance ``Y``), so that
    the reference's mean maps to 1, then tone-mapped with
    :math:`t(v) = v / (1 + v)` per channel (negative values clamped to 0
    first). The tone-mapped images lie in ``[0, 1)``, so ``data_range`` is
    fixed at 1.0. SSIM is computed per channel by scikit-image with the
    settings of Wang et al. (Gaussian window, ``sigma = 1.5``, population
    covariance) on the full image; the SSIM map is then averaged over the
    masked pixels, leaving out the ``(win_size - 1) // 2`` pixel border as
    scikit-image does (so with no mask the value equals scikit-image's).

    The window reaches past the mask's edge. So that the value depends only on
    the test's masked pixels, the test takes the reference's values outside
    the mask before filtering; the reference's own pixels there act as the
    same context in both images.

    Parameters
    ----------
    test, ref : array_like, (H, W, 3)
        Linear RGB test and reference images; each side at least ``win_size``.
    mask : array_like of bool, (H, W), optional
        Pixels to pool over; ``None`` means all.
    win_size : int, default 11
        Odd side of the Gaussian window's support.
    sigma : float, default 1.5
        Standard deviation of the Gaussian window.
    K1, K2 : float, default 0.01, 0.03
        Stabilising constants of Wang et al.

    Returns
    -------
    MetricResult
        ``value`` is the mean of ``per_channel`` (1 is a perfect match,
        ``higher_is_better`` is True); ``error_map`` is ``1 - SSIM`` averaged
        over channels; ``params["exposure"]`` is ``k``.

    Raises
    ------
    ValueError
        If the reference is black over the mask, the image is smaller than the
        window, or the mask lies entirely in the border.

    References
    ----------
    .. [1] Z. Wang, A. C. Bovik, H. R. Sheikh, E. P. Simoncelli, "Image quality
       assessment: from error visibility to structural similarity", IEEE
       Trans. Image Processing 13(4), 2004.
    .. [2] E. Reinhard, M. Stark, P. Shirley, J. Ferwerda, "Photographic tone
       reproduction for digital images", ACM TOG 21(3), 2002.

    Examples
    --------
    >>> import numpy as np
    >>> ref = np.random.default_rng(0).random((16, 16, 3))
    >>> ssim(ref, ref).value
    1.0
    """
    x, y, m = prepare(test, ref, mask)
    win_size = int(win_size)
    if win_size < 3 or win_size % 2 == 0:
        raise ValueError(f"ssim: win_size must be an odd integer >= 3, got {win_size}")
    if min(y.shape[:2]) < win_size:
        raise ValueError(f"ssim: images of {y.shape[1]}x{y.shape[0]} are smaller than the "
                         f"{win_size}x{win_size} window; use a smaller win_size")
    mean_y = float(luminance(y)[m].mean())
    if not mean_y > 0:
        raise ValueError("ssim: the reference is black over the mask; the exposure is undefined")
    k = 1.0 / mean_y
    x = np.where(m[..., None], x, y)  # the test's outside-mask pixels must not count

    def tonemap(img):
        v = np.maximum(img, 0.0) * k
        return v / (1.0 + v)

    _, smap = structural_similarity(
        tonemap(x), tonemap(y), win_size=win_size, gaussian_weights=True, sigma=float(sigma),
        use_sample_covariance=False, K1=float(K1), K2=float(K2), data_range=1.0,
        channel_axis=-1, full=True)
    pad = (win_size - 1) // 2
    pooled = m.copy()
    pooled[:pad, :] = pooled[-pad:, :] = False
    pooled[:, :pad] = pooled[:, -pad:] = False
    if not pooled.any():
        raise ValueError(f"ssim: the mask lies entirely in the {pad}-pixel border that SSIM "
                         "leaves out")
    per_c = smap[pooled].mean(axis=0)
    params = {"tonemap": "v/(1+v) after clamping negatives to 0",
              "exposure": k, "exposure_from": "1 / mean Rec.709 luminance of ref over mask",
              "data_range": 1.0, "win_size": win_size, "gaussian_weights": True,
              "sigma": float(sigma), "use_sample_covariance": False, "K1": float(K1),
              "K2": float(K2), "border_excluded_px": pad,
              "outside_mask": "test replaced by ref before filtering"}
    return MetricResult("ssim", float(per_c.mean()), floats(per_c), params,
                        masked_map(1.0 - smap.mean(axis=-1), m), higher_is_better=True,
                        target=1.0)


@functools.lru_cache(maxsize=None)
def _flip_x_max(tonemapper):
    """log2 of the linear value that ``tonemapper`` maps to 0.85 (FLIP's x_max).

    Asked of FLIP itself: on an all-ones reference its start exposure is
    ``log2(x_max / 1)``.
    """
    import flip_evaluator
    ones = np.ones((8, 8, 3), np.float32)
    _, _, used = flip_evaluator.evaluate(ones, ones, "HDR", applyMagma=False,
                                         computeMeanError=False,
                                         parameters={"tonemapper": tonemapper})
    return float(used["startExposure"])


def flip(test, ref, mask=None, *, ppd=FLIP_DEFAULT_PPD, tonemapper="ACES",
         start_exposure=None, stop_exposure=None, num_exposures=None):
    r"""HDR-FLIP perceptual error, via NVIDIA's ``flip_evaluator``.

    Calls ``flip_evaluator.evaluate(ref, test, "HDR", applyMagma=False,
    parameters=...)``, which returns the FLIP map, its mean and the parameters
    it used. Negative values are clamped to 0 first (HDR-FLIP needs
    non-negative input).

    The exposure range defaults to FLIP's own rule (Andersson et al. 2021,
    Sec. 4), ``start = log2(x_max / max Y)``, ``stop = log2(x_max / median Y)``
    with ``x_max`` the value the tone mapper maps to 0.85, but with the
    maximum and median luminance taken over the reference's *masked* pixels
    (floored at float32 epsilon as FLIP does). With no mask this is exactly
    FLIP's default; with a mask, a black background does not stretch the
    range. FLIP's own mean is over the whole image; ``value`` is the map's
    mean over the mask. FLIP's filters reach past the mask's edge, so, as in
    :func:`ssim`, the test takes the reference's values outside the mask first.

    Parameters
    ----------
    test, ref : array_like, (H, W, 3)
        Linear RGB test and reference images.
    mask : array_like of bool, (H, W), optional
        Pixels to pool over; ``None`` means all.
    ppd : float, default 67.02
        Pixels per degree of visual angle (FLIP's default viewing condition).
    tonemapper : {"ACES", "Hable", "Reinhard"}, default "ACES"
        Tone mapper that HDR-FLIP assumes.
    start_exposure, stop_exposure : float, optional
        Exposure range in stops; computed from the reference when ``None``.
    num_exposures : int, optional
        Number of exposures; FLIP's ``max(2, ceil(stop - start))`` when ``None``.

    Returns
    -------
    MetricResult
        ``params`` holds the parameter dict that FLIP returned (``ppd``,
        ``startExposure``, ``stopExposure``, ``numExposures``, ``tonemapper``)
        and how the exposures were chosen; ``error_map`` is the FLIP map.

    References
    ----------
    .. [1] P. Andersson, J. Nilsson, T. Akenine-Moeller, M. Oskarsson, K. Astroem,
       M. D. Fairchild, "FLIP: A difference evaluator for alternating images",
       Proc. ACM Comput. Graph. Interact. Tech. 3(2), 2020.
    .. [2] P. Andersson, J. Nilsson, P. Shirley, T. Akenine-Moeller, "Visualizing
       errors in rendered high dynamic range images", Eurographics 2021
       short papers.

    Examples
    --------
    >>> import numpy as np
    >>> ref = np.random.default_rng(0).random((16, 16, 3))
    >>> flip(ref, ref).value
    0.0
    """
    import flip_evaluator

    x, y, m = prepare(test, ref, mask)
    # flip_evaluator prints and calls sys.exit on bad parameters: check them here.
    ppd = float(ppd)
    if not (np.isfinite(ppd) and ppd > 0):
        raise ValueError(f"flip: ppd must be a positive number, got {ppd!r}")
    names = {t.lower(): t for t in FLIP_TONEMAPPERS}
    if str(tonemapper).lower() not in names:
        raise ValueError(f"flip: unknown tonemapper {tonemapper!r}; known: {', '.join(FLIP_TONEMAPPERS)}")
    tonemapper = names[str(tonemapper).lower()]
    x = np.maximum(np.where(m[..., None], x, y), 0.0).astype(np.float32)
    y = np.maximum(y, 0.0).astype(np.float32)

    exposure_from = "given"
    if start_exposure is None or stop_exposure is None:
        # FLIP's rule (median = element size//2 of the sorted luminances, as
        # std::nth_element), restricted to the masked reference pixels.
        lum = np.sort(luminance(y.astype(np.float64))[m])
        tiny = float(np.finfo(np.float32).eps)
        x_max = _flip_x_max(tonemapper)
        if start_exposure is None:
            start_exposure = x_max - np.log2(max(lum[-1], tiny))
        if stop_exposure is None:
            stop_exposure = x_max - np.log2(max(lum[lum.size // 2], tiny))
        exposure_from = "FLIP's rule on the reference's masked pixels"
    start_exposure, stop_exposure = float(start_exposure), float(stop_exposure)
    if not (np.isfinite(start_exposure) and np.isfinite(stop_exposure)
            and start_exposure <= stop_exposure):
        raise ValueError(f"flip: need finite start_exposure <= stop_exposure, got "
                         f"{start_exposure} and {stop_exposure}")
    parameters = {"ppd": ppd, "tonemapper": tonemapper,
                  "startExposure": start_exposure, "stopExposure": stop_exposure}
    if num_exposures is not None:
        if int(num_exposures) < 2:
            raise ValueError(f"flip: num_exposures must be >= 2, got {num_exposures}")
        parameters["numExposures"] = int(num_exposures)

    fmap, _, used = flip_evaluator.evaluate(y, x, "HDR", applyMagma=False,
                                            computeMeanError=False, parameters=parameters)
    fmap = np.asarray(fmap, dtype=np.float64).reshape(y.shape[:2])
    params = {k: (v if isinstance(v, str) else float(v) if k != "numExposures" else int(v))
              for k, v in used.items()}
    params.update({"dynamic_range": "HDR", "exposure_from": exposure_from,
                   "outside_mask": "test replaced by ref before filtering",
                   "negatives": "clamped to 0", "pooling": "mean of the FLIP map over the mask"})
    return MetricResult("flip", float(fmap[m].mean()), None, params, masked_map(fmap, m),
                        higher_is_better=False, target=0.0)
