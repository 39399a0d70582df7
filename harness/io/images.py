"""OpenEXR and PNG input/output for linear HDR RGB images.

Images are float32 ``(H, W, 3)``, row 0 at the top. An EXR may carry a per-pixel
standard error as the channels ``R_se, G_se, B_se`` and any further named
single-channel layers.
"""

from pathlib import Path

import numpy as np
import OpenEXR
from PIL import Image

from harness.io.atomic import atomic_write
from harness.errors import InputError

_RGB = ("R", "G", "B")
_SE = ("R_se", "G_se", "B_se")


def write_exr(path, rgb, se=None, extra=None, header=None):
    """Write ``rgb`` (and optionally its standard error ``se``) as float32 EXR, atomically."""
    rgb = np.ascontiguousarray(rgb, dtype=np.float32)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"write_exr: expected (H, W, 3), got {rgb.shape}")
    channels = {c: np.ascontiguousarray(rgb[..., i]) for i, c in enumerate(_RGB)}
    if se is not None:
        se = np.asarray(se, dtype=np.float32)
        channels.update({c: np.ascontiguousarray(se[..., i]) for i, c in enumerate(_SE)})
    for name, arr in (extra or {}).items():
        channels[name] = np.ascontiguousarray(arr, dtype=np.float32)
    hdr = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    hdr.update(header or {})
    with atomic_write(path) as tmp:
        with OpenEXR.File(hdr, channels) as f:
            f.write(str(tmp))


def read_exr(path, expect_shape=None):
    """Read an EXR written by :func:`write_exr`.

    Returns a dict with ``rgb`` (H, W, 3) and, when present, ``se`` and the extra
    layers. Raises :class:`InputError` for a missing file, missing channels, a
    wrong size or NaN/Inf values.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file", "does not exist", "check the path")
    try:
        with OpenEXR.File(str(path), separate_channels=True) as f:
            ch = {k: np.asarray(v.pixels, dtype=np.float32) for k, v in f.channels().items()}
    except Exception as exc:  # OpenEXR raises bare RuntimeErrors for corrupt files
        raise InputError(path, "file", f"not a readable OpenEXR file ({exc})", "re-render it") from exc
    missing = [c for c in _RGB if c not in ch]
    if missing:
        raise InputError(path, "channels", f"missing {','.join(missing)}", "write R, G and B channels")
    out = {"rgb": np.stack([ch.pop(c) for c in _RGB], axis=-1)}
    if all(c in ch for c in _SE):
        out["se"] = np.stack([ch.pop(c) for c in _SE], axis=-1)
    out.update(ch)
    if expect_shape is not None and out["rgb"].shape[:2] != tuple(expect_shape):
        raise InputError(path, "size", f"is {out['rgb'].shape[1]}x{out['rgb'].shape[0]}, expected "
                         f"{expect_shape[1]}x{expect_shape[0]}", "compare images of the same size")
    for key, arr in out.items():
        if not np.all(np.isfinite(arr)):
            bad = int(np.count_nonzero(~np.isfinite(arr)))
            raise InputError(path, key, f"contains {bad} NaN or Inf values", "re-render or fix the image")
    return out


def to_srgb8(rgb, exposure=0.0):
    """Linear RGB -> 8-bit sRGB after scaling by ``2**exposure`` and clamping to [0, 1]."""
    x = np.clip(np.nan_to_num(rgb) * (2.0 ** exposure), 0.0, 1.0)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return (srgb * 255.0 + 0.5).astype(np.uint8)


def auto_exposure(rgb, percentile=99.0):
    """Exposure (stops) that maps the given percentile of the non-zero luminance to 0.9."""
    lum = np.asarray(rgb, dtype=np.float64).mean(axis=-1)
    lit = lum[lum > 0]
    if lit.size == 0:
        return 0.0
    return float(np.log2(0.9 / max(np.percentile(lit, percentile), 1e-12)))


def write_png(path, rgb, exposure=0.0):
    """Tone-map (exposure then sRGB clamp) and write an 8-bit PNG atomically."""
    with atomic_write(path) as tmp:
        Image.fromarray(to_srgb8(rgb, exposure)).save(tmp, format="PNG")


def write_png_uint8(path, rgb8):
    """Write an already tone-mapped 8-bit image atomically."""
    with atomic_write(path) as tmp:
        Image.fromarray(np.asarray(rgb8, dtype=np.uint8)).save(tmp, format="PNG")
