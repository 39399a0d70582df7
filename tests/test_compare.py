"""``sslpv-harness compare``: which pixels it compares, and that a render compared from the
command line gives the numbers a sweep records for the same configuration.

* the mask rule (``--mask`` file, the reference's fully covered pixels, every pixel) on
  synthetic EXRs, and that the output names the rule and the pixel count;
* ``render --size small`` then ``compare`` against the committed reference equals a
  one-scene ``sweep --size small`` of the same parameters (relMSE and energy ratio of the
  subsurface image, to 1e-9 relative). All pixels would not: the sweep compares only
  fully covered ones (``harness.metrics.coverage``).
"""

import json

import numpy as np
import pytest

from harness.cli import main
from harness.cli.compare import format_table, run_compare
from harness.errors import InputError
from harness.io.images import write_exr
from harness.metrics.coverage import FULL_COVERAGE
from harness.reference.committed import REF_DIR
from harness.store import Store

RTOL = 1e-9              # the same images and the same mask give the same float64 sums


@pytest.fixture
def pair(tmp_path):
    """A reference folder (``subsurface.exr`` and its coverage ``mask.exr``) and a test image
    that differs from it only outside the fully covered pixels."""
    rng = np.random.default_rng(3)
    ref = rng.uniform(0.1, 1.0, (20, 24, 3)).astype(np.float32)    # SSIM's window needs 11 x 11
    coverage = np.zeros((20, 24), np.float32)
    coverage[6:14, 6:16] = 1.0                 # 80 fully covered pixels
    coverage[5, 6:16] = 0.5                    # a silhouette row of 10: compared by no sweep
    test = ref.copy()
    test[coverage < FULL_COVERAGE] += 1.0
    folder = tmp_path / "ref"
    folder.mkdir()
    write_exr(folder / "subsurface.exr", ref)
    write_exr(folder / "mask.exr", np.repeat(coverage[..., None], 3, axis=2))
    write_exr(tmp_path / "test.exr", test)
    return folder / "subsurface.exr", tmp_path / "test.exr", coverage


class TestMaskRule:
    def test_reference_coverage_beside_it_gives_the_fully_covered_pixels(self, pair):
        ref, test, _ = pair
        out = run_compare(ref, test, as_json=True)
        assert out["mask_rule"] == "full_coverage" and out["mask"] == str(ref.with_name("mask.exr"))
        assert out["mask_pixels"] == 80 and out["pixels"] == 480 and out["mask_threshold"] == FULL_COVERAGE
        assert out["metrics"]["mae"]["value"] == 0.0
        text = format_table(out)
        assert "80 of 480 pixels" in text and "mask.exr" in text

    def test_all_pixels_opts_out(self, pair):
        ref, test, _ = pair
        out = run_compare(ref, test, all_pixels=True)
        assert out["mask_rule"] == "all_pixels" and out["mask"] is None and out["mask_pixels"] == 480
        assert out["metrics"]["mae"]["value"] == pytest.approx(400 / 480, rel=1e-6)
        assert "all 480 pixels (--all-pixels)" in format_table(out)

    def test_an_explicit_mask_wins(self, pair, tmp_path):
        ref, test, coverage = pair
        mine = coverage > 0                        # the silhouette row too
        np.save(tmp_path / "m.npy", mine)
        out = run_compare(ref, test, tmp_path / "m.npy")
        assert out["mask_rule"] == "file" and out["mask"] == str(tmp_path / "m.npy") and out["mask_pixels"] == 90
        assert out["metrics"]["mae"]["value"] == pytest.approx(10 / 90, rel=1e-6)
        with pytest.raises(InputError, match="--all-pixels: all_pixels: cannot be combined with --mask"):
            run_compare(ref, test, tmp_path / "m.npy", all_pixels=True)

    def test_a_mask_layer_of_the_reference_is_its_coverage(self, pair, tmp_path):
        ref, test, coverage = pair
        from harness.io.images import read_exr

        write_exr(tmp_path / "layered.exr", read_exr(ref)["rgb"], extra={"mask": coverage})
        out = run_compare(tmp_path / "layered.exr", test)
        assert out["mask_rule"] == "full_coverage" and out["mask"].endswith("layered.exr[mask]")
        assert out["mask_pixels"] == 80

    def test_no_coverage_beside_it_compares_every_pixel_and_says_why(self, pair, tmp_path):
        ref, test, _ = pair
        from harness.io.images import read_exr

        write_exr(tmp_path / "bare.exr", read_exr(ref)["rgb"])
        out = run_compare(tmp_path / "bare.exr", test)
        assert out["mask_rule"] == "no_coverage" and out["mask_pixels"] == 480
        assert "no mask layer, no mask.exr" in format_table(out)

    def test_a_coverage_without_a_fully_covered_pixel_is_refused(self, pair):
        ref, test, coverage = pair
        write_exr(ref.with_name("mask.exr"), np.repeat(np.minimum(coverage, 0.5)[..., None], 3, axis=2))
        with pytest.raises(InputError, match="mask.exr: mask: the reference's coverage reaches 0.999 on no pixel"):
            run_compare(ref, test)

    def test_heading_names_ref_then_test_in_the_arguments_order(self, pair):
        ref, test, _ = pair
        lines = format_table(run_compare(ref, test)).splitlines()
        assert lines[0] == f"ref  {ref}" and lines[1] == f"test {test}"


@pytest.mark.gl
def test_render_then_compare_equals_the_sweep(tmp_path, capsys, monkeypatch):
    """One render compared from the command line gives the sweep's relMSE and energy ratio."""
    monkeypatch.setenv("SSLPV_PROGRESS", "off")
    scene, params = "sphere_homogeneous", ["--grid", "16", "--steps", "8"]
    assert main(["sweep", "--scenes", scene, *params, "--size", "small", "--workers", "1", "--no-progress",
                 "--out", str(tmp_path / "sweep"), "--json"]) == 0
    assert main(["render", scene, *params, "--size", "small", "--out", str(tmp_path / "r"), "--json"]) == 0
    ref = REF_DIR / scene / "subsurface.exr"
    capsys.readouterr()
    assert main(["compare", str(ref), str(tmp_path / "r" / "subsurface.exr"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    with Store(tmp_path / "sweep" / "store.sqlite") as st:
        (config,) = st.configs()
    swept = config["metrics"]["subsurface"]
    for name in ("relmse", "energy_ratio"):
        got, want = out["metrics"][name]["value"], swept[name]["value"]
        assert got == pytest.approx(want, rel=RTOL, abs=0), \
            f"{name}: compare {got!r} ({out['mask_pixels']} pixels) vs sweep {want!r} (rel {RTOL})"
    assert out["mask_rule"] == "full_coverage"
