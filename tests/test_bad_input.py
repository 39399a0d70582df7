"""Bad input through the command line: every case exits 2, prints exactly ONE line on stderr
that names the file or setting and the field, and leaves no file behind.

The cases cover command-line values, sweep configurations (``--config``), the
nightly matrix, stores and EXRs, and include every example the issue lists. Each runs
``harness.cli.main`` in this process (a traceback would fail the test as an exception),
with the folder it works in compared before and after. The accuracy matrix has no command
of its own; its cases call the loader that ``pytest -m accuracy`` uses. Scene files and their meshes are
the cases of :mod:`tests.test_bad_scene_input`, through the same runner (:func:`one_line_runner`).
"""

import hashlib
import json
import re
import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from harness.cli import main
from harness.errors import InputError
from harness.io.images import write_exr
from harness.scene import SUITE_DIR
from harness.store import Store

REPO = Path(__file__).resolve().parent.parent
# A small, valid scene: the suite's white sphere at a 16^3 grid (fast to load).
GOOD = (SUITE_DIR / "sphere_homogeneous" / "scene.toml").read_text().replace(
    "resolution = [64, 64, 64]", "resolution = [16, 16, 16]")
JADE = (SUITE_DIR / "jade_veins" / "scene.toml").read_text().replace(
    "resolution = [64, 64, 64]", "resolution = [16, 16, 16]")
SWEEP = ["sweep", "--scenes", "thin_ring", "--grid", "8", "--steps", "4", "--workers", "1", "--size", "64x64"]


def snapshot(root):
    """Every file under ``root`` with its size and content hash (what 'nothing left behind' compares)."""
    out = {}
    for p in sorted(Path(root).rglob("*")):
        if p.is_file():
            out[str(p.relative_to(root))] = hashlib.sha256(p.read_bytes()).hexdigest()
        else:
            out[str(p.relative_to(root))] = "dir"
    return out


@pytest.fixture
def cli(tmp_path, capsys, monkeypatch):
    return one_line_runner(tmp_path, capsys, monkeypatch)


def one_line_runner(tmp_path, capsys, monkeypatch):
    """``cli(argv, *needles)``: run, then check exit 2 (``codes=(3,)`` where the environment, not the input, is at
    fault), one stderr line with the needles, no new files."""
    monkeypatch.setenv("SSLPV_CACHE", str(tmp_path / "cache"))
    monkeypatch.chdir(tmp_path)

    def run(argv, *needles, codes=(2,)):
        before = snapshot(tmp_path)
        capsys.readouterr()
        code = main([str(a) for a in argv])
        captured = capsys.readouterr()
        lines = [line for line in captured.err.splitlines() if line.strip()]
        assert code in codes, (code, captured.err)
        assert len(lines) == 1, captured.err
        assert lines[0].startswith("error: "), lines[0]
        for needle in needles:
            assert str(needle) in lines[0], (needle, lines[0])
        after = snapshot(tmp_path)
        changed = sorted(k for k in set(before) | set(after) if before.get(k) != after.get(k))
        assert not changed, f"files were left behind or changed: {changed}"
        assert captured.out == "", captured.out     # stdout carries only a result, and there is none
        return lines[0]

    return run


@pytest.fixture
def store(tmp_path):
    """A small real store: one sweep run with two configurations of one scene."""
    path = tmp_path / "runs" / "store.sqlite"
    with Store(path) as st:
        rid = st.start_run("sweep", {"scenes": ["thin_ring"]})
        for n in (8, 16):
            st.record_config(rid, "thin_ring", "h" * 64, {"N": n, "steps": 4}, "ok", timings={"total": 1.0},
                             metrics=[{"image": "subsurface", "metric": "relmse", "value": 0.1, "noise_floor": 0.01}])
        st.finish_run(rid, "finished")
    return path


