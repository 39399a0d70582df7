"""``sslpv-harness study`` end to end on a tiny study (two small scenes, 12 configurations each; once cold and once warm
through the sweep), and its bad input.

The end-to-end tests share ONE cold study run and ONE warm rerun (a module fixture, its own result
cache under the test's tmp folder). They check the results table against an independent NumPy
recomputation from the paths in a row (1e-9), the Parquet file against the CSV, the provenance, the
headline table's rows, that a warm rerun renders nothing and writes the same table, and the page in
headless Chromium (skipped without it). The bad-input tests need no GL: each is one line on stderr,
exit 2, and nothing written.
"""

import csv
import io
import json
import math
import os
import re
import shutil
import subprocess

import numpy as np
import pytest

from harness.cli import main
from harness.paths import REPO

TINY = """
title = "tiny study"
scenes = ["thin_ring", "wide_slab"]
size = "small"
metrics = ["relmse", "flip", "energy_ratio"]
significance = ["relmse", "energy_ratio"]
[budget]
grid = 16
steps = [4, 8, "steady"]
[[products]]
grid = [8, 16]
steps = [4, 8]
mapping = ["collision", "diffusion"]
[[products]]
grid = [16]
steps = ["steady"]
mapping = ["diffusion"]
skip = [0]
[[products]]
grid = [16]
steps = [4, 8]
mapping = ["collision"]
outside = ["interior"]
[[products]]
method = "dipole"
gather = ["dense"]
"""


def _study(tmp, text=TINY, name="study.toml"):
    p = tmp / name
    p.write_text(text)
    return p


# --------------------------------------------------------------------------- bad input (no GL)

def _one_line(capsys, args, tmp):
    before = sorted(str(p) for p in tmp.rglob("*"))
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: "), err
    assert sorted(str(p) for p in tmp.rglob("*")) == before, "something was written"
    return err[0]


@pytest.mark.parametrize("edit, field, words", [
    (lambda t: t + "\n[[products]\n", "toml", "is not valid TOML"),
    (lambda t: t.replace('title = "tiny study"', 'title = "x"\ncolour = 1'), "colour", "not a known field"),
    (lambda t: t.replace('"thin_ring", "wide_slab"', '"thin_ring", "no_such_scene"'), "scenes[1]",
     "unknown scene 'no_such_scene'"),
    (lambda t: t.replace('method = "dipole"', 'method = "photon_beams"'), "products[3].method",
     "unknown method 'photon_beams'"),
    (lambda t: t.replace('mapping = ["collision", "diffusion"]', 'mapping = ["collision"]\nwobble = [1]'),
     "products[0].wobble", "not a known field"),
    (lambda t: t.replace('mapping = ["collision", "diffusion"]', 'mapping = ["collison"]'),
     "products[0].mapping", "collison"),
    (lambda t: t.replace('metrics = ["relmse", "flip", "energy_ratio"]', 'metrics = ["relmse", "psnr"]'),
     "metrics[1]", "psnr"),
    (lambda t: t.replace('title = "tiny study"', 'title = "x"\ncalibrations = ["no/such/calibrated.toml"]'),
     "calibrations[0]", "does not exist"),
    (lambda t: t + '\n[[twins]]\nindex_matched = "skin_torus"\ndielectric = "skin_torus_dielectric"\n',
     "twins[0].index_matched", "not one of the study's scenes"),
])
def test_bad_study_file_is_one_line(tmp_path, capsys, edit, field, words):
    study = _study(tmp_path, edit(TINY))
    line = _one_line(capsys, ["study", str(study), "--out", str(tmp_path / "out")], tmp_path)
    assert f"{study}: {field}: " in line and words in line, line
    assert not (tmp_path / "out").exists()


def test_missing_study_file_and_bad_size(tmp_path, capsys):
    line = _one_line(capsys, ["study", str(tmp_path / "none.toml"), "--out", str(tmp_path / "o")], tmp_path)
    assert "none.toml: file: does not exist" in line
    study = _study(tmp_path)
    line = _one_line(capsys, ["study", str(study), "--out", str(tmp_path / "o"), "--size", "huge"], tmp_path)
    assert line.startswith("error: --size: size:")


