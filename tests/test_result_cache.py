"""The result cache (``harness.runs.cache``, ``harness.runs.fingerprint``): exact invalidation, reuse, bad entries.

* **Invalidation is exact.** In a copy of the packages, a constant edited in one shader
  changes the code fingerprint of exactly the methods that load it; a docstring, a comment
  or the report's code changes none; a statement in a shared module changes every method
  that imports it.
* **Reuse.** A second sweep of the same configurations renders nothing and records the
  same metrics, its rows naming the cache entry; ``--no-cache`` renders again; a changed
  calibrated mapping file or another GL renderer string is another key.
* **Metric rows.** A second sweep takes the rows kept in the entry and measures nothing;
  when the metric code's hash differs (a metric was edited) or the kept rows are unreadable,
  the rows are measured again from the cached images, equal, and kept under the new hash.
  An edit in a metric module changes that hash, an edit in a shader does not.
* **Bad input.** A cache folder that is not ours is one line and exit 2, untouched; a corrupt
  entry and an entry of another key format are rendered again, with one line saying why.
"""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from harness.cli import main
from harness.runs.cache import CACHE_MARKER, KEY_FORMAT, ResultCache, result_key
from harness.runs.fingerprint import ENTRIES, method_shaders
from harness.store import Store

REPO = Path(__file__).resolve().parent.parent
SWEEP = ["sweep", "--scenes", "thin_ring", "--grid", "8", "--steps", "2,4", "--workers", "1", "--size", "small",
         "--json"]


# --------------------------------------------------------------------------- fingerprints

@pytest.fixture(scope="module")
def tree(tmp_path_factory):
    """A copy of the three packages, in which files can be edited and fingerprinted in a fresh process."""
    root = tmp_path_factory.mktemp("tree")
    for pkg in ("harness", "sslpv_gl", "dipole_gl"):
        shutil.copytree(REPO / pkg, root / pkg, ignore=shutil.ignore_patterns("__pycache__"))
    return root


def _fingerprints(root):
    code = ("import json; from harness.runs.fingerprint import method_fingerprint as f; "
            "print(json.dumps({m: f(m)['code'] for m in ('sslpv', 'dipole', 'dirpole')}))")
    out = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True, check=True,
                         env={"PATH": "/usr/bin:/bin", "PYTHONPATH": str(root)})
    return json.loads(out.stdout)


def _edit(root, rel, old, new):
    p = root / rel
    text = p.read_text()
    assert text.count(old) == 1, (rel, old)
    p.write_text(text.replace(old, new))
    return lambda: p.write_text(text)


def _before_after(root, rel, old, new, fingerprint):
    """``fingerprint(root)`` before and after one edit of ``rel`` (undone afterwards)."""
    before = fingerprint(root)
    restore = _edit(root, rel, old, new)
    try:
        return before, fingerprint(root)
    finally:
        restore()


@pytest.mark.parametrize("rel, old, new, changed", [
    # a constant in SSLPV's shading shader: SSLPV only (the rivals never load shade.frag)
    ("sslpv_gl/shaders/shade.frag", "out_sub  = vec4(sub, 1.0);", "out_sub  = vec4(sub * 1.01, 1.0);", {"sslpv"}),
    # the rivals' dense gather: both dipole methods, not SSLPV
    ("dipole_gl/shaders/gather_dense.comp", "2.0 * PI * r", "2.0 * PI * r * 1.01", {"dipole", "dirpole"}),
    # a GLSL include both methods load
    ("sslpv_gl/shaders/optics.glsl", "float fresnel_transmittance(", "float  fresnel_transmittance(", set()),  # space
    # Python: a statement in a module every method imports
    ("harness/errors.py", 'text += f"; {fix}"', 'text += f"; fix: {fix}"', {"sslpv", "dipole", "dirpole"}),
    # a docstring and a comment in the renderer, and the report's code: nothing
    ("sslpv_gl/renderer.py", "Run a public method with this renderer's context current",
     "Run a public method with the context current", set()),
    ("sslpv_gl/propagate.py", "# ping-pong", "# swap the grids", set()),
    ("harness/report/build.py", "import math\n", "import math\nimport os as _os  # noqa\n", set()),
])
def test_an_edit_rekeys_exactly_the_methods_that_use_it(tree, rel, old, new, changed):
    before, after = _before_after(tree, rel, old, new, _fingerprints)
    assert {m for m in before if before[m] != after[m]} == changed


def _metrics_fingerprint(root):
    code = "from harness.runs.fingerprint import metrics_fingerprint as f; print(f())"
    return subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True, check=True,
                          env={"PATH": "/usr/bin:/bin", "PYTHONPATH": str(root)}).stdout.strip()