CLI_CASES = [
    ("workers-0", SWEEP + ["--workers", "0"], "--workers: workers: must be an integer > 0"),
    ("spp-0", ["reference", "sphere_homogeneous", "--spp", "0"], "--spp: spp: must be an integer > 0"),
    ("size-huge", SWEEP[:-2] + ["--out", "o", "--size", "100000x100000"], "--size: size: 100000x100000 is larger than 8192x8192"),
    ("size-not-wxh", SWEEP[:-2] + ["--out", "o", "--size", "64"], "--size: size: '64' is not WIDTHxHEIGHT"),
    ("scheduler-garbage", SWEEP + ["--out", "o", "--scheduler", "not an address!"], "--scheduler: scheduler: 'not an address!' "
                                                                      "is not a Dask scheduler address"),
    ("grid-word", ["sweep", "--out", "o", "--scenes", "thin_ring", "--grid", "sixteen"], "--grid: grid: 'sixteen' is not an integer"),
    ("grid-range", ["sweep", "--out", "o", "--scenes", "thin_ring", "--grid", "1000"], "--grid: N: must be an integer in [4, 256]"),
    ("mapping-unknown", ["sweep", "--out", "o", "--scenes", "thin_ring", "--mapping", "magic"], "--mapping: mapping: unknown"),
    ("scene-unknown", ["sweep", "--out", "o", "--scenes", "no_such_scene"], "--scenes: scenes: unknown scene 'no_such_scene'"),
    ("option-unknown", SWEEP + ["--bogus"], "--bogus: bogus: is not an option of `sslpv-harness sweep`"),
    ("out-required", ["render", "thin_ring"], "--out: out: is required"),
    ("render-grid-word", ["render", "thin_ring", "--out", "o", "--grid", "abc"],
     "--grid: grid: 'abc' is not an integer; write an integer, e.g. 32"),
    ("render-steps-0", ["render", "thin_ring", "--out", "o", "--steps", "0"],
     "--steps: steps: 0 is fewer than the 2 steps that --skip leaves out by default"),
    ("render-skip-over-steps", ["render", "thin_ring", "--out", "o", "--steps", "4", "--skip", "5"],
     "--skip: skip: skip 5 must not exceed steps 4"),
    ("render-scene-misspelt", ["render", "thn_ring", "--out", "o"], "scene: no such scene file; did you mean thin_ring?"),
    ("sweep-scene-misspelt", ["sweep", "--out", "o", "--scenes", "thin_rnig"],
     "--scenes: scenes: unknown scene 'thin_rnig'; did you mean thin_ring?"),
    ("eta2-word", ["render", "thin_ring", "--out", "o", "--eta2", "true"], "'true' is not expected"),
    ("baselines-no-action", ["baselines", "frobnicate"], "sslpv-harness baselines: command: unknown command"),
    ("render-size-not-wxh", ["render", "thin_ring", "--out", "o", "--size", "64"],
     "--size: size: '64' is not WIDTHxHEIGHT; write e.g. 128x128, or small"),
    ("render-size-zero", ["render", "thin_ring", "--out", "o", "--size", "0x64"], "--size: size: '0x64' is not WIDTHxHEIGHT"),
    ("render-size-huge", ["render", "thin_ring", "--out", "o", "--size", "9000x64"],
     "--size: size: 9000x64 is larger than 8192x8192"),
    ("render-size-rival", ["render", "thin_ring", "--method", "dipole", "--out", "o", "--size", "tiny"],
     "--size: size: 'tiny' is not WIDTHxHEIGHT"),
    ("render-terms-unknown", ["render", "thin_ring", "--method", "dipole", "--out", "o", "--terms", "multiple"],
     "--terms: terms: unknown value 'multiple'; use one of: diffusion, single, both"),
    ("render-cubemap-samples", ["render", "thin_ring", "--method", "dirpole", "--gather", "cubemap", "--samples", "0",
                                "--out", "o"], "--samples: samples: must be an integer in [1, 65536], got 0"),
    ("render-cubemap-spacing", ["render", "thin_ring", "--method", "dirpole", "--gather", "cubemap", "--spacing", "1",
                                "--out", "o"], "--spacing: spacing: belongs to gather=dense"),
    ("command-unknown", ["frobnicate"], "sslpv-harness: command: unknown command 'frobnicate'"),
    ("target-nan", ["reference", "thin_ring", "--target", "nan"], "--target: target: must be a relative standard"),
    ("date-bad", ["nightly", "--date", "2026-13-45", "--out", "n", "--store", "n.sqlite"], "--date: date:"),
    ("budget-nan", ["report", "{store}", "--out", "r", "--budget-ms", "nan"], "--budget-ms: budget_ms: must be a "
                                                                             "finite number > 0, got 'nan'"),
    ("budget-negative", ["report", "{store}", "--out", "r", "--budget-ms", "-5"], "--budget-ms: budget_ms:"),
    ("export-run-999", ["export", "{store}", "--out", "x", "--run", "999"], "run_id: run 999 does not exist; "
                                                                                "pick one of 1"),
    ("export-scene-nosuch", ["export", "{store}", "--out", "x", "--scenes", "nosuch"], "scene: no configuration "
                                                                                         "is of scene 'nosuch'"),
    ("export-format", ["export", "{store}", "--out", "x", "--format", "txt"], "--format: format: invalid choice"),
    ("export-out-a-file", ["export", "{store}", "--out", "x.csv"], "--out: out: 'x.csv' names a file, but --out is a "
                                                                  "folder; write --out . --format csv"),
    ("report-run-999", ["report", "{store}", "--out", "r", "--run", "999"], "run_id: run 999 does not exist"),
    ("out-is-a-file", SWEEP + ["--out", "afile.txt"], "afile.txt: output: exists and is not a folder"),
    ("out-in-proc", SWEEP + ["--out", "/proc/sslpv/out"], "/proc/sslpv/out: output: /proc"),
    ("out-under-a-file", ["export", "{store}", "--out", "afile.txt/x"], "output: cannot be created: "),
    ("config-and-flags", ["sweep", "--config", "s.json", "--grid", "8"], "--grid: grid: cannot be combined with "
                                                                          "--config"),
]