def test_out_that_is_not_ours_is_refused(tmp_path, capsys):
    study = _study(tmp_path)
    mine = tmp_path / "Documents"
    mine.mkdir()
    (mine / "thesis.tex").write_text("mine")
    line = _one_line(capsys, ["study", str(study), "--out", str(mine)], tmp_path)
    assert f"{mine}: output: is a non-empty folder that is not a study's folder" in line
    assert (mine / "thesis.tex").read_text() == "mine"
    line = _one_line(capsys, ["study", str(study)], tmp_path)      # no --out and no --docs
    assert line.startswith("error: --out: out: is required")


@pytest.mark.parametrize("name", ["default", "full"])
def test_committed_studies_are_valid(name):
    from harness.scene import list_scenes
    from harness.study.spec import load_study

    s = load_study(REPO / "studies" / f"{name}.toml")
    assert s["scenes"] == list_scenes() and s["size"] == "small"
    assert {c["family"] for c in s["calibrations"]} >= {"diffusion", "collision"}
    assert {c["family"] for c in s["calibrations"]} <= {"diffusion", "collision", "transport"}
    assert {p.get("method", "sslpv") for p in s["params"]} == {"sslpv", "dipole", "dirpole"}


# --------------------------------------------------------------------------- end to end (GL)

def _recompute(row):
    """relMSE and the energy ratio of one CSV row with plain NumPy from its paths (not harness.metrics)."""
    import OpenEXR

    def rgb(path, extra=False):
        with OpenEXR.File(str(path), separate_channels=True) as f:
            ch = {k: np.asarray(v.pixels, dtype=np.float64) for k, v in f.channels().items()}
        return np.stack([ch["R"], ch["G"], ch["B"]], axis=-1), ch

    x, _ = rgb(f"{row['render_dir']}/subsurface.exr")
    y, ch = rgb(f"{row['reference_dir']}/subsurface.exr")
    cov = ch.get("mask")
    if cov is None:
        cov = rgb(f"{row['reference_dir']}/mask.exr")[0][..., 0]
    m = cov >= 0.999                                   # fully covered pixels only (the sweep's rule)
    relmse = float(np.mean([np.mean((x[..., c][m] - y[..., c][m]) ** 2 / (y[..., c][m] ** 2 + 1e-2))
                            for c in range(3)]))
    energy = float(np.mean([x[..., c][m].sum() / y[..., c][m].sum() for c in range(3)]))
    return relmse, energy


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """One cold study, a warm rerun into the same folder (served as it is), and a run into a new folder
    (every configuration served by the result cache), with a result cache of their own."""
    tmp = tmp_path_factory.mktemp("study")
    study = _study(tmp)
    out, out2 = tmp / "out", tmp / "out2"
    old = os.environ.get("SSLPV_RESULT_CACHE")
    os.environ["SSLPV_RESULT_CACHE"] = str(tmp / "cache")
    try:
        from harness.study.run import run_study

        cold = run_study(study, out, progress=False)
        csv_cold = (out / "results.csv").read_text()
        mtimes = {p: p.stat().st_mtime_ns for p in out.iterdir()}
        warm = run_study(study, out, progress=False)
        served = run_study(study, out2, progress=False)
    finally:
        if old is None:
            os.environ.pop("SSLPV_RESULT_CACHE", None)
        else:
            os.environ["SSLPV_RESULT_CACHE"] = old
    built = cold.pop("_built")
    served.pop("_built", None)
    return {"cold": cold, "warm": warm, "served": served, "out": out, "out2": out2, "csv_cold": csv_cold,
            "built": built, "study": study, "mtimes": mtimes}


@pytest.mark.gl
@pytest.mark.slow
def test_csv_row_recomputes_with_numpy(runs):
    from harness.study.table import read_csv

    rows = read_csv(runs["out"] / "results.csv")
    assert len(rows) == runs["cold"]["configurations"] == 2 * 12
    picked = [next(r for r in rows if r["method"] == "sslpv" and r["K"] == "8"),
              next(r for r in rows if r["method"] == "dipole")]
    for row in picked:
        relmse, energy = _recompute(row)
        assert math.isclose(float(row["subsurface_relmse"]), relmse, rel_tol=1e-9, abs_tol=0), (row["setting"], relmse)
        assert math.isclose(float(row["subsurface_energy_ratio"]), energy, rel_tol=1e-9, abs_tol=0), \
            (row["setting"], energy)
        assert float(row["subsurface_relmse_floor"]) > 0 and float(row["frame_ms"]) > 0


