"""Tests for harness.metrics and harness.cli.compare, on small hand-checked images."""

import json

import numpy as np
import pytest

from harness.cli.compare import format_table, run_compare
from harness.errors import InputError
from harness.io.images import write_exr
from harness.metrics import (METRICS, MetricResult, compare_images, compute, compute_all,
                             noise_floor)

ZERO_WHEN_IDENTICAL = ("rmse", "relmse", "mae", "smape", "si_relmse", "flip",
                       "ciede2000_mean", "ciede2000_p95")
ONE_WHEN_IDENTICAL = ("ssim", "energy_ratio")


@pytest.fixture(scope="module")
def ref():
    """A smooth, strictly positive 64x64 HDR image with some values above 1."""
    rng = np.random.default_rng(7)
    yy, xx = np.mgrid[0:64, 0:64] / 63.0
    base = np.stack([0.2 + 2.0 * xx, 0.1 + 1.5 * yy, 0.3 + xx * yy], axis=-1)
    return (base * (1.0 + 0.2 * rng.random((64, 64, 3)))).astype(np.float32)


@pytest.fixture(scope="module")
def mask():
    m = np.zeros((64, 64), bool)
    m[16:48, 12:52] = True
    return m


class TestRegistry:
    def test_names(self):
        assert list(METRICS) == ["rmse", "relmse", "mae", "smape", "energy_ratio", "si_relmse",
                                 "ssim", "flip", "ciede2000_mean", "ciede2000_p95"]

    def test_unknown_name_lists_known(self, ref):
        with pytest.raises(ValueError, match=r"unknown metric 'psnr'.*rmse, relmse.*ciede2000_p95"):
            compute("psnr", ref, ref)
        with pytest.raises(ValueError, match="unknown metric 'psnr'"):
            compute_all(ref, ref, names=["rmse", "psnr"])

    def test_shape_mismatch_names_both(self, ref):
        with pytest.raises(ValueError, match=r"test \(32, 64, 3\), ref \(64, 64, 3\)"):
            compute("rmse", ref[:32], ref)

    def test_not_rgb(self, ref):
        with pytest.raises(ValueError, match=r"\(H, W, 3\)"):
            compute("rmse", ref[..., 0], ref[..., 0])

    def test_non_finite(self, ref):
        bad = ref.copy()
        bad[3, 4, 1] = np.nan
        with pytest.raises(ValueError, match="test: contains 1 NaN"):
            compute("mae", bad, ref)

    def test_bad_mask(self, ref, mask):
        with pytest.raises(ValueError, match="mask: shape"):
            compute("rmse", ref, ref, mask[:10])
        with pytest.raises(ValueError, match="selects no pixels"):
            compute("rmse", ref, ref, np.zeros_like(mask))

    def test_unknown_param(self, ref):
        with pytest.raises(ValueError, match="relmse: unknown parameter.*accepted: eps"):
            compute("relmse", ref, ref, epsilon=0.1)

    def test_params_are_used(self, ref):
        r = compute("relmse", 2 * ref, ref, eps=0.5)
        assert r.params == {"eps": 0.5}

    def test_result_type(self, ref):
        for name, r in compute_all(ref, ref).items():
            assert isinstance(r, MetricResult) and r.name == name
            assert isinstance(r.value, float)
            json.dumps(r.params)  # parameters are plain JSON types
            if r.error_map is not None:
                assert r.error_map.shape == (64, 64) and r.error_map.dtype == np.float32


class TestIdentical:
    @pytest.mark.parametrize("name", ZERO_WHEN_IDENTICAL)
    def test_zero(self, ref, name):
        assert compute(name, ref, ref).value == pytest.approx(0.0, abs=1e-12)

    @pytest.mark.parametrize("name", ONE_WHEN_IDENTICAL)
    def test_one(self, ref, name):
        assert compute(name, ref, ref).value == pytest.approx(1.0, abs=1e-12)


