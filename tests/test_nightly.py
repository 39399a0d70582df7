"""Nightly job: two small nights end to end (``size = "small"``: each scene at its committed size, 64x64,
and the non-square wide_slab at 60x36; committed references); the verdict rules themselves are tested in
``test_verdict.py``."""

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from harness.cli import main
from harness.paths import REPO


MATRIX = """
scenes = ["thin_ring", "absorbing_sphere", "wide_slab"]
size = "small"
[params]
grid = [8, 16]
steps = [8]
mapping = ["collision"]
[tolerance]
rel = 0.05
abs = 1e-4
"""


def _render_dir(store, run_id, scene, n):
    from harness.store import Store

    with Store(store) as st:
        return next(Path(c["render_dir"]) for c in st.configs(run_id=run_id)
                    if c["scene"] == scene and c["params"]["N"] == n)


@pytest.mark.gl
@pytest.mark.slow
def test_two_nights_verdicts_and_index(tmp_path, capsys):
    from harness.io.images import read_exr, write_exr

    matrix = tmp_path / "matrix.toml"
    matrix.write_text(MATRIX)
    store, out = tmp_path / "nightly.sqlite", tmp_path / "nightly"
    args = ["nightly", "--matrix", str(matrix), "--store", str(store), "--out", str(out), "--json"]
    assert main(args + ["--date", "2026-11-20"]) == 0
    first = json.loads(capsys.readouterr().out)
    # the same renderer as the committed baseline images: nothing changed (N16-K8-collision has one)
    assert first["verdict"] == "unchanged" and first["configurations"] == 6 and first["changed_images"] == 0
    night1 = json.loads((out / "2026-11-20" / "night.json").read_text())
    assert night1["baseline_comparisons"] == 3 and night1["previous_comparisons"] == 0

    # Make last night's thin_ring N8 render the reference itself (tonight's real render must be a regression),
    # last night's absorbing_sphere N8 spoilt by strong per-pixel noise (tonight improves), and delete one folder.
    run1 = night1["run_id"]
    ring = _render_dir(store, run1, "thin_ring", 8)
    ref = read_exr(REPO / "baselines" / "refs" / "thin_ring" / "subsurface.exr")["rgb"]
    mask = read_exr(ring / "subsurface.exr")["mask"]
    for part in ("subsurface", "full"):
        write_exr(ring / f"{part}.exr", ref, extra={"mask": mask})
    sphere = _render_dir(store, run1, "absorbing_sphere", 8)
    z = np.random.default_rng(0).standard_normal((64, 64, 1))
    for part in ("subsurface", "full"):
        layers = read_exr(sphere / f"{part}.exr")
        write_exr(sphere / f"{part}.exr", layers["rgb"] * np.exp(0.5 * z - 0.125), extra={"mask": layers["mask"]})
    gone = _render_dir(store, run1, "absorbing_sphere", 16)
    shutil.rmtree(gone)

    assert main(args + ["--date", "2026-11-21"]) == 1
    second = json.loads(capsys.readouterr().out)
    assert second["verdict"] == "regression" and second["changed_images"] == 2
    night = json.loads((out / "2026-11-21" / "night.json").read_text())
    regs = {(c["scene"], c["metric"]) for c in night["regressions"]}
    assert ("thin_ring", "relmse") in regs and all(c["against"] == "previous-night" for c in night["regressions"])
    reg = next(c for c in night["regressions"] if c["metric"] == "relmse")
    assert reg["new"] > reg["old"] and reg["delta"] > reg["threshold"] > reg["tolerance"] and reg["se"] > 0
    # 5 pairs with last night (one folder gone) and 3 with the committed images, subsurface only
    # (index-matched: full = subsurface), 4 headline metrics each
    assert reg["z"] > reg["critical"] and reg["family"] == 32 and night["family"] == 32
    imps = {(c["scene"], c["metric"]) for c in night["improvements"]}
    assert ("absorbing_sphere", "relmse") in imps
    assert any(str(gone) in n and "gone" in n for n in night["notes"]), night["notes"]
    page = (out / "2026-11-21" / "index.html").read_text()
    assert "regression" in page and "improvement" in page and reg["config"] in page and "SE" in page
    assert str(gone) in page
    assert (out / "2026-11-21" / "report" / "index.html").is_file()
    assert list((out / "2026-11-21").glob("trend_*_relmse.svg"))
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


def test_judge_night_notes_renderer_scene_and_missing_renders(tmp_path):
    """The night's pairs without rendering: another GL renderer and a changed scene give one line each."""
    from harness.io.images import write_exr
    from harness.reference.committed import committed_reference
    from harness.regression.accuracy import small_scene
    from harness.regression.nightly import judge_night
    from harness.store import Store
    from sslpv_gl.params import SSLPVParams

    scene = small_scene("thin_ring")
    img = np.full((64, 64, 3), 0.2, np.float32)
    mask = np.ones((64, 64), np.float32)

    def render_dir(name):
        d = tmp_path / name
        d.mkdir()
        for part in ("subsurface", "full"):
            write_exr(d / f"{part}.exr", img, extra={"mask": mask})
        return str(d)

    p8, p4 = SSLPVParams(N=8, steps=8).as_dict(), SSLPVParams(N=4, steps=8).as_dict()
    with Store(tmp_path / "s.sqlite") as st:
        prev = st.start_run("nightly", {}, gl_renderer="GL one")
        st.record_config(prev, "thin_ring", scene.content_hash, p8, "ok", render_dir=render_dir("a"))
        st.record_config(prev, "thin_ring", "f" * 64, p4, "ok", render_dir=render_dir("b"))
        now = st.start_run("nightly", {}, gl_renderer="GL two")
        st.record_config(now, "thin_ring", scene.content_hash, p8, "ok", render_dir=render_dir("c"))
        st.record_config(now, "thin_ring", scene.content_hash, p4, "ok", render_dir=render_dir("d"))
        res = judge_night(st, now, prev, {"thin_ring": committed_reference(scene)}, ["thin_ring"], [64, 64],
                          {"rel": 0.05, "abs": 1e-4})
    assert res["changes"] == [] and [r["changed"] for r in res["images"]] == [False]
    assert res["family"] == 4                     # one pair (subsurface = full), four headline metrics
    assert any("'GL one', tonight with 'GL two'" in n for n in res["notes"])
    assert any("N4-K8-collision: the scene changed since the previous night (hash ffffffffffff" in n
               for n in res["notes"])


