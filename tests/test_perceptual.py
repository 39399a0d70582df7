"""The SSIM wrapper (``harness.metrics.perceptual.ssim``) against values derived by hand.

The wrapper fixes an exposure ``k = 1 / mean Y_ref`` over the mask, tone-maps
``t(v) = k v / (1 + k v)``, and hands scikit-image ``data_range = 1`` (so
``C1 = (0.01)^2``, ``C2 = (0.03)^2``), a Gaussian window (sigma 1.5, radius 5) and
population covariances; the map is pooled over the mask without the 5-pixel
border. Two cases have closed forms:

* **Constant images** (grey ``v`` and ``c v``): every window sees one value, the
  variances vanish and ``SSIM = (2 t_x t_y + C1) / (t_x^2 + t_y^2 + C1)`` with
  ``t_y = 1/2`` (the reference maps to its own mean) and ``t_x = c / (1 + c)``.
  It fixes the exposure, the tone curve and ``C1`` (hence ``data_range``).
* **A one-pixel checkerboard** of two greys in both images: the tone-mapped test is
  an affine function ``t_x = a t_y + b`` of the tone-mapped reference (two points
  fix a line), so ``mu_x = a mu_y + b``, ``var_x = a^2 var_y``, ``cov = a var_y``.
  With the window's alternating sum ``s = sum_i w_i (-1)^i`` (11 normalised Gaussian
  weights), a window centred on a pixel of sign ``p = +-1`` has
  ``mu_y = m + p d s^2`` and ``var_y = d^2 (1 - s^4)`` for the checkerboard
  ``m +- d``. The contrast-structure term ``(2 a var_y + C2) / ((1 + a^2) var_y + C2)``
  fixes ``C2`` and the covariance normalisation (``var_y`` is of the order of C2).

Tolerance ``1e-12``: both are exact up to float64 rounding.
"""

import numpy as np
import pytest

from harness.metrics import compute

C1, C2 = 0.01 ** 2, 0.03 ** 2


def ssim_constant(c):
    tx, ty = c / (1.0 + c), 0.5
    return (2 * tx * ty + C1) / (tx * tx + ty * ty + C1)


class TestConstantImages:
    @pytest.mark.parametrize("c", [0.0, 0.5, 2.0, 7.0])
    def test_scaled_grey(self, c):
        ref = np.full((24, 20, 3), 3.7)
        r = compute("ssim", c * ref, ref)
        assert r.params["exposure"] == pytest.approx(1 / 3.7, rel=1e-14)
        assert r.value == pytest.approx(ssim_constant(c), abs=1e-12), f"c = {c}"
        assert r.per_channel == pytest.approx((ssim_constant(c),) * 3, abs=1e-12)

    def test_exposure_from_the_mask_only(self):
        ref = np.full((24, 24, 3), 2.0)
        mask = np.zeros((24, 24), bool)
        mask[6:18, 6:18] = True
        ref_outside = np.where(mask[..., None], ref, 50.0)          # must not change the exposure
        r = compute("ssim", 0.5 * ref_outside, ref_outside, mask)
        assert r.params["exposure"] == pytest.approx(0.5, rel=1e-14)


def window_alternating_sum(sigma=1.5, radius=5):
    x = np.arange(-radius, radius + 1)
    w = np.exp(-0.5 * x * x / sigma ** 2)
    w /= w.sum()
    return float(np.sum(w * (-1.0) ** x))


def checkerboard(h, w, low, high):
    parity = (np.add.outer(np.arange(h), np.arange(w)) % 2).astype(bool)        # True: "high" pixels
    return np.repeat(np.where(parity, high, low)[..., None], 3, axis=-1), parity


class TestCheckerboard:
    @pytest.mark.parametrize("test_levels", [(0.5, 1.6), (1.3, 0.7), (0.9, 1.05)])
    def test_affine_tone_mapped_pair(self, test_levels):
        H, W = 26, 30
        ref, parity = checkerboard(H, W, 0.8, 1.2)                 # mean luminance 1: k = 1
        test, _ = checkerboard(H, W, *test_levels)
        r = compute("ssim", test, ref)
        k = 1.0 / ref[..., 1].mean()
        assert r.params["exposure"] == pytest.approx(k, rel=1e-14)

        def t(v):
            return k * v / (1 + k * v)

        ty_lo, ty_hi = t(0.8), t(1.2)
        tx_lo, tx_hi = t(test_levels[0]), t(test_levels[1])
        a = (tx_hi - tx_lo) / (ty_hi - ty_lo)
        b = tx_lo - a * ty_lo
        m, d = 0.5 * (ty_hi + ty_lo), 0.5 * (ty_hi - ty_lo)         # t_y = m + d on "high" pixels
        s2 = window_alternating_sum() ** 2                           # separable window: s^2 in 2D
        sign = np.where(parity, 1.0, -1.0)                           # +1 on "high" pixels
        mu_y = m + sign * d * s2
        var_y = d * d * (1.0 - s2 * s2)
        mu_x = a * mu_y + b
        per_pixel = ((2 * mu_x * mu_y + C1) * (2 * a * var_y + C2)
                     / ((mu_x ** 2 + mu_y ** 2 + C1) * ((1 + a * a) * var_y + C2)))
        want = per_pixel[5:-5, 5:-5].mean()
        assert var_y / C2 == pytest.approx(d * d / C2, rel=1e-3) and 0.5 < d * d / C2 < 5
        assert r.value == pytest.approx(want, abs=1e-12), f"{test_levels}: {r.value} vs closed form {want}"