class TestPixelMetrics:
    def test_rmse_constant_offset(self, ref):
        r = compute("rmse", ref + np.float32(0.25), ref)
        assert r.value == pytest.approx(0.25, rel=1e-6)
        assert r.per_channel == pytest.approx((0.25,) * 3, rel=1e-6)

    def test_mae_constant_offset(self, ref):
        assert compute("mae", ref - np.float32(0.125), ref).value == pytest.approx(0.125, rel=1e-6)

    def test_relmse_of_double(self, ref):
        # (2y - y)^2 / (y^2 + eps) = y^2 / (y^2 + eps), averaged by hand.
        y = ref.astype(np.float64)
        expected = np.mean(y ** 2 / (y ** 2 + 1e-2))
        r = compute("relmse", 2 * ref, ref)
        assert r.params["eps"] == 1e-2
        assert r.value == pytest.approx(expected, rel=1e-10)
        assert r.per_channel[1] == pytest.approx(np.mean(y[..., 1] ** 2 / (y[..., 1] ** 2 + 1e-2)),
                                                 rel=1e-10)

    def test_smape_hand(self):
        y = np.ones((4, 4, 3))
        # 2|3 - 1| / (3 + 1 + 0.01)
        assert compute("smape", 3 * y, y).value == pytest.approx(4 / 4.01, rel=1e-12)

    def test_energy_ratio_of_double(self, ref):
        r = compute("energy_ratio", 2 * ref, ref)
        assert r.value == pytest.approx(2.0, rel=1e-9)
        assert r.per_channel == pytest.approx((2.0, 2.0, 2.0), rel=1e-9)
        assert r.target == 1.0 and r.error_map is None

    def test_energy_ratio_black_reference(self, ref):
        black = ref.copy()
        black[..., 2] = 0
        with pytest.raises(ValueError, match="B channel sums to 0"):
            compute("energy_ratio", ref, black)

    def test_si_relmse_of_double(self, ref):
        r = compute("si_relmse", 2 * ref, ref)
        assert r.value == pytest.approx(0.0, abs=1e-12)
        assert r.params["scales"] == pytest.approx((0.5, 0.5, 0.5), rel=1e-9)

    def test_si_relmse_is_least_squares(self, ref):
        # The closed-form scale beats nearby scales.
        rng = np.random.default_rng(3)
        test = ref * (1.3 + 0.1 * rng.standard_normal(ref.shape))
        r = compute("si_relmse", test, ref)
        for ds in (-1e-3, 1e-3):
            worse = compute("relmse", test * (np.array(r.params["scales"]) + ds), ref)
            assert worse.value > r.value


class TestMask:
    @pytest.mark.parametrize("name", list(METRICS))
    def test_garbage_outside_mask_is_ignored(self, ref, mask, name):
        rng = np.random.default_rng(11)
        garbage = ref.copy()
        garbage[~mask] = rng.random((int((~mask).sum()), 3)) * 1e3
        noisy = ref * np.float32(1.1)
        clean = compute(name, noisy, ref, mask)
        polluted = compute(name, np.where(mask[..., None], noisy, garbage), ref, mask)
        assert polluted.value == pytest.approx(clean.value, abs=1e-12)

    @pytest.mark.parametrize("name", [n for n in METRICS if n not in ("ssim", "flip")])
    def test_garbage_in_reference_outside_mask_is_ignored(self, ref, mask, name):
        # Per-pixel metrics see no context; SSIM and FLIP filter across the
        # mask's edge and so do see the reference there (documented).
        garbage_ref = np.where(mask[..., None], ref, np.float32(1e3))
        clean = compute(name, ref * np.float32(1.1), ref, mask)
        polluted = compute(name, ref * np.float32(1.1), garbage_ref, mask)
        assert polluted.value == pytest.approx(clean.value, rel=1e-12, abs=1e-12)

    def test_mask_selects_pixels(self, ref, mask):
        test = ref.copy()
        test[~mask] += 5.0
        assert compute("rmse", test, ref, mask).value == 0.0
        assert compute("rmse", test, ref).value > 1.0
        assert np.all(compute("rmse", test, ref, mask).error_map[~mask] == 0)

    def test_integer_mask_accepted(self, ref, mask):
        assert compute("mae", ref + 1, ref, mask.astype(np.uint8)).value == pytest.approx(1.0)


class TestPerceptual:
    def test_ssim_drops_with_noise(self, ref):
        rng = np.random.default_rng(5)
        noisy = ref * (1 + 0.3 * rng.standard_normal(ref.shape))
        r = compute("ssim", noisy, ref)
        assert 0.0 < r.value < 0.95
        assert r.higher_is_better and r.params["data_range"] == 1.0

    def test_flip_records_its_parameters(self, ref):
        r = compute("flip", ref * 1.5, ref)
        assert 0.0 < r.value < 1.0
        for k in ("ppd", "startExposure", "stopExposure", "numExposures", "tonemapper"):
            assert k in r.params
        assert r.params["startExposure"] <= r.params["stopExposure"]

    def test_flip_matches_flip_default_without_mask(self, ref):
        import flip_evaluator
        _, mean, used = flip_evaluator.evaluate(ref, ref * 1.5, "HDR", applyMagma=False)
        r = compute("flip", ref * 1.5, ref)
        assert r.value == pytest.approx(mean, rel=1e-4)
        assert r.params["stopExposure"] == pytest.approx(used["stopExposure"], abs=1e-5)

    def test_flip_bad_tonemapper_raises_not_exits(self, ref):
        with pytest.raises(ValueError, match="unknown tonemapper"):
            compute("flip", ref, ref, tonemapper="filmic")

    def test_ciede_white_from_reference(self, ref):
        r = compute("ciede2000_mean", ref, ref)
        y = ref.astype(np.float64) @ np.array([0.2126, 0.7152, 0.0722])
        assert r.params["white"] == pytest.approx(np.percentile(y, 99), rel=1e-9)
        p95 = compute("ciede2000_p95", ref * 0.8, ref)
        assert p95.value >= compute("ciede2000_mean", ref * 0.8, ref).value > 0


