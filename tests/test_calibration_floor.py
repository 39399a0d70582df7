"""The floor of a calibrated family (harness/calibration/floor.py, Eqs. L1, L2): each scene at its own best scales.

Synthetic scans whose optimum is known per colour channel, checked against brute force through
``harness.metrics`` and the calibration's own fit; the study's target and limits read the floor file.
"""

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from harness import paths
from harness.calibration.fit import SceneSamples, fit
from harness.calibration.floor import (FILE, channel_floor, floor_for, median_bound, run_floor, scene_floor,
                                       terms_uniform)
from harness.calibration.form_loss import scan_grid
from harness.metrics import compute
from harness.metrics.pixel import RELMSE_EPS

SCAN = [2.0 ** k for k in range(-4, 7)]


def scene(rng, u_star, v_star, shape=(10, 9, 3), noise=0.1):
    """A scene whose channel ``c`` at ``u = ln s`` is its reference times ``exp(w (u - u_c) / 2 - v_c)`` times a fixed
    pixel noise: channel ``c``'s optimum is ``(u_star[c], v_star[c])``. -> (SceneSamples, ref, {s: image})."""
    ref = rng.uniform(0.1, 2.0, shape)
    w, eps = rng.normal(0.0, 1.0, shape), rng.lognormal(0.0, noise, shape)
    u_c, v_c = np.asarray(u_star, float), np.asarray(v_star, float)
    smp = SceneSamples("x", {"full": ref.ravel(), "half_a": ref.ravel(), "half_b": ref.ravel()})
    images = {}
    for s in SCAN:
        images[s] = ref * np.exp(0.5 * w * (math.log(s) - u_c) - v_c) * eps
        smp.add(s, images[s].ravel())
    return smp, ref, images


def test_channel_floor_is_the_brute_force_minimum_through_the_metric():
    """At the scan's samples (the grid = the samples), (L1) equals a brute-force search over s and r of each channel
    (no pair does better), and the image assembled from each channel at its floor's scales, judged by
    harness.metrics' relMSE (a second route), has the floor's relMSE."""
    rng = np.random.default_rng(3)
    smp, ref, images = scene(rng, [0.4, 1.6, -0.9], [0.3, -0.5, 0.1])
    got = scene_floor(smp, np.log(np.asarray(SCAN)))
    mask = np.ones(ref.shape[:2], bool)
    r_grid = np.exp(np.linspace(-2.0, 2.0, 801))
    img = np.empty_like(ref)
    for c, ch in enumerate(got["channels"]):
        R = ref[..., c]
        brute = min((float(np.mean((r * images[s][..., c] - R) ** 2 / (R * R + RELMSE_EPS))), s)
                    for s in SCAN for r in r_grid)
        assert ch["relmse"] <= brute[0] * (1 + 1e-12)
        assert ch["relmse"] == pytest.approx(brute[0], rel=1e-3)
        assert ch["s"] == pytest.approx(brute[1])
        img[..., c] = images[ch["s"]][..., c] * ch["r"]
    assert got["relmse"] == pytest.approx(compute("relmse", img, ref, mask).value, rel=1e-9)


def test_scalar_floor_is_the_calibrations_oracle():
    """(L2) on the fine grid equals the calibration's own fit of the scene alone (Brent on the spline, Eq. C2)."""
    rng = np.random.default_rng(5)
    for u_star in (-1.3, 0.7, 2.2):
        smp, _, _ = scene(rng, [u_star] * 3, [0.2] * 3)
        got = scene_floor(smp, scan_grid(SCAN, 769))["scalar"]
        f = fit([smp])
        assert got["relmse"] == pytest.approx(math.exp(f.loss), rel=2e-3)
        assert math.log(got["s"]) == pytest.approx(math.log(f.s), abs=0.02)
        assert got["r"] == pytest.approx(f.r, rel=5e-3)


def test_channel_floor_below_the_scalar_and_equal_for_a_grey_scene():
    rng = np.random.default_rng(7)
    grid = scan_grid(SCAN, 769)
    colour = scene_floor(scene(rng, [-1.0, 0.5, 2.0], [0.6, 0.0, -0.4])[0], grid)
    assert colour["relmse"] < 0.9 * colour["scalar"]["relmse"]
    ref = rng.uniform(0.1, 2.0, (8, 8, 1))
    w = rng.normal(0.0, 1.0, (8, 8, 1))
    grey = SceneSamples("g", {k: np.repeat(ref, 3, axis=2).ravel() for k in ("full", "half_a", "half_b")})
    for s in SCAN:
        grey.add(s, np.repeat(ref * np.exp(0.5 * w * (math.log(s) - 0.3)), 3, axis=2).ravel())
    g = scene_floor(grey, grid)
    assert g["relmse"] == pytest.approx(g["scalar"]["relmse"], rel=1e-12)


def test_energy_ratio_at_the_floor_is_the_assembled_images():
    rng = np.random.default_rng(11)
    smp, ref, images = scene(rng, [0.0, 0.7, 1.4], [0.3, 0.1, -0.2])
    got = scene_floor(smp, np.log(np.asarray(SCAN)))
    img = np.stack([images[c["s"]][..., k] * c["r"] for k, c in enumerate(got["channels"])], axis=-1)
    assert got["energy_ratio"] == pytest.approx(img.sum() / ref.sum(), rel=1e-12)