@pytest.mark.parametrize("argv,needle", [c[1:] for c in CLI_CASES], ids=[c[0] for c in CLI_CASES])
def test_bad_cli_value(cli, tmp_path, store, argv, needle):
    (tmp_path / "afile.txt").write_text("a user's file\n")
    argv = [str(store) if a == "{store}" else a for a in argv]
    cli(argv, needle)


def test_usage_errors_are_one_line_in_a_fresh_process(tmp_path):
    """argparse's own exit path (not main's) gives one line too: what a shell user sees."""
    for argv in (SWEEP + ["--workers", "0"], ["reference", "thin_ring", "--spp", "0"]):
        proc = subprocess.run([sys.executable, "-m", "harness.cli", *argv], cwd=tmp_path, capture_output=True,
                              text=True, env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"}, timeout=120)
        assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
        assert proc.stderr.startswith("error: --") and "must be an integer > 0" in proc.stderr



LIGHT_BUDGET_CASES = [
    ("mapping", ["--mappings", "diffusion,foo"], "--mapping: mapping: unknown mapping 'foo'"),
    ("outside", ["--outsides", "nowhere"], "--outside: outside: unknown outside 'nowhere'"),
    ("grids", ["--grids", "16,x"], "--grids: grids: '16,x' is not a comma-separated list of integers"),
    ("scene", ["--scenes", "nosuch"], "--scenes: scenes: unknown scene 'nosuch'"),
    ("merge", ["--merge", "nosuch.json"], "nosuch.json: file: cannot be read (No such file or directory)"),
]


@pytest.mark.parametrize("argv,needle", [c[1:] for c in LIGHT_BUDGET_CASES], ids=[c[0] for c in LIGHT_BUDGET_CASES])
def test_light_budget_benchmark_bad_values(tmp_path, argv, needle):
    """benchmarks/sslpv_light_budget.py checks every value before it renders or writes anything."""
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, str(REPO / "benchmarks" / "sslpv_light_budget.py"), "--part", "refine",
                           *argv, "--out", str(out)], cwd=tmp_path, capture_output=True, text=True,
                          env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"}, timeout=120)
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert proc.stderr.startswith("error: " + needle), proc.stderr
    assert not out.exists()

# --------------------------------------------------------------------------- outputs that are not ours

def test_sweep_refuses_a_users_folder_and_keeps_its_sweep_json(cli, tmp_path):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "sweep.json").write_text('{"my": "own notes"}\n')
    (mine / "notes.txt").write_text("precious\n")
    cli(SWEEP + ["--out", mine], mine, "output: is a non-empty folder that is not a sweep's")
    assert (mine / "sweep.json").read_text() == '{"my": "own notes"}\n'