@pytest.mark.parametrize("rel, old, new, changed", [
    ("harness/metrics/registry.py", "def compute_all(", "def  compute_all(", False),            # blank space
    ("harness/metrics/colour_difference.py", "WHITE_PERCENTILE = 99.0", "WHITE_PERCENTILE = 99.5", True),
    ("harness/runs/worker.py", "rows = []", "rows = list()", True),
    ("sslpv_gl/shaders/shade.frag", "out_sub  = vec4(sub, 1.0);", "out_sub  = vec4(sub * 1.01, 1.0);", False),
])
def test_the_metric_code_hash_follows_the_metric_code_only(tree, rel, old, new, changed):
    before, after = _before_after(tree, rel, old, new, _metrics_fingerprint)
    assert (before != after) == changed


def test_every_shader_is_found():
    """Each package's stage files belong to a method (a run-time built name would be missed)."""
    found = {p.name for m in ENTRIES for p in method_shaders(m)}
    on_disk = {p.name for d in ("sslpv_gl/shaders", "dipole_gl/shaders") for p in (REPO / d).iterdir()}
    assert found == on_disk
    assert "shade.frag" not in {p.name for p in method_shaders("dipole")}


def test_key_follows_every_part(tmp_path):
    base = dict(method="sslpv", scene_hash="s", params={"N": 8, "mapping": "collision"}, ref_hash="r",
                gl_renderer="llvmpipe")
    k = result_key(**base)
    for change in ({"scene_hash": "t"}, {"params": {"N": 16, "mapping": "collision"}}, {"ref_hash": "q"},
                   {"gl_renderer": "NVIDIA H200"}, {"method": "dipole"}):
        assert result_key(**dict(base, **change)) != k, change
    cal = tmp_path / "cal.toml"
    committed = (REPO / "baselines" / "calibrated" / "diffusion" / "calibrated.toml").read_text()
    cal.write_text(committed)
    k1 = result_key(**dict(base, params={"mapping": f"calibrated:{cal}"}))
    cal.write_text(committed + "\n# fitted again\n")            # the same path, another file
    assert result_key(**dict(base, params={"mapping": f"calibrated:{cal}"})) != k1


# --------------------------------------------------------------------------- sweeps through the cache

def _sweep(out, *extra):
    """One sweep through ``harness.cli.main`` -> (its JSON summary, its stderr)."""
    import contextlib
    import io

    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        code = main(SWEEP + ["--out", str(out), *extra])
    assert code == 0, stderr.getvalue()
    return json.loads(stdout.getvalue()), stderr.getvalue()


def _metrics(store):
    with Store(store) as st:
        rows = {(c["config_key"], img, m): v["value"] for c in st.configs()
                for img, ms in c["metrics"].items() for m, v in ms.items()}
        cached = {c["config_key"]: c["cached_from"] for c in st.configs()}
        dirs = {c["config_key"]: c["render_dir"] for c in st.configs()}
    return rows, cached, dirs


@pytest.fixture(scope="module")
def first(tmp_path_factory):
    """One sweep into an empty cache of the module's: what the tests below reuse."""
    root = tmp_path_factory.mktemp("first")
    mp = pytest.MonkeyPatch()
    mp.setenv("SSLPV_RESULT_CACHE", str(root / "cache"))
    try:
        summary, _ = _sweep(root / "a")
    finally:
        mp.undo()
    return root, summary


@pytest.mark.gl
def test_a_second_sweep_renders_nothing(first, tmp_path, monkeypatch):
    root, summary = first
    assert summary["reused"] == 0 and summary["ok"] == 2
    monkeypatch.setenv("SSLPV_RESULT_CACHE", str(root / "cache"))
    second, _ = _sweep(tmp_path / "b")
    assert second["reused"] == 2 and second["groups"] == 0
    m1, c1, d1 = _metrics(root / "a" / "store.sqlite")
    m2, c2, d2 = _metrics(tmp_path / "b" / "store.sqlite")
    assert m1 == m2 and len(m1) > 10
    assert set(c1.values()) == {None} and all(c2.values())
    for key, folder in d2.items():                   # the reused render folders hold the same images
        for f in ("subsurface.exr", "full.exr"):
            assert (Path(folder) / f).read_bytes() == (Path(d1[key]) / f).read_bytes()
    third, _ = _sweep(tmp_path / "c", "--no-cache")
    assert third["reused"] == 0 and third["groups"] == 1
    assert _metrics(tmp_path / "c" / "store.sqlite")[0] == m1