@pytest.mark.gl
@pytest.mark.slow
def test_parquet_and_provenance(runs):
    import hashlib

    import pyarrow.parquet as pq

    from harness.study.table import read_csv

    out = runs["out"]
    rows = read_csv(out / "results.csv")
    table = pq.read_table(out / "results.parquet").to_pylist()
    assert [r["setting"] for r in table] == [r["setting"] for r in rows]
    assert list(table[0]) == list(rows[0])
    for a, b in zip(table, rows):
        assert repr(a["subsurface_relmse"]) == b["subsurface_relmse"]
    info = json.loads((out / "study.json").read_text())
    assert re.fullmatch(r"[0-9a-f]{40}", info["commit"]) and info["gl_renderer"]
    assert info["versions"]["numpy"] == np.__version__
    assert info["study_text"] == runs["study"].read_text()
    ref = info["references"]["thin_ring"]
    assert ref["sha256"]["subsurface.exr"] == hashlib.sha256(
        (REPO / "baselines" / "refs" / "thin_ring" / "subsurface.exr").read_bytes()).hexdigest()
    assert ref["median_rel_se_subsurface"] > 0 and ref["K"] >= 2
    assert not any(".sslpv-tmp" in p.name or "sslpv-tmp" in p.name for p in out.rglob("*"))


@pytest.mark.gl
@pytest.mark.slow
def test_warm_rerun_renders_nothing(runs):
    cold, warm, served = runs["cold"], runs["warm"], runs["served"]
    assert cold["rendered"] == cold["configurations"] and cold["reused"] == 0 and not cold["unchanged"]
    # the same folder, nothing changed: served as it is, nothing rendered or rewritten
    assert warm["unchanged"] and warm["rendered"] == 0 and warm["reused"] == warm["configurations"] == 24
    assert {p: p.stat().st_mtime_ns for p in runs["out"].iterdir()} == runs["mtimes"]
    # a new folder: the sweep serves every configuration from the result cache and measures it again
    assert not served["unchanged"] and served["rendered"] == 0 and served["reused"] == 24

    def metrics(text):
        rows = [dict(r) for r in csv.DictReader(io.StringIO(text))]
        return [{k: v for k, v in r.items() if k not in ("cached", "render_dir")} for r in rows]

    assert metrics((runs["out2"] / "results.csv").read_text()) == metrics(runs["csv_cold"])


@pytest.mark.gl
def test_a_changed_study_is_not_served_as_it_is(tmp_path):
    from harness.study.memo import inputs_key
    from harness.study.run import TEMPLATES
    from harness.study.spec import load_study

    a = load_study(_study(tmp_path, TINY, "a.toml"))
    b = load_study(_study(tmp_path, TINY.replace("steps = [4, 8]\n", "steps = [4, 16]\n", 1), "b.toml"))
    c = load_study(_study(tmp_path, TINY.replace('significance = ["relmse", "energy_ratio"]',
                                                 'significance = ["relmse"]'), "c.toml"))
    keys = {inputs_key(s, TEMPLATES) for s in (a, b, c)}
    assert len(keys) == 3 and inputs_key(a, TEMPLATES) == inputs_key(load_study(tmp_path / "a.toml"), TEMPLATES)


@pytest.mark.gl
def test_a_changed_data_file_is_not_served_as_it_is(tmp_path, monkeypatch):
    """The data files a study reads beside its renders (a scene's lighting-twin verdicts, the selection of the
    best calibration) are part of its key: a new or changed one writes the study again."""
    from harness.study import memo, target, twin
    from harness.study.run import TEMPLATES
    from harness.study.spec import load_study

    study = load_study(_study(tmp_path, TINY, "a.toml"))
    scene = study["scenes"][0]
    monkeypatch.setattr(twin, "VERDICTS", tmp_path / "twin")
    monkeypatch.setattr(target, "SELECTION", tmp_path / "selection.json")
    before = memo.inputs_key(study, TEMPLATES)
    (tmp_path / "twin").mkdir()
    (tmp_path / "twin" / f"{scene}.json").write_text("{}")
    added = memo.inputs_key(study, TEMPLATES)
    (tmp_path / "twin" / f"{scene}.json").write_text('{"grid": 32}')
    changed = memo.inputs_key(study, TEMPLATES)
    (tmp_path / "selection.json").write_text("{}")
    last = memo.inputs_key(study, TEMPLATES)
    assert None not in (before, last) and len({before, added, changed, last}) == 4
    (tmp_path / "twin" / "not_a_scene_of_the_study.json").write_text("{}")
    assert memo.inputs_key(study, TEMPLATES) == last