def test_render_and_report_refuse_a_users_folder(cli, tmp_path, store):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("precious\n")
    cli(["render", "thin_ring", "--out", mine], mine, "output: is a non-empty folder that the harness did not write")
    cli(["report", store, "--out", mine], mine, "output: is a non-empty folder that the harness did not write")


def test_nightly_refuses_a_users_folder(cli, tmp_path):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "index.html").write_text("<p>my page</p>\n")
    cli(["nightly", "--out", mine, "--store", tmp_path / "n.sqlite"], mine, "is a non-empty folder that is not "
                                                                            "the nightly's reports folder")


@pytest.fixture
def readonly(tmp_path):
    """A folder this process cannot create files in (chmod 555; chattr +i when running as root)."""
    folder = tmp_path / "ro"
    folder.mkdir()
    (folder / "existing.txt").write_text("x\n")
    folder.chmod(0o555)
    undo = [lambda: folder.chmod(0o755)]
    try:
        (folder / "probe").touch()
        (folder / "probe").unlink()
        if subprocess.run(["chattr", "+i", str(folder)], capture_output=True).returncode == 0:
            undo.insert(0, lambda: subprocess.run(["chattr", "-i", str(folder)], check=True))
        else:
            pytest.skip("no way to make a read-only folder here (root without chattr)")
        try:
            (folder / "probe").touch()
            pytest.skip("the folder is still writable")
        except OSError:
            pass
    except OSError:
        pass
    yield folder
    for step in undo:
        step()


def test_outputs_in_a_readonly_folder(cli, tmp_path, store, readonly):
    cli(SWEEP + ["--out", readonly / "out"], readonly / "out", "output:", "is not writable")
    cli(["export", store, "--out", readonly / "x"], readonly / "x", "output:", "is not writable")
    cli(["report", store, "--out", readonly / "site"], readonly / "site", "output:", "is not writable")
    cli(["render", "thin_ring", "--out", readonly / "r"], readonly / "r", "output:", "is not writable")
    cli(SWEEP + ["--out", tmp_path / "s", "--store", readonly / "s.sqlite"], readonly / "s.sqlite",
        "is not writable")


# --------------------------------------------------------------------------- sweep configurations (--config)

def write_config(tmp_path, **change):
    data = {"scenes": ["thin_ring"], "params": {"N": [8], "steps": [4]}, "out": str(tmp_path / "s"), "store": "",
            "size": [64, 64], "kind": "sweep", "reference_target": None}
    data.update(change)
    path = tmp_path / "sweep.json"
    path.write_text(json.dumps(data))
    return path


CONFIG_CASES = [
    ("scenes-5", {"scenes": 5}, "scenes: must be a non-empty list of non-empty strings, got 5"),
    ("unknown-key", {"grid": [8]}, "grid: is not a known field"),
    ("param-type", {"params": {"N": ["x"]}}, 'params.N[0]: must be an integer, got "x"'),
    ("param-unknown", {"params": {"M": [8]}}, "params.M: is not a known field"),
    ("param-range", {"params": {"N": [1000]}}, "params.N: must be an integer in [4, 256]"),
    ("size-huge", {"size": [100000, 64]}, "size[0]: must be an integer in [1, 8192]"),
    ("scene-unknown", {"scenes": ["nosuch"]}, "scenes[0]: unknown scene 'nosuch'"),
    ("target-range", {"reference_target": 2.0}, "reference_target: must be a number in (0, 1)"),
]


@pytest.mark.parametrize("change,needle", [c[1:] for c in CONFIG_CASES], ids=[c[0] for c in CONFIG_CASES])
def test_bad_sweep_config(cli, tmp_path, change, needle):
    path = write_config(tmp_path, **change)
    cli(["sweep", "--config", path], path, needle)


def test_sweep_config_not_json_and_missing(cli, tmp_path):
    path = tmp_path / "sweep.json"
    path.write_text("{not json")
    cli(["sweep", "--config", path], path, "json: is not valid JSON")
    cli(["sweep", "--config", tmp_path / "none.json"], "none.json: file: does not exist")


# --------------------------------------------------------------------------- matrices

