"""Nightly job: verdict arithmetic, and two small nights end to end (64x64, committed references)."""

import json
import re
import sqlite3

import pytest

from harness.cli import main
from harness.regression.verdict import badness, compare_rows, judge, overall


class TestVerdict:
    def test_badness_is_distance_from_ideal(self):
        assert badness("relmse", 0.2) == 0.2
        assert badness("energy_ratio", 0.7) == pytest.approx(0.3)
        assert badness("energy_ratio", 1.3) == pytest.approx(0.3)
        assert badness("ssim", 0.9) == pytest.approx(0.1)

    def test_within_noise_and_tolerance_is_unchanged(self):
        # threshold = 0.01 + 0.01 + max(1e-4, 0.05 * 0.2) = 0.03
        c = judge("s", "c", "subsurface", "relmse", 0.20, 0.01, 0.229, 0.01, {"rel": 0.05, "abs": 1e-4})
        assert c.threshold == pytest.approx(0.03) and c.verdict == "unchanged"

    def test_beyond_is_regression_or_improvement(self):
        tol = {"rel": 0.05, "abs": 1e-4}
        assert judge("s", "c", "subsurface", "relmse", 0.20, 0.01, 0.231, 0.01, tol).verdict == "regression"
        assert judge("s", "c", "subsurface", "relmse", 0.20, 0.01, 0.169, 0.01, tol).verdict == "improvement"

    def test_energy_ratio_moving_away_from_one_regresses(self):
        tol = {"rel": 0.0, "abs": 0.01}
        assert judge("s", "c", "subsurface", "energy_ratio", 1.05, 1.0, 1.2, 1.0, tol).verdict == "regression"
        assert judge("s", "c", "subsurface", "energy_ratio", 0.8, 1.0, 0.95, 1.0, tol).verdict == "improvement"

    def test_compare_rows_matches_keys_and_headline_only(self):
        old = [{"scene": "a", "config": "x", "image": "subsurface", "metric": m, "value": 0.1, "noise_floor": 0.0}
               for m in ("relmse", "rmse")]
        new = [dict(r, value=0.5) for r in old] + [dict(old[0], scene="b")]
        changes = compare_rows(old, new, {"rel": 0.0, "abs": 0.0})
        assert [(c.scene, c.metric, c.verdict) for c in changes] == [("a", "relmse", "regression")]
        assert overall(changes) == "regression" and overall([]) == "unchanged"


MATRIX = """
scenes = ["thin_ring", "absorbing_sphere"]
size = [64, 64]
[params]
grid = [8, 16]
steps = [8]
mapping = ["collision"]
[tolerance]
rel = 0.05
abs = 1e-4
"""


@pytest.mark.gl
@pytest.mark.slow
def test_two_nights_verdicts_and_index(tmp_path, capsys):
    matrix = tmp_path / "matrix.toml"
    matrix.write_text(MATRIX)
    store, out = tmp_path / "nightly.sqlite", tmp_path / "nightly"
    args = ["nightly", "--matrix", str(matrix), "--store", str(store), "--out", str(out), "--json"]
    assert main(args + ["--date", "2026-11-20"]) == 0
    first = json.loads(capsys.readouterr().out)
    assert first["verdict"] in ("unchanged", "improvement") and first["configurations"] == 4

    # Make night 1 look far better than SSLPV is, so night 2 must be judged a regression.
    with sqlite3.connect(store) as db:
        db.execute("UPDATE metrics SET value = value * 0.5 WHERE metric = 'relmse' AND image = 'subsurface'")
    assert main(args + ["--date", "2026-11-21"]) == 1
    second = json.loads(capsys.readouterr().out)
    assert second["verdict"] == "regression" and second["regressions"] >= 4
    night = json.loads((out / "2026-11-21" / "night.json").read_text())
    reg = night["regressions"][0]
    assert reg["metric"] == "relmse" and reg["against"] == "previous-night" and reg["scene"] in MATRIX
    assert reg["new"] > reg["old"] and reg["delta"] > reg["threshold"]
    page = (out / "2026-11-21" / "index.html").read_text()
    assert "regression" in page and reg["config"] in page
    assert (out / "2026-11-21" / "report" / "index.html").is_file()
    assert list((out / "2026-11-21").glob("trend_*_relmse.png"))
    index = (out / "index.html").read_text()
    assert index.index("2026-11-21") < index.index("2026-11-20")


def test_bad_matrix_is_one_line(tmp_path, capsys):
    matrix = tmp_path / "m.toml"
    matrix.write_text(MATRIX.replace("grid = [8, 16]", "colour = [1]"))
    assert main(["nightly", "--matrix", str(matrix), "--store", str(tmp_path / "s.sqlite"),
                 "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "params.colour: is not a known field" in err[0]
    assert not (tmp_path / "s.sqlite").exists()


def test_matrix_also_products(tmp_path):
    """[[also]] tables add further cartesian products; a relative calibrated path stays as written."""
    from harness.errors import InputError
    from harness.regression.nightly import load_matrix
    from harness.runs.sweep import expand_all

    m = tmp_path / "m.toml"
    m.write_text('scenes = ["thin_ring"]\n[params]\ngrid = [8]\nsteps = [4, 8]\nmapping = ["collision"]\n'
                 '[[also]]\ngrid = [8]\nsteps = [8, "steady"]\nmapping = ["diffusion", "calibrated:x/c.toml"]\n')
    # The calibrated file is looked up at load time (from here, else the repository) and refused when missing.
    with pytest.raises(InputError, match=re.escape("x/c.toml: file: does not exist")):
        load_matrix(m)
    m.write_text(m.read_text().replace(', "calibrated:x/c.toml"', ""))
    params = load_matrix(m)["params"]
    assert isinstance(params, list) and len(params) == 2
    configs = expand_all(params)
    assert [(c.steps, c.mapping) for c in configs] == [(4, "collision"), (8, "collision"), (8, "diffusion"),
                                                       ("steady", "diffusion")]
    m.write_text('[params]\ngrid = [8]\n[[also]]\ngridd = [8]\n')
    with pytest.raises(InputError, match=r"also\[0\]\.gridd: is not a known field"):
        load_matrix(m)
