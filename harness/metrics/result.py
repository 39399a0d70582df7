"""The result type shared by every metric, and the input checks they all use.

Every metric is a pure function ``f(test, ref, mask=None, **params) ->
MetricResult`` on float32 ``(H, W, 3)`` linear HDR RGB images (see
``docs/conventions.md``). ``mask`` is a boolean ``(H, W)`` array; ``None`` means
every pixel. Pooled values average over the masked pixels only.
"""

from dataclasses import dataclass, field

import numpy as np

#: Rec. 709 / linear sRGB luminance weights (the Y row of the sRGB->XYZ matrix).
LUMINANCE_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])


@dataclass(frozen=True)
class MetricResult:
    """What one metric says about one pair of images.

    Attributes
    ----------
    name : str
        Registry name of the metric (``"rmse"``, ``"flip"``, ...).
    value : float
        The pooled value over the masked pixels.
    per_channel : tuple of 3 float or None
        The value per R, G, B channel where the metric is defined per channel.
    params : dict
        Every parameter that produced ``value`` (defaults included, and values
        derived from the reference such as exposures or scales), as plain
        JSON-ready Python types.
    error_map : ndarray or None
        Float32 ``(H, W)`` per-pixel error whose masked mean is the pooled value
        (or, for ``rmse``, its square); 0 outside the mask. ``None`` for
        metrics without a per-pixel form.
    higher_is_better : bool
        ``True`` only for similarity scores (``ssim``).
    target : float
        The value of a perfect match: 0 for errors, 1 for ``ssim`` and
        ``energy_ratio``. For ``energy_ratio`` both directions are bad;
        rank by ``abs(value - target)``.
    """

    name: str
    value: float
    per_channel: tuple | None
    params: dict
    error_map: np.ndarray | None = field(default=None, repr=False, compare=False)
    higher_is_better: bool = False
    target: float = 0.0


def as_image(arr, what):
    """Check one image: ``(H, W, 3)``, finite; returns it as float64."""
    a = np.asarray(arr)
    if a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"{what}: expected an (H, W, 3) RGB image, got shape {a.shape}")
    if not np.issubdtype(a.dtype, np.number) or np.iscomplexobj(a):
        raise ValueError(f"{what}: expected a real-valued image, got dtype {a.dtype}")
    a = a.astype(np.float64)
    if not np.all(np.isfinite(a)):
        bad = int(np.count_nonzero(~np.isfinite(a)))
        raise ValueError(f"{what}: contains {bad} NaN or Inf values; metrics need finite images")
    return a


def as_mask(mask, shape):
    """Check a mask against an image ``shape`` (H, W, 3); ``None`` -> all True."""
    if mask is None:
        return np.ones(shape[:2], dtype=bool)
    m = np.asarray(mask)
    if m.shape != tuple(shape[:2]):
        raise ValueError(f"mask: shape {m.shape} does not match the images' (H, W) = {tuple(shape[:2])}")
    if m.dtype != bool:
        if not np.issubdtype(m.dtype, np.number) or not np.all((m == 0) | (m == 1)):
            raise ValueError(f"mask: expected a boolean (H, W) array, got dtype {m.dtype} "
                             "with values other than 0 and 1")
        m = m.astype(bool)
    if not m.any():
        raise ValueError("mask: selects no pixels; metrics need at least one")
    return m


def prepare(test, ref, mask):
    """Validate a (test, ref, mask) triple; returns float64 images and a bool mask."""
    x = as_image(test, "test")
    y = as_image(ref, "ref")
    if x.shape != y.shape:
        raise ValueError(f"test and ref shapes differ: test {x.shape}, ref {y.shape}")
    return x, y, as_mask(mask, y.shape)


def luminance(rgb):
    """Rec. 709 luminance of linear RGB, shape ``(H, W)``."""
    return rgb @ LUMINANCE_WEIGHTS


def masked_map(per_pixel, mask):
    """Float32 error map with pixels outside ``mask`` set to 0."""
    return np.where(mask, per_pixel, 0.0).astype(np.float32)


def floats(values):
    """A tuple of plain Python floats."""
    return tuple(float(v) for v in values)