MATRIX = """scenes = ["thin_ring"]
size = [64, 64]
[params]
grid = [8]
steps = [4]
mapping = ["collision"]
[tolerance]
rel = 0.05
abs = 1e-4
"""

MATRIX_CASES = [
    ("size-one", MATRIX.replace("size = [64, 64]", "size = [64]"), "size: must be a list of 2 integers"),
    ("tolerance-string", 'tolerance = "loose"\n' + MATRIX.replace("[tolerance]\nrel = 0.05\nabs = 1e-4\n", ""),
     'tolerance: must be a table, got "loose"'),
    ("scenes-5", MATRIX.replace('scenes = ["thin_ring"]', "scenes = 5"), 'scenes: must be one of "all" or a non-empty list'),
    ("param-unknown", MATRIX.replace("grid = [8]", "colour = [1]"), "params.colour: is not a known field"),
    ("param-range", MATRIX.replace("grid = [8]", "grid = [1000]"), "params.grid: must be an integer in [4, 256]"),
    ("also-unknown", MATRIX + "[[also]]\ngridd = [8]\n", "also[0].gridd: is not a known field"),
    ("scene-unknown", MATRIX.replace('"thin_ring"', '"nosuch"'), "scenes[0]: unknown scene 'nosuch'"),
    ("tolerance-negative", MATRIX.replace("rel = 0.05", "rel = -1"), "tolerance.rel: must be a number >= 0"),
    ("not-toml", "scenes = [\n", "toml: is not valid TOML"),
]


@pytest.mark.parametrize("text,needle", [c[1:] for c in MATRIX_CASES], ids=[c[0] for c in MATRIX_CASES])
def test_bad_nightly_matrix(cli, tmp_path, text, needle):
    matrix = tmp_path / "m.toml"
    matrix.write_text(text)
    cli(["nightly", "--matrix", matrix, "--store", tmp_path / "n.sqlite", "--out", tmp_path / "n"], matrix, needle)


ACCURACY = (REPO / "baselines" / "accuracy_matrix.toml").read_text()


@pytest.mark.parametrize("text,needle", [
    (re.sub(r"scenes = \[[^\]]*\]", "scenes = 5", ACCURACY), "scenes: must be a non-empty list of non-empty"),
    (ACCURACY + "[tolerance.nosuch]\nrel = 0.1\n", "tolerance.nosuch: names no scene of the matrix"),
    (ACCURACY.replace("rel = 0.03", 'rel = "loose"'), 'tolerance.default.rel: must be a number >= 0, got "loose"'),
    (ACCURACY.replace("grid = [16, 32]", "grid = [16, 3200]"), "params.grid: must be an integer in [4, 256]"),
], ids=["scenes-5", "tolerance-scene", "tolerance-type", "param-range"])
def test_bad_accuracy_matrix(tmp_path, text, needle):
    from harness.regression.baselines import load_matrix

    path = tmp_path / "accuracy_matrix.toml"
    path.write_text(text)
    with pytest.raises(InputError) as info:
        load_matrix(path)
    assert "\n" not in str(info.value) and str(path) in str(info.value) and needle in str(info.value), info.value


# --------------------------------------------------------------------------- stores

def test_foreign_sqlite_is_refused_untouched(cli, tmp_path):
    other = tmp_path / "music.sqlite"
    db = sqlite3.connect(other)
    db.execute("CREATE TABLE songs (title TEXT)")
    db.execute("INSERT INTO songs VALUES ('a')")
    db.commit()
    db.close()
    cli(["export", other, "--out", tmp_path / "x"], other, "another program's SQLite database")
    cli(["report", other, "--out", tmp_path / "r"], other, "another program's SQLite database")
    cli(SWEEP + ["--out", tmp_path / "s", "--store", other], other, "another program's SQLite database")
    with sqlite3.connect(other) as db:
        assert db.execute("PRAGMA journal_mode").fetchone()[0] == "delete"
        assert [r[0] for r in db.execute("SELECT name FROM sqlite_master")] == ["songs"]