@pytest.mark.gl
@pytest.mark.slow
def test_headline_table_and_limits(runs):
    head, lims = runs["built"]["head"], runs["built"]["limits"]
    assert head["scenes"] == ["thin_ring", "wide_slab"]
    assert head["families"] == ["collision", "diffusion", "dipole dense + S1"]
    for scene in head["scenes"]:
        cells = head["overall"][scene]
        statuses = [c["status"] for c in cells.values()]
        assert statuses.count("best") == 1 and set(statuses) <= {"best", "tied", "worse", "better-in-part", "mixed"}
        best = min(cells.values(), key=lambda c: c["row"]["subsurface_relmse"])
        assert best["status"] == "best"
        for c in cells.values():                     # SSLPV at the budget's N only
            assert c["row"]["method"] != "sslpv" or c["row"]["N"] == 16
        s = lims[scene]["steps"]
        if s["measured"]:
            assert s["relmse"]["steady"] == pytest.approx(next(
                r["subsurface_relmse"] for r in runs["built"]["rows"] if r["setting"] == s["steady"]
                and r["scene"] == scene))
        assert lims[scene]["boundary"]["measured"] is False
    html = (runs["out"] / "index.html").read_text()
    body = html.split('<table id="headline">', 1)[1].split("</table>", 1)[0].split("<tbody>", 1)[1]
    assert body.count("<tr>") == 2
    for scene in head["scenes"]:                 # each cell shows its values and its setting
        for c in head["overall"][scene].values():
            r = c["row"]
            assert f"{r['subsurface_relmse']:.3g} / {r['subsurface_flip']:.3g} / {r['subsurface_energy_ratio']:.3g}" \
                in body and r["setting"] in body
    assert "built-in method" not in html
    # the extension family has its own table, against its base, and stays out of the headline
    ext = runs["built"]["extensions"]
    assert [f["family"] for f in ext["families"]] == ["collision + interior"]
    fam = ext["families"][0]
    for scene in head["scenes"]:
        c = fam["cells"][scene]
        rel = {r["setting"]: r["subsurface_relmse"] for r in runs["built"]["rows"] if r["scene"] == scene}
        assert c["ratio"] == pytest.approx(rel[c["setting"]] / rel[c["base_setting"]])
        assert c["outcome"] in {"better", "worse", "≈", "mixed", "≈ (better in part)", "≈ (base better in part)"}
        assert "outside=interior" in c["setting"] and "outside" not in c["base_setting"]
    d = ext["default_outside"]
    assert d["outside"] == ("interior" if d["by_mode"]["interior"] < 1 else "vacuum")
    for scene in head["scenes"]:          # the limits' subject is a headline family's; its interior twin is beside it
        subject = lims[scene]["subject"]
        assert "outside=interior" not in subject
        modes = [m["outside"] for m in lims[scene]["outside"]["other_modes"]]
        assert modes == (["interior"] if subject in ("N16-K4-collision", "N16-K8-collision") else []), (subject, modes)
    assert "The extensions beside the published method" in html and "collision + interior" in html


CHROMIUM = next((shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome") if shutil.which(n)),
                None)


@pytest.mark.gl
@pytest.mark.slow
@pytest.mark.browser
@pytest.mark.skipif(CHROMIUM is None, reason="headless Chromium is not installed (apt-get install -y chromium)")
def test_page_in_headless_chromium(runs, tmp_path):
    """The page loads with no console message, every image decodes, the headline has one row per scene."""
    page = runs["out"] / "index.html"
    probe = tmp_path / "probe.html"
    probe.write_text(page.read_text().replace("</body>", """<script>
window.addEventListener("load", function () {
  var imgs = Array.prototype.slice.call(document.images);
  document.body.dataset.images = imgs.length;
  document.body.dataset.broken = imgs.filter(function (i) { return !(i.complete && i.naturalWidth > 0); }).length;
  document.body.dataset.rows = document.querySelectorAll("#headline tbody tr").length;
});
</script></body>""").replace('src="figures/', f'src="{page.parent.as_uri()}/figures/'))
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-extensions",
           "--enable-logging=stderr", "--v=0", "--virtual-time-budget=10000", f"--user-data-dir={tmp_path / 'p'}",
           "--allow-file-access-from-files", "--dump-dom", probe.as_uri()]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    console = [ln for ln in proc.stderr.splitlines() if ":CONSOLE" in ln]
    assert console == [], console
    attrs = dict(re.findall(r'data-(\w+)="(\d+)"', proc.stdout.split("<body", 1)[1].split(">", 1)[0]))
    assert attrs.get("rows") == "2" and int(attrs.get("images", 0)) >= 5 and attrs.get("broken") == "0", attrs


