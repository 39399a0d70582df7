"""``benchmarks/sslpv_light_budget.py --merge``: several refine runs joined into one table and plot.

The grid-refinement table is printed by this merge from the runs' ``refine.json``
files, so the join itself is tested: each N comes from the last file that has it, a
(scene, mapping) that no file has is shown as ``--``, and a bad file is one line, exit 2.
"""

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def lb():
    spec = importlib.util.spec_from_file_location("sslpv_light_budget", REPO / "benchmarks" / "sslpv_light_budget.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _row(scene, mapping, rel, er, floor=1e-3):
    return {"scene": scene, "mapping": mapping, "outside": "vacuum", "relmse": {str(n): v for n, v in rel.items()},
            "energy_ratio": {str(n): v for n, v in er.items()}, "noise_floor_relmse": floor, "wall_s": 1.0}


def _files(tmp_path):
    a = tmp_path / "a.json"
    b = tmp_path / "b.json"
    a.write_text(json.dumps([_row("s1", "diffusion", {16: 0.1, 32: 0.2}, {16: 1.5, 32: 2.0}),
                             _row("s1", "collision", {16: 3.0}, {16: 4.0}),
                             _row("s2", "diffusion", {16: 0.5}, {16: 0.9})]))
    b.write_text(json.dumps([_row("s1", "diffusion", {32: 0.25, 64: 0.3}, {32: 2.5, 64: 3.0})]))
    return a, b


def test_each_n_comes_from_the_last_file_that_has_it(lb, tmp_path):
    rows, grids = lb.merge_refine(_files(tmp_path))
    assert grids == [16, 32, 64]
    assert [(r["scene"], r["mapping"]) for r in rows] == [("s1", "collision"), ("s1", "diffusion"), ("s2", "diffusion")]
    s1d = rows[1]
    assert s1d["relmse"] == {16: 0.1, 32: 0.25, 64: 0.3}          # 32 from b, 16 from a
    assert s1d["energy_ratio"] == {16: 1.5, 32: 2.5, 64: 3.0}


def test_table_shows_missing_cells(lb, tmp_path):
    rows, _ = lb.merge_refine(_files(tmp_path))
    table = lb.refine_table(rows).splitlines()
    assert table[0] == ("| scene | `collision`, vacuum: E/E, N = 16 (relMSE) | "
                        "`diffusion`, vacuum: E/E, N = 16 / 32 / 64 (relMSE) |")
    assert table[2] == "| s1 | 4.00 (3) | 1.50 / 2.50 / 3.00 (0.1 / 0.25 / 0.3) |"
    assert table[3] == "| s2 | -- | 0.90 / -- / -- (0.5 / -- / --) |"


def test_summary_ranges_and_growth(lb, tmp_path):
    rows, _ = lb.merge_refine(_files(tmp_path))
    lines = lb.refine_summary(rows).splitlines()
    assert lines[0] == "collision/vacuum over 1 scenes: E/E N = 16: 4.00-4.00"
    # diffusion: s1 16->32 grows 0.1 -> 0.25 (2.5x), s2 has N = 16 only
    assert lines[1] == ("diffusion/vacuum over 2 scenes: E/E N = 16: 0.90-1.50, N = 32: 2.50-2.50, "
                        "N = 64: 3.00-3.00; relMSE per doubling 16->32: 2.50-2.50x (1/1 grow), "
                        "32->64: 1.20-1.20x (1/1 grow)")


def test_merge_writes_json_and_plot(lb, tmp_path, capsys):
    out = tmp_path / "out"
    lb.main(["--merge", *map(str, _files(tmp_path)), "--out", str(out)])
    assert "| s1 | 4.00 (3) |" in capsys.readouterr().out
    assert json.loads((out / "refine.json").read_text())[1]["relmse"] == {"16": 0.1, "32": 0.25, "64": 0.3}
    assert (out / "refine.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("text,needle", [
    ("{not json", "file: is not JSON"),
    ('{"rows": []}', "rows: must be a list of rows"),
    ('[{"scene": "s"}]', "row 0: lacks mapping, outside, relmse, energy_ratio, noise_floor_relmse"),
    (json.dumps([_row("s", "diffusion", {16: 0.1}, {16: 1.0})]).replace('"16": 0.1', '"sixteen": 0.1'),
     "row 0: relmse and energy_ratio must map N to a number"),
], ids=["json", "not-a-list", "missing-keys", "bad-n"])
def test_a_bad_file_is_one_line(tmp_path, text, needle):
    bad = tmp_path / "bad.json"
    bad.write_text(text)
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, str(REPO / "benchmarks" / "sslpv_light_budget.py"), "--merge", str(bad),
                           "--out", str(out)], cwd=tmp_path, capture_output=True, text=True,
                          env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"}, timeout=120)
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert proc.stderr.startswith(f"error: {bad}: {needle}"), proc.stderr
    assert not out.exists()