def test_corrupt_newer_and_folder_stores(cli, tmp_path, store):
    text = tmp_path / "notes.sqlite"
    text.write_text("not a database at all, but long enough to have a header of one hundred bytes ......\n" * 3)
    cli(["export", text, "--out", tmp_path / "x"], text, "file: is not an SQLite database")
    db = sqlite3.connect(store)
    db.execute("PRAGMA user_version = 99")
    db.commit()
    db.close()
    cli(["export", store, "--out", tmp_path / "x"], store, "schema: store schema v99 is newer")
    cli(["report", tmp_path / "nothing", "--out", tmp_path / "r"], "nothing: store: does not exist")


def test_corrupt_store_to_nightly_leaves_nothing(cli, tmp_path):
    bad = tmp_path / "nightly.sqlite"
    bad.write_text("garbage " * 40)
    matrix = tmp_path / "m.toml"
    matrix.write_text(MATRIX)
    cli(["nightly", "--matrix", matrix, "--store", bad, "--out", tmp_path / "n", "--date", "2026-11-20"], bad,
        "is not an SQLite database")
    assert not (tmp_path / "n").exists()


def test_store_in_a_readonly_folder_is_read(tmp_path, store, readonly):
    """Reading needs no write: export and report open a store read-only (the issue: 'not an SQLite database')."""
    import shutil

    subprocess.run(["chattr", "-i", str(readonly)], capture_output=True)
    readonly.chmod(0o755)
    shutil.copy(store, readonly / "store.sqlite")
    readonly.chmod(0o555)
    subprocess.run(["chattr", "+i", str(readonly)], capture_output=True)
    assert main(["export", str(readonly / "store.sqlite"), "--out", str(tmp_path / "x"), "--json"]) == 0
    assert len((tmp_path / "x" / "results.csv").read_text().splitlines()) == 3
    with pytest.raises(InputError, match=r"store.sqlite: folder: .* is not writable, and a store writes its journal"):
        Store(readonly / "store.sqlite")


# --------------------------------------------------------------------------- EXRs

def test_bad_exrs(cli, tmp_path):
    img = np.ones((8, 8, 3), np.float32)
    write_exr(tmp_path / "ref.exr", img)
    write_exr(tmp_path / "small.exr", np.ones((4, 4, 3), np.float32))
    nan = img.copy()
    nan[2, 3, 1] = np.nan
    write_exr(tmp_path / "nan.exr", nan)
    (tmp_path / "text.exr").write_text("not an image\n")
    cli(["compare", tmp_path / "ref.exr", tmp_path / "nan.exr"], "nan.exr: rgb: contains 1 NaN or Inf values")
    cli(["compare", tmp_path / "ref.exr", tmp_path / "small.exr"], "small.exr: size: is 4x4")
    cli(["compare", tmp_path / "ref.exr", tmp_path / "text.exr"], "text.exr: file: not a readable OpenEXR file")
    cli(["compare", tmp_path / "ref.exr", tmp_path / "none.exr"], "none.exr: file: does not exist")


@pytest.mark.parametrize("argv,needle", [
    (["--against", "no-such-commit"], "--against: against: git has no sslpv_gl/shaders/propagate.comp at "
                                      "'no-such-commit'"),
    (["--against", "HEAD", "--N", "64,x"], "--N: N: '64,x' is not a comma-separated list of integers"),
], ids=["commit", "grids"])
def test_propagate_benchmark_bad_values(tmp_path, argv, needle):
    """benchmarks/bench_sslpv.py --against: one line, exit 2, before a GL context is made."""
    proc = subprocess.run([sys.executable, str(REPO / "benchmarks" / "bench_sslpv.py"), *argv], cwd=tmp_path,
                          capture_output=True, text=True, env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"},
                          timeout=120)
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert proc.stderr.startswith("error: " + needle), proc.stderr


def test_sweep_benchmark_summarize_missing(tmp_path):
    """benchmarks/bench_sweep.py --summarize: a folder without both stores is one line, exit 2."""
    proc = subprocess.run([sys.executable, str(REPO / "benchmarks" / "bench_sweep.py"), "--summarize", str(tmp_path)],
                          cwd=tmp_path, capture_output=True, text=True,
                          env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"}, timeout=120)
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert proc.stderr.startswith(f"error: {tmp_path / 'per_config' / 'store.sqlite'}: file: does not exist"), \
        proc.stderr
