"""CIEDE2000 (``harness.metrics.colour_difference``) against published and hand-derived values.

* ``delta_e_2000``, the function every CIEDE2000 value of the harness goes through,
  against the 34 test pairs of Sharma, Wu and Dalal (2005), Table 1, to their
  printed four decimals (``abs = 5e-5``). The pairs are typed from the paper's
  supplementary data (``ciede2000testdata.txt``, G. Sharma's CIEDE2000 page) as
  republished in the source corpus; cross-checked, not copied, against the same
  table in colour-science's ``colour/difference/tests/test_delta_e.py``.
* ``srgb_to_lab`` against IEC 61966-2-1 by hand: the XYZ matrix derived here from the
  sRGB primaries and the D65 white point, then the CIE 1976 L*a*b* formulas.
* ``ciede2000_mean`` on grey images, where CIEDE2000 has a closed form: for two
  neutral colours ``dE00 = |dL*| / S_L``, ``S_L = 1 + 0.015 (L - 50)^2 / sqrt(20 + (L - 50)^2)``
  at the mean lightness ``L``, and the white is the reference's 99th-percentile luminance.
"""

import numpy as np
import pytest

from harness.metrics import compute
from harness.metrics.colour_difference import delta_e_2000, srgb_to_lab

#: Sharma, Wu, Dalal (2005), Table 1: (L1, a1, b1), (L2, a2, b2), dE00.
SHARMA_2005 = [
    ((50.0000, 2.6772, -79.7751), (50.0000, 0.0000, -82.7485), 2.0425),
    ((50.0000, 3.1571, -77.2803), (50.0000, 0.0000, -82.7485), 2.8615),
    ((50.0000, 2.8361, -74.0200), (50.0000, 0.0000, -82.7485), 3.4412),
    ((50.0000, -1.3802, -84.2814), (50.0000, 0.0000, -82.7485), 1.0000),
    ((50.0000, -1.1848, -84.8006), (50.0000, 0.0000, -82.7485), 1.0000),
    ((50.0000, -0.9009, -85.5211), (50.0000, 0.0000, -82.7485), 1.0000),
    ((50.0000, 0.0000, 0.0000), (50.0000, -1.0000, 2.0000), 2.3669),
    ((50.0000, -1.0000, 2.0000), (50.0000, 0.0000, 0.0000), 2.3669),
    ((50.0000, 2.4900, -0.0010), (50.0000, -2.4900, 0.0009), 7.1792),
    ((50.0000, 2.4900, -0.0010), (50.0000, -2.4900, 0.0010), 7.1792),
    ((50.0000, 2.4900, -0.0010), (50.0000, -2.4900, 0.0011), 7.2195),
    ((50.0000, 2.4900, -0.0010), (50.0000, -2.4900, 0.0012), 7.2195),
    ((50.0000, -0.0010, 2.4900), (50.0000, 0.0009, -2.4900), 4.8045),
    ((50.0000, -0.0010, 2.4900), (50.0000, 0.0010, -2.4900), 4.8045),
    ((50.0000, -0.0010, 2.4900), (50.0000, 0.0011, -2.4900), 4.7461),
    ((50.0000, 2.5000, 0.0000), (50.0000, 0.0000, -2.5000), 4.3065),
    ((50.0000, 2.5000, 0.0000), (73.0000, 25.0000, -18.0000), 27.1492),
    ((50.0000, 2.5000, 0.0000), (61.0000, -5.0000, 29.0000), 22.8977),
    ((50.0000, 2.5000, 0.0000), (56.0000, -27.0000, -3.0000), 31.9030),
    ((50.0000, 2.5000, 0.0000), (58.0000, 24.0000, 15.0000), 19.4535),
    ((50.0000, 2.5000, 0.0000), (50.0000, 3.1736, 0.5854), 1.0000),
    ((50.0000, 2.5000, 0.0000), (50.0000, 3.2972, 0.0000), 1.0000),
    ((50.0000, 2.5000, 0.0000), (50.0000, 1.8634, 0.5757), 1.0000),
    ((50.0000, 2.5000, 0.0000), (50.0000, 3.2592, 0.3350), 1.0000),
    ((60.2574, -34.0099, 36.2677), (60.4626, -34.1751, 39.4387), 1.2644),
    ((63.0109, -31.0961, -5.8663), (62.8187, -29.7946, -4.0864), 1.2630),
    ((61.2901, 3.7196, -5.3901), (61.4292, 2.2480, -4.9620), 1.8731),
    ((35.0831, -44.1164, 3.7933), (35.0232, -40.0716, 1.5901), 1.8645),
    ((22.7233, 20.0904, -46.6940), (23.0331, 14.9730, -42.5619), 2.0373),
    ((36.4612, 47.8580, 18.3852), (36.2715, 50.5065, 21.2231), 1.4146),
    ((90.8027, -2.0831, 1.4410), (91.1528, -1.6435, 0.0447), 1.4441),
    ((90.9257, -0.5406, -0.9208), (88.6381, -0.8985, -0.7239), 1.5381),
    ((6.7747, -0.2908, -2.4247), (5.8714, -0.0985, -2.2286), 0.6377),
    ((2.0776, 0.0795, -1.1350), (0.9033, -0.0636, -0.5514), 0.9082),
]


