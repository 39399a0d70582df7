"""The two steps of a verdict (``harness.regression.verdict``): changed at all, then paired
and variance-propagated better/worse with a Bonferroni correction."""

import math

import numpy as np
import pytest

from harness.metrics.uncertainty import PairedDifference
from harness.regression.verdict import (IMAGE_RTOL, badness, critical_value, image_change, judge, judge_images,
                                        overall)


class TestImageChange:
    def images(self):
        rng = np.random.default_rng(0)
        old = rng.uniform(0.1, 1.0, (16, 16, 3)).astype(np.float32)
        mask = np.ones((16, 16), bool)
        mask[:2] = False
        return old, mask

    def test_equal_and_within_tolerance_are_unchanged(self):
        old, mask = self.images()
        assert not image_change(old, old, mask, mask).changed
        near = old * (1 + 0.5 * IMAGE_RTOL)
        res = image_change(near, old, mask, mask)
        assert not res.changed and res.worst <= 1.0 and "unchanged" in res.line()

    def test_one_pixel_beyond_tolerance_is_a_change(self):
        old, mask = self.images()
        new = old.copy()
        new[8, 8, 1] *= 1 + 3 * IMAGE_RTOL
        res = image_change(new, old, mask, mask)
        assert res.changed and res.beyond == 1 and res.mask_flips == 0

    def test_outside_the_mask_does_not_count_but_coverage_does(self):
        old, mask = self.images()
        new = old.copy()
        new[0, 0] = 100.0                                  # not covered in either image
        assert not image_change(new, old, mask, mask).changed
        flipped = mask.copy()
        flipped[0, 0] = True
        res = image_change(new, old, flipped, mask)
        assert res.changed and res.mask_flips == 1

    def test_near_black_pixels_use_the_absolute_part(self):
        old, mask = self.images()
        old[5, 5] = 0.0
        new = old.copy()
        new[5, 5] = 1e-8                                   # << 1e-6 x max
        assert not image_change(new, old, mask, mask).changed


def _diff(delta, se, old=0.2, dof=math.inf, metric="relmse"):
    return PairedDifference(metric, old, old + delta, delta, se, dof, "delta")


class TestJudge:
    TOL = {"rel": 0.05, "abs": 1e-4}

    def test_critical_value_is_bonferroni(self):
        from scipy import stats

        assert critical_value(1, 0.05) == pytest.approx(stats.norm.ppf(0.975))
        assert critical_value(288, 0.01) == pytest.approx(stats.norm.ppf(1 - 0.01 / 576))
        assert critical_value(288, 0.01, dof=7) > critical_value(288, 0.01)

    def test_threshold_is_tolerance_plus_t_se(self):
        c = judge("s", "c", "subsurface", _diff(0.02, 0.001), self.TOL, family=100)
        t = critical_value(100)
        assert c.tolerance == pytest.approx(0.01) and c.threshold == pytest.approx(0.01 + t * 0.001)
        assert c.z == pytest.approx(20.0) and c.verdict == "regression" and c.critical == pytest.approx(t)

    def test_significant_but_within_tolerance_is_within_noise(self):
        c = judge("s", "c", "subsurface", _diff(0.009, 1e-6), self.TOL, family=100)
        assert c.z > 1000 and c.verdict == "changed-within-noise"

    def test_beyond_tolerance_but_noisy_is_within_noise(self):
        c = judge("s", "c", "subsurface", _diff(0.02, 0.005), self.TOL, family=100)
        assert c.verdict == "changed-within-noise"

    def test_improvement_and_energy_ratio_direction(self):
        assert judge("s", "c", "sub", _diff(-0.05, 0.001), self.TOL).verdict == "improvement"
        # energy ratio 0.8 -> 1.15: badness 0.2 -> 0.15, better
        d = PairedDifference("energy_ratio", 0.8, 1.15, badness("energy_ratio", 1.15) - 0.2, 0.001, math.inf,
                             "delta")
        assert judge("s", "c", "sub", d, {"rel": 0.0, "abs": 0.01}).verdict == "improvement"

    def test_overall(self):
        reg = judge("s", "c", "sub", _diff(0.05, 0.001), self.TOL)
        imp = judge("s", "c", "sub", _diff(-0.05, 0.001), self.TOL)
        noise = judge("s", "c", "sub", _diff(0.0, 0.001), self.TOL)
        assert overall([noise, imp, reg]) == "regression" and overall([noise, imp]) == "improvement"
        assert overall([noise]) == "changed-within-noise" and overall([]) == "unchanged"
        assert overall([], image_changed=True) == "changed-within-noise"
        assert "Delta" in reg.line() and "SE" in reg.line() and "z" in reg.line() and "threshold" in reg.line()
        assert reg.as_dict()["verdict"] == "regression"


