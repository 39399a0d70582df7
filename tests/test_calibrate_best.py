"""``sslpv-harness calibrate-best``: the best calibrated mapping by its held-out figures (Eq. S1).

Checked by a route that does not use the ranking code: the geometric mean written out by hand
over synthetic calibrations built so that the arithmetic mean and the best single budget pick
other winners; the committed ``baselines/calibrated/best/`` against the committed calibrations it
names; the copy read back as its source.
"""

import json
import math
from pathlib import Path

import pytest

from harness import paths
from harness.calibration.select import select
from harness.cli import main
from sslpv_gl.calibrated import load_calibrated
from sslpv_gl.material import MAPPINGS

BEST = paths.REPO / "baselines" / "calibrated" / "best"
SCENES = ["a", "b", "c"]


def fake(folder, medians, scenes=SCENES, grid=32):
    """A calibration folder whose held-out medians at budgets K = 8, 16, steady are ``medians``."""
    folder = Path(folder)
    folder.mkdir(parents=True)
    src = paths.REPO / "baselines" / "calibrated" / "collision" / "calibrated.toml"
    (folder / "calibrated.toml").write_text(src.read_text() + f"# fake calibration {folder.name}\n")
    budgets = [[grid, 8], [grid, 16], [grid, "steady"]]
    results = {f"N={n} steps={k}": {"targets": {"median_held_out_relmse": m, "energy_outside": {"a": 0.5}}}
               for (n, k), m in zip(budgets, medians)}
    (folder / "calibration.json").write_text(json.dumps({"family": "collision", "scenes": scenes,
                                                         "budgets": budgets, "results": results}))
    return str(folder)


def test_the_lowest_geometric_mean_wins(tmp_path):
    # x: best geometric mean (0.136); y: best arithmetic mean (0.2 against x's 0.337) and best at two budgets.
    meds = {"x": [0.01, 0.5, 0.5], "y": [0.2, 0.2, 0.2], "z": [0.3, 0.3, 0.9]}
    folders = {k: fake(tmp_path / k, m) for k, m in meds.items()}
    by_hand = {folders[k]: math.exp(sum(math.log(v) for v in m) / 3) for k, m in meds.items()}
    assert sum(meds["y"]) < sum(meds["x"]) and by_hand[folders["x"]] < by_hand[folders["y"]]
    sel = select(list(folders.values()), 32)
    assert sel["winner"] == folders["x"]
    assert [c["folder"] for c in sel["candidates"]] == sorted(by_hand, key=by_hand.get)
    for c in sel["candidates"]:
        assert c["score"] == pytest.approx(by_hand[c["folder"]], rel=1e-12)


def test_only_the_common_budgets_count(tmp_path):
    a = fake(tmp_path / "a", [0.1, 0.1, 10.0])    # a's bad steady budget must not count: b has none
    b = tmp_path / "b"
    fake(b, [0.2, 0.2, 0.2])
    cal = json.loads((b / "calibration.json").read_text())
    cal["budgets"] = cal["budgets"][:2]
    (b / "calibration.json").write_text(json.dumps(cal))
    sel = select([a, str(b)], 32)
    assert sel["budgets"] == ["N=32 steps=8", "N=32 steps=16"] and sel["winner"] == a


def test_committed_best_is_what_the_command_writes_from_the_committed_calibrations():
    sel = json.loads((BEST / "selection.json").read_text())
    again = select(sel["command"].split("--from ")[1].split(" --out")[0].split(), sel["grid"])
    assert again["winner"] == sel["winner"]
    assert [c["folder"] for c in again["candidates"]] == [c["folder"] for c in sel["candidates"]]
    text = (BEST / "calibrated.toml").read_text()
    source = (paths.REPO / sel["winner"] / "calibrated.toml").read_text()
    assert text.endswith(source) and all(line.startswith("#") for line in text[:-len(source)].splitlines())
    mine, theirs = (load_calibrated(p, tuple(MAPPINGS)) for p in (BEST / "calibrated.toml",
                                                                   paths.REPO / sel["winner"] / "calibrated.toml"))
    assert mine.settings == theirs.settings and mine.budgets == theirs.budgets