class TestSharma2005:
    def test_all_34_pairs_to_four_decimals(self):
        assert len(SHARMA_2005) == 34
        lab1 = np.array([p[0] for p in SHARMA_2005])
        lab2 = np.array([p[1] for p in SHARMA_2005])
        want = np.array([p[2] for p in SHARMA_2005])
        got = delta_e_2000(lab1, lab2)
        worst = int(np.argmax(np.abs(got - want)))
        assert np.abs(got - want).max() <= 5e-5, (f"pair {worst + 1}: dE00 {got[worst]:.5f}, "
                                                  f"published {want[worst]:.4f}")

    def test_symmetric(self):
        lab1 = np.array([p[0] for p in SHARMA_2005])
        lab2 = np.array([p[1] for p in SHARMA_2005])
        np.testing.assert_allclose(delta_e_2000(lab1, lab2), delta_e_2000(lab2, lab1), atol=1e-12)


# --------------------------------------------------------------- sRGB -> XYZ -> Lab by hand

def srgb_matrix():
    """IEC 61966-2-1: the RGB -> XYZ matrix from the primaries' and D65's chromaticities."""
    xy = np.array([[0.64, 0.33], [0.30, 0.60], [0.15, 0.06]])          # R, G, B
    white_xy = np.array([0.3127, 0.3290])                              # D65
    prim = np.stack([xy[:, 0] / xy[:, 1], np.ones(3), (1 - xy.sum(axis=1)) / xy[:, 1]])   # columns: XYZ at Y=1
    white = np.array([white_xy[0] / white_xy[1], 1.0, (1 - white_xy.sum()) / white_xy[1]])
    return prim * np.linalg.solve(prim, white)[None, :], white


#: IEC 61966-2-1's RGB -> XYZ matrix as the standard prints it (four decimals; colour-science uses it as printed)
IEC_MATRIX = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])


def lab_by_hand(rgb):
    m, white = IEC_MATRIX, srgb_matrix()[1]
    t = (rgb @ m.T) / white
    eps = (6 / 29) ** 3
    f = np.where(t > eps, np.cbrt(t), t / (3 * (6 / 29) ** 2) + 4 / 29)
    return np.stack([116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]), 200 * (f[..., 1] - f[..., 2])], axis=-1)


class TestSrgbToLab:
    def test_printed_matrix_is_the_derived_one(self):
        # the printed matrix is the one derived from the primaries and D65, to its four decimals
        np.testing.assert_allclose(srgb_matrix()[0], IEC_MATRIX, atol=6e-5)

    def test_against_hand_conversion(self):
        rgb = np.array([[1.0, 1.0, 1.0], [0.5, 0.5, 0.5], [0.002, 0.002, 0.002], [1.0, 0.0, 0.0],
                        [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.8, 0.35, 0.1], [0.05, 0.3, 0.6]])
        err = np.abs(srgb_to_lab(rgb) - lab_by_hand(rgb)).max(axis=1)
        assert err.max() <= 1e-9, (f"srgb_to_lab of {rgb[np.argmax(err)].tolist()} is off the hand conversion by "
                                   f"{err.max():.3g} in L*a*b*")
        # white is L* = 100 up to the printed matrix's rounding (its rows sum to D65 within 1e-4)
        np.testing.assert_allclose(srgb_to_lab(np.ones(3)), [100.0, 0.0, 0.0], atol=1e-2)


# --------------------------------------------------------------- the metric on grey images

#: The printed matrix leaves a grey a tiny chroma (a* ~ 4e-4), which moves dE00 by ~3e-7 from the
#: neutral closed form; an XYZ scaled by 1.03 moves it by ~1, CIE 1994 in place of CIEDE2000 by ~5.
NEUTRAL_ABS = 1e-5


def neutral_de00(l1, l2):
    lbar = 0.5 * (l1 + l2)
    s_l = 1 + 0.015 * (lbar - 50) ** 2 / np.sqrt(20 + (lbar - 50) ** 2)
    return np.abs(l1 - l2) / s_l


def lightness(y):
    eps = (6 / 29) ** 3
    return 116 * np.where(y > eps, np.cbrt(y), y / (3 * (6 / 29) ** 2) + 4 / 29) - 16


class TestMetricOnGrey:
    @pytest.mark.parametrize("ratio", [0.25, 0.8, 1.1])
    def test_grey_scaled(self, ratio):
        # reference grey 3.0 everywhere: the white is 3.0, so the reference is L* = 100; the test
        # is ratio * 3.0, clamped to the white, L* = lightness(min(ratio, 1))
        ref = np.full((8, 8, 3), 3.0)
        r = compute("ciede2000_mean", ratio * ref, ref)
        want = neutral_de00(lightness(min(ratio, 1.0)), 100.0)
        assert r.params["white"] == pytest.approx(3.0, rel=1e-12)
        assert r.value == pytest.approx(want, abs=NEUTRAL_ABS), f"ratio {ratio}: {r.value} vs closed form {want}"

    def test_two_greys_and_the_percentile_white(self):
        # 90 % of the reference at 1.0 and 10 % at 2.0: the 99th percentile is 2.0
        ref = np.ones((10, 10, 3))
        ref[:1] = 2.0
        test = ref * 0.5
        r = compute("ciede2000_mean", test, ref)
        want = 0.9 * neutral_de00(lightness(0.25), lightness(0.5)) + 0.1 * neutral_de00(lightness(0.5), 100.0)
        assert r.params["white"] == pytest.approx(2.0, rel=1e-12)
        assert r.value == pytest.approx(want, abs=NEUTRAL_ABS)
        # 90 of the 100 values are the first (and larger) one, so it is the 95th percentile
        p95 = compute("ciede2000_p95", test, ref)
        assert neutral_de00(lightness(0.25), lightness(0.5)) > neutral_de00(lightness(0.5), 100.0)
        assert p95.value == pytest.approx(neutral_de00(lightness(0.25), lightness(0.5)), abs=NEUTRAL_ABS)