@pytest.mark.gl
@pytest.mark.slow
def test_docs_page_from_the_study(runs, tmp_path):
    from harness.study.docs import write_docs

    doc = tmp_path / "docs" / "results.md"
    written = write_docs(runs["built"], runs["out"], doc=doc)
    text = doc.read_text()
    assert text.count("\n| thin_ring |") == 1 and text.count("\n| wide_slab |") == 1
    assert runs["built"]["info"]["commit"] in text and "sslpv-harness study" in text
    for name in ("pareto", "refine_k", "refine_n"):
        assert (tmp_path / "docs" / "figures" / f"results_{name}.svg").is_file()
        assert f"figures/results_{name}.png" in text
    assert str(doc) in written
    assert "## The extensions beside the published method" in text and "\n| collision + interior | collision |" in text
    # the extensions' outside treatment, committed beside this page (not into the repository's baselines)
    choice = tmp_path / "docs" / "outside.json"
    assert str(choice) in written
    assert json.loads(choice.read_text())["outside"] == runs["built"]["extensions"]["default_outside"]["outside"]
    assert "That choice is committed to" in text
    # the calibration target: this study does not render the committed best calibration, and says so
    assert "## The calibration target" in text and "The calibration target is not judged:" in text
    assert "<h2>The calibration target</h2>" in (runs["out"] / "index.html").read_text()


def test_a_study_killed_in_its_first_sweep_is_ours(tmp_path, capsys):
    """The folder of a study killed before its marker was written holds only its sweep: it is resumed, not
    refused; a folder with anything else is refused."""
    from harness.errors import InputError
    from harness.io.outputs import SWEEP_MARKER
    from harness.study.run import check_study_folder

    out = tmp_path / "killed"
    (out / "sweep").mkdir(parents=True)
    (out / "sweep" / SWEEP_MARKER).touch()
    check_study_folder(out)
    other = tmp_path / "other"
    (other / "sweep").mkdir(parents=True)
    with pytest.raises(InputError, match="not a study's folder"):
        check_study_folder(other)


# --------------------------------------------------------------------------- FLIP judged by resampling (no GL)

class _StubImages:
    """Images by name, in place of render folders and a reference folder."""

    def __init__(self, renders, ref):
        self.renders, self.ref = renders, ref

    def render(self, d):
        return self.renders[d]

    def reference(self, d, shape):
        return self.ref


def _flip_cells(other_scale):
    from harness.study.headline import judge_cells

    rng = np.random.default_rng(3)
    y = 0.2 + rng.random((24, 24, 3))
    ref = {"subsurface": y, "se": 0.002 * y, "mask": np.ones((24, 24), bool), "K": 8}
    renders = {"best": y * 1.01, "other": y * other_scale}
    rows = {f: {"scene": "s", "setting": f, "render_dir": f, "reference_dir": "ref",
                "subsurface_relmse": float(np.mean((renders[f] - y) ** 2 / (y ** 2 + 1e-2)))} for f in renders}
    return judge_cells([rows], "relmse", ["flip"], _StubImages(renders, ref))[0]


def test_flip_significance_is_judged_by_resampling():
    """A family far from the best in FLIP is worse beyond noise, by resampling; the same image is tied."""
    far = _flip_cells(1.6)
    assert far["best"]["status"] == "best"
    assert far["other"]["status"] == "worse" and far["other"]["changes"][0]["method"] == "resampling"
    same = _flip_cells(1.01)
    assert same["other"]["status"] == "tied"


def test_flip_is_a_valid_significance_metric(tmp_path):
    from harness.study.spec import load_study

    s = load_study(_study(tmp_path, TINY.replace('significance = ["relmse", "energy_ratio"]',
                                                 'significance = ["relmse", "flip"]')))
    assert s["significance"] == ["relmse", "flip"]