def test_the_winner_is_ranked_again_at_every_other_grid_it_holds(tmp_path):
    """x wins at N = 32 but y leads at N = 64: ``other_grids`` ranks the candidates that hold N = 64 (z, fitted at
    N = 32 alone, is not among them) by the same (S1), and the written header names y as the leader there."""
    def two_grids(name, m32, m64):
        f = Path(fake(tmp_path / name, m32))
        cal = json.loads((f / "calibration.json").read_text())
        for k, m in zip((8, 16, "steady"), m64):
            cal["budgets"].append([64, k])
            cal["results"][f"N=64 steps={k}"] = {"targets": {"median_held_out_relmse": m, "energy_outside": {}}}
        (f / "calibration.json").write_text(json.dumps(cal))
        return str(f)

    x, y = two_grids("x", [0.01, 0.01, 0.01], [0.2, 0.2, 0.2]), two_grids("y", [0.02, 0.02, 0.02], [0.1, 0.05, 0.2])
    z = fake(tmp_path / "z", [0.03, 0.03, 0.03])
    sel = select([x, y, z], 32)
    assert sel["winner"] == x and [o["grid"] for o in sel["other_grids"]] == [64]
    o = sel["other_grids"][0]
    assert o["leader"] == y and o["winner_rank"] == 2 and [c["folder"] for c in o["candidates"]] == [y, x]
    assert o["candidates"][0]["score"] == pytest.approx((0.1 * 0.05 * 0.2) ** (1 / 3), rel=1e-12)
    assert main(["calibrate-best", "--json", "--from", x, y, z, "--out", str(tmp_path / "best")]) == 0
    header = (tmp_path / "best" / "calibrated.toml").read_text().split("format =")[0]
    assert f"At N = 64 it ranks 2 of 2 by the same rule; {y} leads there" in header
    only = select([x, z], 32)["other_grids"][0]                 # the winner alone holds N = 64: first of one
    assert only["winner_rank"] == 1 and only["leader"] == x


def test_committed_best_holds_every_grid_of_the_study():
    """The best calibration is usable at N = 16, 32 and 64, each at every real-time budget: a user who renders
    it at the grids the study reports (``studies/default.toml``) is not refused for a missing grid."""
    best = load_calibrated(BEST / "calibrated.toml", tuple(MAPPINGS))
    have = {(b.N, b.steps) for b in best.budgets}
    want = {(n, k) for n in (16, 32, 64) for k in (8, 16, 32, 64, "steady")}
    assert want <= have, sorted(want - have, key=str)
    for n, k in sorted(want, key=str):
        assert best.budget(n, k).N == n


def test_the_command_writes_the_winner_and_reads_it_back(tmp_path, capsys):
    a, b = fake(tmp_path / "a", [0.3, 0.3, 0.3]), fake(tmp_path / "b", [0.1, 0.2, 0.3])
    assert main(["calibrate-best", "--json", "--from", a, b, "--out", str(tmp_path / "best")]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["winner"] == b
    assert (tmp_path / "best" / "calibrated.toml").read_text().endswith((Path(b) / "calibrated.toml").read_text())


@pytest.mark.parametrize("case, needle", [
    ("other_scenes", "scenes: fitted on other scenes"),
    ("no_grid", "budgets: none at N = 32"),
    ("missing", "calibrated.toml: is missing"),
    ("foreign_out", "output: is a non-empty folder that the harness did not write"),
    ("no_held_out", "results.N=32 steps=8.targets.median_held_out_relmse: is missing"),
])
def test_bad_input_is_one_line(tmp_path, capsys, case, needle):
    a = fake(tmp_path / "a", [0.1, 0.1, 0.1])
    b = {"other_scenes": lambda: fake(tmp_path / "b", [0.1, 0.1, 0.1], scenes=["a", "b"]),
         "no_grid": lambda: fake(tmp_path / "b", [0.1, 0.1, 0.1], grid=16),
         "missing": lambda: str(tmp_path),
         "foreign_out": lambda: a,
         "no_held_out": lambda: _without_held_out(fake(tmp_path / "b", [0.1, 0.1, 0.1]))}[case]()
    out = tmp_path / "out"
    if case == "foreign_out":
        out.mkdir()
        (out / "mine.txt").write_text("not the harness's")
    assert main(["calibrate-best", "--from", a, b, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and needle in err[0]
    assert case == "foreign_out" and (out / "mine.txt").read_text() == "not the harness's" or not out.exists()


def _without_held_out(folder):
    """``folder`` (a fake calibration) with its first budget's held-out validation removed."""
    path = Path(folder) / "calibration.json"
    cal = json.loads(path.read_text())
    del cal["results"]["N=32 steps=8"]["targets"]["median_held_out_relmse"]
    path.write_text(json.dumps(cal))
    return folder