def test_judge_images_catches_a_darker_image_and_calls_the_same_image_within_noise():
    rng = np.random.default_rng(4)
    truth = rng.uniform(0.2, 1.0, (24, 24, 1)) * np.ones((1, 1, 3))
    se = 0.02 * truth
    ref = truth + se * rng.standard_normal((24, 24, 1))
    mask = np.ones((24, 24), bool)
    old = truth * 1.02
    worse = judge_images("s", "c", "subsurface", truth * 0.7, old, ref, se, mask, {"rel": 0.03, "abs": 1e-4},
                         family=8, k=8)
    assert {c.metric for c in worse} == {"relmse", "si_relmse", "energy_ratio", "flip"}
    assert overall(worse) == "regression"
    same = judge_images("s", "c", "subsurface", old * (1 + 1e-4), old, ref, se, mask, {"rel": 0.03, "abs": 1e-4},
                        family=8, k=8)
    assert overall(same) == "changed-within-noise"


class TestWithinTolerance:
    """A resampled standard error (FLIP: 2 x draws evaluations of the metric) is skipped where no
    standard error could change the verdict, |Delta| <= tol; elsewhere it is estimated as before."""

    @staticmethod
    def _pair(scale, seed=5):
        rng = np.random.default_rng(seed)
        truth = rng.uniform(0.2, 1.0, (20, 20, 1)) * np.ones((1, 1, 3))
        se = 0.02 * truth
        ref = truth + se * rng.standard_normal((20, 20, 1))
        return truth * scale, truth * 1.02, ref, se, np.ones((20, 20), bool)

    def test_the_same_verdicts_with_and_without_the_shortcut(self, monkeypatch):
        from harness.metrics import uncertainty

        tol = {"rel": 0.05, "abs": 1e-4}
        real = uncertainty.paired_difference
        skipped = 0
        for scale in (1.02 * (1 + 1e-4), 1.0, 1.03, 0.97, 0.9, 0.7, 1.2):
            new, old, ref, se, mask = self._pair(scale)
            with_short = judge_images("s", "c", "subsurface", new, old, ref, se, mask, tol, family=8, k=8,
                                      metrics=("flip",))[0]
            monkeypatch.setattr(uncertainty, "paired_difference",
                                lambda *a, decided_within=None, **kw: real(*a, **kw))
            without = judge_images("s", "c", "subsurface", new, old, ref, se, mask, tol, family=8, k=8,
                                   metrics=("flip",))[0]
            monkeypatch.setattr(uncertainty, "paired_difference", real)
            assert with_short.verdict == without.verdict and with_short.delta == without.delta, scale
            assert without.method == "resampling" and math.isfinite(without.se)
            if with_short.method == "within-tolerance":
                skipped += 1
                assert abs(with_short.delta) <= with_short.tolerance and math.isnan(with_short.se)
                assert with_short.verdict == "changed-within-noise"
                assert with_short.as_dict()["se"] is None and "no SE needed" in with_short.line()
            else:
                assert with_short.se == without.se
        assert 0 < skipped < 7                      # both branches were taken

    def test_resampling_is_skipped_only_within_the_tolerance(self):
        from harness.metrics.uncertainty import paired_difference

        new, old, ref, se, mask = self._pair(1.0)
        d = paired_difference("flip", new, old, ref, se, mask, k=8, decided_within=lambda v: 1e9)
        assert d.method == "within-tolerance" and math.isnan(d.se)
        d = paired_difference("flip", new, old, ref, se, mask, k=8, decided_within=0.0)
        assert d.method == "resampling" and d.se > 0
        with pytest.raises(ValueError, match="beyond the tolerance"):
            judge("s", "c", "subsurface", PairedDifference("flip", 0.1, 0.5, 0.4, math.nan, math.nan,
                                                           "within-tolerance", {}))