class TestNoiseFloor:
    def test_identical_halves(self, ref):
        floors = noise_floor(ref, ref)
        assert set(floors) == set(METRICS)
        for name in ZERO_WHEN_IDENTICAL:
            assert floors[name].value == pytest.approx(0.0, abs=1e-12)
        for name in ONE_WHEN_IDENTICAL:
            assert floors[name].value == pytest.approx(1.0, abs=1e-12)

    def test_compare_images_rows(self, ref, mask):
        rows = compare_images(ref + 0.1, ref, mask, half_a=ref * 1.01, half_b=ref,
                              names=["rmse", "mae"])
        assert [r["metric"] for r in rows] == ["rmse", "mae"]
        assert rows[0]["value"] == pytest.approx(0.1, rel=1e-6)
        expected_floor = np.sqrt(np.mean((0.01 * ref.astype(np.float64)[mask]) ** 2))
        assert rows[0]["noise_floor"] == pytest.approx(expected_floor, rel=1e-5)
        assert set(rows[0]) == {"metric", "value", "per_channel", "noise_floor", "params",
                                "higher_is_better", "target"}

    def test_compare_images_without_halves(self, ref):
        assert all(r["noise_floor"] is None for r in compare_images(ref, ref, names=["rmse"]))

    def test_one_half_only(self, ref):
        with pytest.raises(ValueError, match="both half_a and half_b"):
            compare_images(ref, ref, half_a=ref)


class TestRunCompare:
    def test_two_exrs(self, tmp_path, ref):
        write_exr(tmp_path / "ref.exr", ref)
        write_exr(tmp_path / "test.exr", ref + np.float32(0.5))
        out = run_compare(tmp_path / "ref.exr", tmp_path / "test.exr", as_json=True)
        assert out["ref"].endswith("ref.exr") and out["test"].endswith("test.exr")
        assert set(out["metrics"]) == set(METRICS)
        assert out["metrics"]["rmse"]["value"] == pytest.approx(0.5, rel=1e-6)
        assert out["noise_floor_from"] is None
        json.dumps(out, allow_nan=False)
        assert "rmse" in format_table(out)

    def test_noise_floor_from_halves(self, tmp_path, ref):
        write_exr(tmp_path / "subsurface.exr", ref)
        write_exr(tmp_path / "half_a.exr", ref * np.float32(1.02))
        write_exr(tmp_path / "half_b.exr", ref)
        write_exr(tmp_path / "test.exr", ref)
        out = run_compare(tmp_path / "subsurface.exr", tmp_path / "test.exr")
        assert out["metrics"]["energy_ratio"]["noise_floor"] == pytest.approx(1.02, rel=1e-6)

    def test_mask_file(self, tmp_path, ref, mask):
        test = ref.copy()
        test[~mask] = 100.0
        write_exr(tmp_path / "ref.exr", ref)
        write_exr(tmp_path / "test.exr", test)
        np.save(tmp_path / "mask.npy", mask)
        out = run_compare(tmp_path / "ref.exr", tmp_path / "test.exr", tmp_path / "mask.npy")
        assert out["metrics"]["mae"]["value"] == 0.0

    def test_nan_exr_names_file(self, tmp_path, ref):
        bad = ref.copy()
        bad[0, 0, 0] = np.nan
        write_exr(tmp_path / "ref.exr", ref)
        write_exr(tmp_path / "nan_test.exr", bad)
        with pytest.raises(InputError, match="nan_test.exr"):
            run_compare(tmp_path / "ref.exr", tmp_path / "nan_test.exr")

    def test_size_mismatch_names_both(self, tmp_path, ref):
        write_exr(tmp_path / "ref.exr", ref)
        write_exr(tmp_path / "small.exr", ref[:32])
        with pytest.raises(InputError, match=r"small\.exr: size: is 64x32 but the reference .*ref\.exr is 64x64"):
            run_compare(tmp_path / "ref.exr", tmp_path / "small.exr")

    def test_missing_file(self, tmp_path, ref):
        write_exr(tmp_path / "ref.exr", ref)
        with pytest.raises(InputError, match="missing.exr: file: does not exist"):
            run_compare(tmp_path / "ref.exr", tmp_path / "missing.exr")