def test_an_optimum_beyond_the_scan_is_marked_and_a_plateau_is_settled():
    rng = np.random.default_rng(13)
    grid = scan_grid(SCAN, 769)
    beyond = scene_floor(scene(rng, [6.0] * 3, [0.0] * 3)[0], grid)
    assert all(c["at_bound"] and not c["settled"] for c in beyond["channels"])
    inside = scene_floor(scene(rng, [0.5] * 3, [0.0] * 3)[0], grid)
    assert not any(c["at_bound"] for c in inside["channels"])
    T = np.tile([1.0, 0.5, 1.0], (len(grid), 1))                     # a flat loss: the end is the plateau's
    T[len(grid) // 2:, 2] += np.linspace(0.0, 1.0, len(grid) - len(grid) // 2)
    flat = channel_floor(T, grid)
    assert flat["at_bound"] and flat["settled"]


def test_median_bound_takes_varying_scenes_as_zero():
    entry = {"scenes": {"a": {"relmse": 0.01, "uniform": True}, "b": {"relmse": 0.02, "uniform": True},
                        "c": {"relmse": 0.03, "uniform": True}, "d": {"relmse": 0.5, "uniform": False},
                        "e": {"relmse": 0.6, "uniform": False}}}
    assert median_bound(entry) == pytest.approx(0.01)               # 0, 0, 0.01, 0.02, 0.03
    assert median_bound(entry, ["a", "b", "c"]) == pytest.approx(0.02)
    assert median_bound(entry, ["zz"]) is None
    open_end = {"relmse": 0.015, "uniform": True, "channels": [{"settled": True}, {"settled": False}, {"settled": True}]}
    entry["scenes"]["f"] = open_end                              # its least at the scan's end, not levelled off
    assert median_bound(entry, ["a", "b", "c", "f"]) == pytest.approx(0.015)     # 0, 0.01, 0.02, 0.03
    open_end["channels"][1]["settled"] = True
    assert median_bound(entry, ["a", "b", "c", "f"]) == pytest.approx(0.0175)


def test_terms_uniform_on_a_homogeneous_and_a_varying_medium():
    from harness.scene import load_scene

    settings = {"resample": "box"}
    assert terms_uniform(load_scene("sphere_homogeneous"), 16, settings)
    assert not terms_uniform(load_scene("jade_veins"), 16, settings)


def test_floor_for_prefers_the_calibrations_own_then_its_sources(tmp_path):
    src, form = tmp_path / "collision", tmp_path / "collision_form"
    src.mkdir()
    form.mkdir()
    entry = {"N": 32, "steps": 8, "scenes": {"a": {"relmse": 0.01}}}
    (src / FILE).write_text(json.dumps({"budgets": {"N=32 steps=8": entry}}))
    (form / "calibration.json").write_text(json.dumps({"sources": [str(src)]}))
    got, path = floor_for(form / "calibration.json", "N=32 steps=8")
    assert got == entry and path == src / FILE
    assert floor_for(form / "calibration.json", "N=32 steps=16") == (None, None)
    own = dict(entry, scenes={"a": {"relmse": 0.005}})
    (form / FILE).write_text(json.dumps({"budgets": {"N=32 steps=8": own}}))
    assert floor_for(form / "calibration.json", "N=32 steps=8") == (own, form / FILE)


@pytest.mark.parametrize("folder, field", [("collision_loss_form", "sigma_scan"), ("no_such_folder", "folder")])
def test_a_form_or_a_missing_folder_is_refused_in_one_line(tmp_path, folder, field):
    """A form's folder (it has no scan of its own) and a folder without a calibration: one line, exit 2, nothing
    written, through the command line."""
    src = paths.REPO / "baselines" / "calibrated" / folder
    before = sorted(p.name for p in src.iterdir()) if src.is_dir() else None
    p = subprocess.run([sys.executable, "-m", "harness.cli", "calibrate-floor", "--from", str(src)],
                       capture_output=True, text=True, cwd=paths.REPO)
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and field in lines[0], lines
    assert (sorted(p.name for p in src.iterdir()) if src.is_dir() else None) == before


def test_committed_floor_matches_its_calibrations_oracle():
    """Each committed floor file against its calibration's recorded oracle (a render at the scene's own fitted
    optimum, a second route): the scalar floor (L2) is never above it (else the floor would not bound what a
    render reached), and equals it where both found the same optimum; the per-channel floor (L1) is never above
    the scalar one; the floor was written from the calibration's current scenes."""
    same = 0
    for path in sorted((paths.REPO / "baselines" / "calibrated").glob(f"*/{FILE}")):
        floor = json.loads(path.read_text())
        cal = json.loads((path.parent / "calibration.json").read_text())
        assert floor["scenes"] == cal["scenes"]
        for label, b in floor["budgets"].items():
            for n, row in b["scenes"].items():
                oracle = cal["results"][label]["oracle"][n]
                assert row["scalar"]["relmse"] <= oracle["relmse"] * 1.01, (path, label, n)
                if abs(math.log(row["scalar"]["s"] / oracle["s"])) < 0.05:
                    assert row["scalar"]["relmse"] == pytest.approx(oracle["relmse"], rel=0.01), (path, label, n)
                    same += 1
                assert row["relmse"] <= row["scalar"]["relmse"] * (1 + 1e-9)
    assert same > 0


def test_run_floor_end_to_end_on_a_small_calibration(tmp_path, capsys):
    """``sslpv-harness calibrate`` on two small scenes writes the floor beside the calibration; ``calibrate-floor`` on
    its folder is served the scan from the result cache the calibration filled (no render) and writes the same
    floor (the calibration's renders at its optima are not part of it), as does a run that renders the scan afresh;
    the scalar floor is the calibration's oracle (there refined by renders at the optimum, here the spline of the
    scan's five samples)."""
    from harness.cli import main

    out = tmp_path / "cal"
    assert main(["calibrate", "--family", "collision", "--scenes", "sphere_homogeneous,thin_ring", "--grid", "8",
                 "--steps", "4,steady", "--points", "5", "--no-progress", "--json", "--out", str(out)]) == 0
    capsys.readouterr()
    written = json.loads((out / FILE).read_text())              # calibrate writes the floor from its own scan
    assert main(["calibrate-floor", "--from", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["renders"] == 0 and summary["served_from_cache"] == 2 * 5 * 2
    on_disk = json.loads((out / FILE).read_text())
    assert on_disk["command"] == f"sslpv-harness calibrate-floor --from {out}"
    assert {k: {"median": v["median"], "median_scalar": v["median_scalar"]}
            for k, v in on_disk["budgets"].items()} == summary["budgets"]
    again = run_floor(out, tmp_path / "floor.json", cache=False, progress=lambda m: None)      # rendered afresh
    assert again["renders"] > 0 and again["budgets"] == on_disk["budgets"] == written["budgets"]
    cal = json.loads((out / "calibration.json").read_text())
    for label, b in on_disk["budgets"].items():
        assert set(b["scenes"]) == {"sphere_homogeneous", "thin_ring"}
        for n, row in b["scenes"].items():
            assert row["uniform"] is True
            assert row["relmse"] <= row["scalar"]["relmse"] * (1 + 1e-12)
            assert row["scalar"]["relmse"] == pytest.approx(cal["results"][label]["oracle"][n]["relmse"], rel=0.05)


def test_the_studys_limits_give_each_familys_floor_once(tmp_path):
    """What limits SSLPV: each calibration's in-sample and held-out figures, and each floor file once (two
    calibrations of one family share their source's floor)."""
    from harness.study.limits import _mapping
    from harness.study.present import limit_lines

    src = tmp_path / "collision"
    _write_floor(src, {"a": 0.004}, uniform=True)
    cals = []
    for name, sources in (("collision", []), ("collision_form", [str(src)])):
        d = tmp_path / name
        d.mkdir(exist_ok=True)
        fig = {"a": {"relmse": 0.01, "energy_ratio": 0.9}}
        (d / "calibration.json").write_text(json.dumps({"sources": sources, "results": {"N=32 steps=8": {
            "N": 32, "steps": 8, "in_sample": fig, "held_out": fig}}}))
        cals.append({"report": str(d / "calibration.json"), "family": "collision", "file": str(d / "calibrated.toml"),
                     "label": f"calibrated {name}"})
    m = _mapping({"scene": "a", "K": "8", "N": 32}, cals, {"grid": 32, "steps": [8, "steady"]})
    assert [f["family"] for f in m["floors"]] == ["collision"]
    assert m["floors"][0]["relmse"] == pytest.approx(0.004) and m["floors"][0]["uniform"] is True
    lines = limit_lines({**LIM, "mapping": m})
    floor_lines = [x for x in lines if x.startswith("Floor of the collision family")]
    assert len(floor_lines) == 1 and "0.004 with each colour channel" in floor_lines[0]
    assert "no calibration of the family does better" in floor_lines[0]
    m["floors"][0].update(bounds=False)                          # uniform, but a channel's least at the scan's end
    assert "beyond the scan" in [x for x in limit_lines({**LIM, "mapping": m}) if x.startswith("Floor")][0]
    m["floors"][0].update(uniform=False)
    assert "terms vary" in [x for x in limit_lines({**LIM, "mapping": m}) if x.startswith("Floor")][0]


LIM = {"subject": "x", "relmse": 0.01, "floor": 0.001, "steps": {"measured": False, "why": "-"},
       "outside": {"measured": False, "why": "-"}, "boundary": {"measured": False, "why": "-"}, "speed": {}}


def _write_floor(folder, values, uniform):
    folder.mkdir(exist_ok=True)
    rows = {s: {"relmse": v, "scalar": {"relmse": 2 * v}, "energy_ratio": 1.0, "uniform": uniform}
            for s, v in values.items()}
    (folder / FILE).write_text(json.dumps({"budgets": {"N=32 steps=8": {"N": 32, "steps": 8, "scenes": rows}}}))