@pytest.mark.gl
def test_metric_rows_are_kept_and_measured_again_when_their_code_changes(first, tmp_path, monkeypatch):
    from harness.runs import cache as cache_mod, worker

    root, _ = first
    m1 = _metrics(root / "a" / "store.sqlite")[0]
    shutil.copytree(root / "cache", tmp_path / "cache")
    monkeypatch.setenv("SSLPV_RESULT_CACHE", str(tmp_path / "cache"))
    entries = sorted(p for p in (tmp_path / "cache").glob("??/*") if p.is_dir())
    assert all((e / "metrics.json").is_file() for e in entries) and len(entries) == 2

    measured = []
    real = worker.measure
    monkeypatch.setattr(worker, "measure", lambda *a: measured.append(1) or real(*a))
    _sweep(tmp_path / "b")                                         # kept rows: nothing measured
    assert measured == [] and _metrics(tmp_path / "b" / "store.sqlite")[0] == m1

    monkeypatch.setattr(cache_mod, "metrics_fingerprint", lambda: "another metric code")
    _sweep(tmp_path / "c")                                         # a metric edited: measured again, equal
    assert len(measured) == 2 and _metrics(tmp_path / "c" / "store.sqlite")[0] == m1
    assert {json.loads((e / "metrics.json").read_text())["metrics_code"] for e in entries} == {"another metric code"}

    (entries[0] / "metrics.json").write_text("{not json")          # unreadable rows: measured again
    _sweep(tmp_path / "d")
    assert len(measured) == 3 and _metrics(tmp_path / "d" / "store.sqlite")[0] == m1


@pytest.mark.gl
def test_corrupt_and_foreign_entries_are_rendered_again(first, tmp_path, monkeypatch):
    root, _ = first
    shutil.copytree(root / "cache", tmp_path / "cache")
    monkeypatch.setenv("SSLPV_RESULT_CACHE", str(tmp_path / "cache"))
    cache = ResultCache()
    entries = sorted(p for p in cache.root.glob("??/*") if p.is_dir())
    assert len(entries) == 2
    data = (entries[0] / "images.npz").read_bytes()
    (entries[0] / "images.npz").write_bytes(data[: len(data) // 2])           # truncated: its hash fails
    info = json.loads((entries[1] / "result.json").read_text())
    info["key_format"] = KEY_FORMAT + 1                                         # another key format
    (entries[1] / "result.json").write_text(json.dumps(info))
    out, err = _sweep(tmp_path / "b", "--no-progress")                         # warnings print all the same
    assert out["reused"] == 0 and out["ok"] == 2
    lines = [line for line in err.splitlines() if "result cache: entry" in line]
    assert len(lines) == 2, err
    assert any("do not match their recorded hash" in line for line in lines)
    assert any(f"key format {KEY_FORMAT + 1}" in line for line in lines)
    fresh = ResultCache()                                                       # both were stored again
    assert all(fresh.get(e.name) is not None for e in entries)


def test_a_cache_of_another_key_format_is_emptied_with_one_line(tmp_path):
    root = tmp_path / "rc"
    (root / "ab" / ("ab" + "0" * 62)).mkdir(parents=True)
    (root / CACHE_MARKER).write_text(json.dumps({"key_format": KEY_FORMAT - 1}))
    lines = []
    ResultCache(root, log=lines.append)
    assert len(lines) == 1 and f"key format {KEY_FORMAT - 1}" in lines[0]
    assert not (root / "ab").exists()


def test_a_folder_that_is_not_a_cache_is_refused_untouched(tmp_path, capsys, monkeypatch):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("keep me")
    monkeypatch.setenv("SSLPV_RESULT_CACHE", str(mine))
    code = main(SWEEP + ["--out", str(tmp_path / "a"), "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert err[0].startswith(f"error: {mine}: cache: is a non-empty folder that is not a result cache")
    assert sorted(p.name for p in mine.iterdir()) == ["thesis.tex"] and not (tmp_path / "a").exists()


def test_prune_keeps_the_newest_under_the_limit(tmp_path):
    cache = ResultCache(tmp_path / "rc", limit_bytes=1)
    res = {"status": "ok", "images": {"subsurface": np.ones((4, 4, 3)), "full": np.ones((4, 4, 3))},
           "mask": np.ones((4, 4), bool), "timings": {}, "gl_renderer": "x"}
    for i in range(3):
        cache.put(f"{i:02d}" + "f" * 62, res)
    size = sum(f.stat().st_size for f in (cache.root / "02").rglob("*") if f.is_file())
    cache.limit = size
    cache.prune()
    assert [p.name[:2] for p in sorted(cache.root.glob("??/*"))] == ["02"]
    assert cache.get("02" + "f" * 62)["images"]["full"].shape == (4, 4, 3)


@pytest.mark.parametrize("value", ["x", "0", "-5"])
def test_a_bad_cache_limit_is_one_line(tmp_path, capsys, monkeypatch, value):
    monkeypatch.setenv("SSLPV_RESULT_CACHE_LIMIT_MB", value)
    code = main(SWEEP + ["--out", str(tmp_path / "a"), "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert err[0] == f"error: SSLPV_RESULT_CACHE_LIMIT_MB: limit: is {value!r}; give a size in MB above 0"
    assert not (tmp_path / "a").exists()