def test_trend_series_mixes_step_modes_and_keeps_settings_apart(tmp_path):
    """Step counts and modes ('steady') in one matrix, and one mapping at two skips: every configuration
    is its own line, and the plots are drawn (sorting int with str steps failed once, after the night)."""
    from harness.regression.trends import trend_plots, trend_series

    class Store:
        def configs(self, run_id):
            return [{"status": "ok", "scene": "thin_ring", "method": "sslpv",
                     "params": {"N": 32, "steps": steps, "mapping": "diffusion", "skip": skip},
                     "metrics": {"subsurface": {"relmse": {"value": 0.1 * run_id + skip}}}}
                    for steps in (8, "steady") for skip in (2, 0)]

    nights = [(1, "2026-11-20"), (2, "2026-11-21")]
    lines = trend_series(Store(), nights)[("thin_ring", "relmse")]
    assert sorted(lines, key=lambda k: (str(k[2]), k[3])) == [
        ("diffusion", 32, 8, ""), ("diffusion", 32, 8, "skip=0"),
        ("diffusion", 32, "steady", ""), ("diffusion", 32, "steady", "skip=0")]
    assert lines[("diffusion", 32, 8, "skip=0")] == [("2026-11-20", 0.1), ("2026-11-21", 0.2)]
    out = trend_plots(Store(), nights, tmp_path)
    assert [o["file"] for o in out] == ["trend_thin_ring_relmse.svg"] and (tmp_path / out[0]["file"]).is_file()
    assert (tmp_path / "trend_legend.svg").is_file()        # one legend for every figure of the night


def test_trend_figure_points_map_back_to_the_nights_values(tmp_path):
    """Each point of a trend figure, read back through the axis its decade labels state, is the badness of
    that configuration on that night (energy ratio: |x - 1|), and every line is on its mapping's panel."""
    import xml.etree.ElementTree as ET

    from harness.regression.trends import trend_plots

    values = {1: (0.3, 1.07), 2: (0.02, 0.98), 3: (0.0045, 1.0003)}       # night -> (relmse, energy ratio)

    class Store:
        def configs(self, run_id):
            rel, er = values[run_id]
            return [{"status": "ok", "scene": "thin_ring", "method": "sslpv",
                     "params": {"N": n, "steps": 8, "mapping": mapping},
                     "metrics": {"subsurface": {"relmse": {"value": rel * n / 16},
                                                "energy_ratio": {"value": 1 + (er - 1) * n / 16}}}}
                    for n in (16, 32) for mapping in ("collision", "diffusion")]

    nights = [(1, "2026-11-20"), (2, "2026-11-21"), (3, "2026-11-22")]
    out = trend_plots(Store(), nights, tmp_path)
    ns = {"s": "http://www.w3.org/2000/svg"}
    for fig in out:
        root = ET.parse(tmp_path / fig["file"]).getroot()
        ticks = {int(t.get("data-log10")): float(t.get("y")) - 3 for t in root.iter("{http://www.w3.org/2000/svg}text")
                 if t.get("class") == "ytick"}
        lo, hi = min(ticks), max(ticks)
        for panel in root.findall("s:g[@class='panel']", ns):
            # The panel's frame spans the labelled decades: its top is 10^hi, its bottom 10^lo.
            rect = panel.find("s:rect", ns)
            top, bottom = float(rect.get("y")), float(rect.get("y")) + float(rect.get("height"))
            per_decade = (bottom - top) / (hi - lo)
            assert all(abs(ticks[d] - (top + (hi - d) * per_decade)) < 0.01 for d in ticks)
            for g in panel.findall("s:g[@class='line']", ns):
                n = int(g.get("data-line").split()[0][1:])
                pts = [tuple(map(float, p.split(","))) for p in g.find("s:polyline", ns).get("points").split()]
                got = [10 ** (hi - (yv - top) / per_decade) for _, yv in pts]
                k = 0 if fig["metric"] == "relmse" else 1
                want = [values[r][0] * n / 16 if k == 0 else abs(values[r][1] - 1) * n / 16 for r in (1, 2, 3)]
                assert len(got) == 3 and all(abs(a / b - 1) < 1e-3 for a, b in zip(got, want)), (fig, got, want)
                assert [round(x, 2) for x, _ in pts] == sorted(round(x, 2) for x, _ in pts)   # oldest night left
            assert {g.get("data-line") for g in panel.findall("s:g[@class='line']", ns)} == {"N16 K8", "N32 K8"}
    assert {f["metric"] for f in out} >= {"relmse", "energy_ratio"}
