"""``sslpv-harness calibrate`` end to end on a small case, checked by routes that do not use its code.

Two scenes, N = 16, budgets K = 8 and steady, five scanned sigma scales, against the
committed 64x64 references. The calibration's reported figures are reproduced by
rendering through the ordinary parameters (``--mapping calibrated:FILE`` and
``--sigma-scale``/``--radiance-scale``) and measuring with ``harness.metrics``.
"""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from harness.calibration.run import run_calibrate
from harness.cli import main
from harness.metrics import compute
from harness.regression.accuracy import load_case_reference, small_scene
from sslpv_gl.calibrated import load_calibrated
from sslpv_gl.material import MAPPINGS
from sslpv_gl.params import SSLPVParams

pytestmark = [pytest.mark.gl]
SCENES = ["sphere_homogeneous", "thin_ring"]
ARGS = ["--scenes", ",".join(SCENES), "--grid", "16", "--steps", "8,steady", "--points", "5", "--no-progress"]


@pytest.fixture(scope="module")
def calibration(tmp_path_factory, gl_renderer):
    out = tmp_path_factory.mktemp("calibrate") / "diffusion"
    summary = run_calibrate(family="diffusion", out=out, scenes=SCENES, grids=(16,), steps=(8, "steady"), points=5,
                            progress=False, renderer=gl_renderer, argv=["calibrate", "--family", "diffusion"] + ARGS)
    info = json.loads((out / "calibration.json").read_text())
    return out, summary, info


def _relmse_energy(gl_renderer, name, params):
    scene = small_scene(name)
    ref, _ = load_case_reference(scene)
    img = gl_renderer.render(scene, params).subsurface
    return (compute("relmse", img, ref["subsurface"], ref["mask"]).value,
            compute("energy_ratio", img, ref["subsurface"], ref["mask"]).value)


class TestOutput:
    def test_folder_and_file(self, calibration):
        out, summary, info = calibration
        for name in ("calibrated.toml", "calibration.json", "index.html", "plots/loss_16_8.png",
                     "plots/loss_16_steady.png", ".sslpv-output"):
            assert (out / name).is_file(), name
        cal = load_calibrated(out / "calibrated.toml", tuple(MAPPINGS))
        assert cal.family == "diffusion" and cal.settings["skip"] == 0 and cal.settings["outside"] == "vacuum"
        assert sorted((b.N, str(b.steps)) for b in cal.budgets) == [(16, "8"), (16, "steady")]
        assert cal.fit["scenes"] == SCENES and "calibrate --family diffusion" in cal.fit["command"]
        for b in cal.budgets:
            res = info["results"][f"N={b.N} steps={b.steps}"]
            assert (b.sigma_scale, b.radiance_scale) == (res["sigma_scale"], res["radiance_scale"])
            assert b.sigma_scale_se == res["sigma_scale_se"] >= 0
        assert summary["mapping_file"] == str(out / "calibrated.toml")
        page = (out / "index.html").read_text()
        for text in ("calibrated, held out", "oracle (scene alone)", "Budget N=16 steps=steady",
                     "Targets for the held-out calibrated mapping"):
            assert text in page
        missed = any(not (r["targets"]["energy_met"] and r["targets"]["relmse_met"]) for r in info["results"].values())
        assert ("What stops it" in page) == missed

    @pytest.mark.parametrize("steps", [8, "steady"])
    def test_in_sample_figures_are_a_render_with_the_file(self, calibration, gl_renderer, steps):
        """The file, used as ``--mapping calibrated:FILE``, reproduces what the calibration reported."""
        out, _, info = calibration
        res = info["results"][f"N=16 steps={steps}"]
        for name in SCENES:
            p = SSLPVParams(N=16, steps=steps, skip=0, mapping=f"calibrated:{out / 'calibrated.toml'}")
            rel, energy = _relmse_energy(gl_renderer, name, p)
            assert rel == pytest.approx(res["in_sample"][name]["relmse"], rel=1e-5)
            assert energy == pytest.approx(res["in_sample"][name]["energy_ratio"], rel=1e-5)

    def test_held_out_and_oracle_figures_are_renders_at_their_parameters(self, calibration, gl_renderer):
        _, _, info = calibration
        res = info["results"]["N=16 steps=8"]
        for col in ("held_out", "oracle"):
            for name in SCENES:
                v = res[col][name]
                p = SSLPVParams(N=16, steps=8, skip=0, mapping="diffusion", sigma_scale=v["s"], radiance_scale=v["r"])
                rel, energy = _relmse_energy(gl_renderer, name, p)
                assert rel == pytest.approx(v["relmse"], rel=1e-5), (col, name)
                assert energy == pytest.approx(v["energy_ratio"], rel=1e-5), (col, name)

    def test_the_oracle_is_each_scene_at_its_best(self, calibration):
        """Fitted on itself a scene does at least as well as with anyone else's parameters."""
        _, _, info = calibration
        for res in info["results"].values():
            for name in SCENES:
                oracle, inside, held = (res[c][name]["relmse"] for c in ("oracle", "in_sample", "held_out"))
                assert oracle <= inside * (1 + 1e-3) and oracle <= held * (1 + 1e-3), (name, oracle, inside, held)
            assert res["loss"] == pytest.approx(np.mean([math.log(res["in_sample"][n]["relmse"]) for n in SCENES]))

    def test_fixed_mappings_are_plain_renders(self, calibration, gl_renderer):
        _, _, info = calibration
        res = info["results"]["N=16 steps=8"]
        for mapping, over in info["compared_settings"].items():
            rel, energy = _relmse_energy(gl_renderer, "thin_ring", SSLPVParams(N=16, steps=8, mapping=mapping, **over))
            assert rel == pytest.approx(res["compared"][mapping]["thin_ring"]["relmse"], rel=1e-6)
        t = res["targets"]
        assert t["relmse_met"] == (t["median_held_out_relmse"] <= 0.5 * min(t["median_relmse_literal"],
                                                                             t["median_relmse_collision"]))


class TestCommittedCalibrations:
    """A committed calibration's in-sample figures (``calibration.json``) are single renders with its file.

    The calibration scanned each sigma scale once for all integer budgets (one shared propagation,
    right there: a scan fixes sigma_scale for every count) and applied the radiance scale to the
    image. Here every budget is one ``render`` through ``--mapping calibrated:FILE`` (never a step
    group), measured with ``harness.metrics``, on two of the fit's scenes.
    """

    @pytest.mark.parametrize("family", ["diffusion", "collision", "transport"])
    def test_in_sample_figures_are_single_renders(self, gl_renderer, family):
        folder = Path(__file__).resolve().parent.parent / "baselines" / "calibrated" / family
        info = json.loads((folder / "calibration.json").read_text())
        cal = load_calibrated(folder / "calibrated.toml", tuple(MAPPINGS))
        assert len(cal.budgets) == 5
        for b in cal.budgets:
            res = info["results"][f"N={b.N} steps={b.steps}"]
            assert (res["sigma_scale"], res["radiance_scale"]) == (b.sigma_scale, b.radiance_scale)
            for name in ("sphere_homogeneous", "thin_ring"):
                p = SSLPVParams(N=b.N, steps=b.steps, mapping=f"calibrated:{folder / 'calibrated.toml'}",
                                **cal.settings)
                rel, energy = _relmse_energy(gl_renderer, name, p)
                want = res["in_sample"][name]
                assert rel == pytest.approx(want["relmse"], rel=1e-5), (b.steps, name)
                assert energy == pytest.approx(want["energy_ratio"], rel=1e-5), (b.steps, name)


class TestBadInput:
    @pytest.mark.parametrize("argv, where", [
        (["--family", "magic"], "--family: family: unknown mapping family 'magic'"),
        (["--family", "diffusion", "--points", "2"], "--points: points: must be an integer in [5, 64]"),
        (["--family", "diffusion", "--points", "x"], "--points: points:"),
        (["--family", "diffusion", "--sigma-range", "0,1"], "--sigma-range: min:"),
        (["--family", "diffusion", "--sigma-range", "4,2"], "--sigma-range: sigma-range: min 4 is not below max 2"),
        (["--family", "diffusion", "--sigma-range", "1"], "--sigma-range: sigma-range:"),
        (["--family", "diffusion", "--grid", "2"], "--grid: N: must be an integer in [4, 256]"),
        (["--family", "diffusion", "--steps", "auto"], "--steps: steps: 'auto' is not a budget"),
        (["--family", "diffusion", "--steps", "8,8"], "--steps: steps: a budget appears twice"),
        (["--family", "diffusion", "--outside", "space"], "--outside: outside: unknown outside 'space'"),
        (["--family", "collision", "--boundary-reflect", "mirror"],
         "--boundary-reflect: boundary_reflect: unknown boundary_reflect 'mirror'"),
        (["--family", "collision", "--phase-scaling", "foo"], "--phase-scaling: phase_scaling: unknown phase_scaling"),
        (["--family", "collision", "--boundary-reflect", "rdr", "--outside", "extrapolated"],
         "--boundary-reflect: boundary_reflect:"),
        (["--family", "diffusion", "--skip", "x"], "--skip: skip:"),
        (["--family", "diffusion", "--exitance", "lambert"], "--exitance: exitance: unknown exitance 'lambert'"),
        (["--family", "diffusion", "--exitance", "boundary"], "--exitance: exitance: boundary reads the exitance"),
        (["--family", "collision", "--outside", "extrapolated", "--exitance", "boundary"],
         "--exitance: exitance: boundary reads the exitance"),
        (["--family", "collision", "--inject-depth", "-1"], "--inject-depth: inject_depth: must be a number in [0, 16]"),
        (["--family", "collision", "--inject-depth", "deep"], "--inject-depth: inject-depth: 'deep' is not"),
        (["--family", "collision", "--shade-depth", "5"], "--shade-depth: shade_depth: must be a number in [0, 4]"),
        (["--family", "collision", "--lookup", "bicubic"], "--lookup: lookup:"),
        (["--family", "transport", "--outside", "vacuum"], "--outside: outside: mapping transport needs"),
        (["--family", "diffusion", "--scenes", "thin_ring"], "--scenes: scenes: 1 scene given"),
        (["--family", "diffusion", "--scenes", "thin_ring,nosuch"], "--scenes: scenes: unknown scene 'nosuch'"),
        (["--family", "diffusion", "--scenes", "thin_ring,sphere_homogeneous", "--size", "32x32"],
         "--scenes thin_ring: reference: scene thin_ring has no reference at 32x32 yet"),
    ])
    def test_one_line_and_nothing_written(self, tmp_path, capsys, argv, where):
        out = tmp_path / "out"
        code = main(["calibrate", "--out", str(out)] + argv)
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1, err
        assert err[0].startswith("error: " + where), err[0]
        assert not out.exists() and list(tmp_path.iterdir()) == []

    def test_extension_flags_reach_the_fit(self, tmp_path, capsys, monkeypatch):
        """--outside, --boundary-reflect, --phase-scaling, --inject-depth, --shade-depth, --lookup and --exitance become
        the fit's renderer settings (no render here)."""
        import harness.calibration.run as cal_run

        seen = {}
        monkeypatch.setattr(cal_run, "run_calibrate", lambda **kw: seen.update(kw) or {"out": str(kw["out"])})
        code = main(["calibrate", "--json", "--family", "collision", "--out", str(tmp_path / "o"), "--outside",
                     "interior", "--boundary-reflect", "rdr", "--phase-scaling", "delta-eddington", "--inject-depth", "1",
                     "--shade-depth", "1", "--lookup", "trilinear"])
        assert code == 0, capsys.readouterr().err
        assert seen["settings"] == {"outside": "interior", "boundary_reflect": "rdr", "phase_scaling": "delta-eddington",
                                    "inject_depth": 1.0, "shade_depth": 1.0, "lookup": "trilinear"}
        code = main(["calibrate", "--json", "--family", "diffusion", "--out", str(tmp_path / "o"), "--outside",
                     "extrapolated", "--exitance", "boundary"])
        assert code == 0, capsys.readouterr().err
        assert seen["settings"] == {"outside": "extrapolated", "exitance": "boundary"}

    def test_the_compared_mappings_with_an_exitance_fit(self):
        """The fixed mappings of a fit with exitance = boundary: diffusion shares it, literal and collision (which do
        not support it) are compared at the paper's isotropic read, so the fit's base params accept them."""
        from harness.calibration.families import COMPARED
        from sslpv_gl.params import SSLPVParams

        base = SSLPVParams(mapping="diffusion", skip=0, outside="extrapolated", exitance="boundary")
        made = {m: base.replace(mapping=m, **over) for m, over in COMPARED.items()}
        assert made["diffusion"].exitance == "boundary"
        assert made["literal"].exitance == made["collision"].exitance == "isotropic"

    @pytest.mark.parametrize("argv, where", [
        (["--from", "NOWHERE"], "--from: folder: NOWHERE holds no calibration.json"),
        (["--from", "baselines/calibrated/collision", "--against", "NOWHERE"],
         "--against: folder: NOWHERE holds no calibration.json"),
    ])
    def test_form_one_line_and_nothing_written(self, tmp_path, capsys, argv, where):
        out = tmp_path / "out"
        code = main(["calibrate-form", "--out", str(out)] + [str(a).replace("NOWHERE", str(tmp_path / "x"))
                                                             for a in argv])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1, err
        assert err[0].startswith("error: " + where.replace("NOWHERE", str(tmp_path / "x"))), err[0]
        assert not out.exists()

    def test_a_foreign_folder_is_refused_before_any_render(self, tmp_path, capsys, monkeypatch):
        import harness.calibration.scan as scan

        monkeypatch.setattr(scan.Scanner, "_run", lambda *a: pytest.fail("rendered"))
        out = tmp_path / "mine"
        out.mkdir()
        (out / "notes.txt").write_text("a user's file")
        assert main(["calibrate", "--family", "diffusion", "--out", str(out)] + ARGS) == 2
        assert "non-empty folder that the harness did not write" in capsys.readouterr().err
        assert [p.name for p in out.iterdir()] == ["notes.txt"]


@pytest.mark.parametrize("where", ["scan", "page"])
def test_an_interrupted_calibration_leaves_nothing(tmp_path, capsys, monkeypatch, where):
    import harness.calibration.page as page
    import harness.calibration.scan as scan

    calls = {"n": 0}
    real = scan.Scanner._run

    def interrupt_third(self, *a):
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt
        return real(self, *a)

    if where == "scan":
        monkeypatch.setattr(scan.Scanner, "_run", interrupt_third)
    else:
        monkeypatch.setattr(page, "write_page", lambda *a: (_ for _ in ()).throw(KeyboardInterrupt()))
    out = tmp_path / "cal"
    assert main(["calibrate", "--family", "collision", "--out", str(out), "--scenes", ",".join(SCENES), "--grid", "8",
                 "--steps", "4", "--points", "5", "--no-progress"]) == 130
    assert "interrupted" in capsys.readouterr().err
    # no output, no temporary folder; the result cache (this test's own, tests/conftest.py) keeps only whole
    # entries of the renders that finished, which a calibration run again is served
    assert [p.name for p in tmp_path.iterdir() if p.name != "result-cache"] == []
    entries = [e for e in (tmp_path / "result-cache").glob("??/*")]
    assert len(entries) == 2 if where == "scan" else len(entries) > 2   # the two renders before the interruption
    assert all(sorted(f.name for f in e.iterdir()) == [".sslpv-output", "images.npz", "result.json"] for e in entries)


def test_sweep_records_the_calibrated_file(calibration, tmp_path):
    """A sweep with ``--mapping calibrated:FILE`` stores the file's path and hash with each configuration."""
    from harness.runs.sweep import SweepConfig, run_sweep
    from harness.store import Store

    out, _, _ = calibration
    path = str(out / "calibrated.toml")
    cfg = SweepConfig(scenes=["thin_ring"], params={"N": [16], "steps": [8, "steady"], "skip": [0],
                                                    "mapping": [f"calibrated:{path}"]},
                      out=str(tmp_path / "s"), size=[64, 64])
    summary = run_sweep(cfg, workers=1, progress=False)
    assert summary["ok"] == 2
    sha = load_calibrated(Path(path), tuple(MAPPINGS)).sha256
    with Store(summary["store"]) as st:
        for c in st.configs(run_id=summary["run_id"]):
            assert c["calibration"]["path"] == path and c["calibration"]["sha256"] == sha
            assert c["calibration"]["steps"] == c["params"]["steps"]


def test_the_trilinear_read_is_an_extension(tmp_path, monkeypatch):
    """The paper shades from each boundary cell's own coefficients (lookup = cell); the trilinear read is an
    extension: a calibration fitted with it is another calibration, its page and its study column named after it,
    a study configuration with it competes in a family of its own (collision + trilinear), and a render that
    turns it on without an outside treatment takes the extensions' committed one."""
    import importlib.util
    import json
    from pathlib import Path

    from harness.calibration.families import fit_extensions
    from harness.methods.extension_outside import with_extension_outside
    from harness.study.extensions import family_suffix
    from harness.study.spec import study_label
    from sslpv_gl.params import SSLPVParams

    assert fit_extensions("collision", {"skip": 2, "lookup": "cell"}) == {}
    assert fit_extensions("collision", {"outside": "interior", "lookup": "trilinear"}) == \
        {"outside": "interior", "lookup": "trilinear"}
    assert family_suffix({"mapping": "collision", "lookup": "trilinear"}) == " + trilinear"
    assert family_suffix({"mapping": "collision", "lookup": "cell"}) == ""
    choice = tmp_path / "outside.json"
    choice.write_text(json.dumps({"format": "sslpv-extensions-outside", "outside": "interior",
                                  "by_mode": {"interior": 0.9}}))
    assert with_extension_outside({"lookup": "trilinear"}, SSLPVParams, choice)["outside"] == "interior"
    assert "outside" not in with_extension_outside({"lookup": "cell"}, SSLPVParams, choice)

    root = Path(__file__).resolve().parents[1]
    monkeypatch.syspath_prepend(str(root / "benchmarks"))
    spec = importlib.util.spec_from_file_location("bench_calibration_table", root / "benchmarks" / "calibration_table.py")
    table = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(table)
    cal = json.loads((root / "baselines" / "calibrated" / "collision" / "calibration.json").read_text())
    assert table.page_name(cal)[0] == "calibration_collision"
    cal["settings"] = dict(cal["settings"], lookup="trilinear")
    assert table.page_name(cal)[0] == "calibration_collision_trilinear"

    text = (root / "baselines" / "calibrated" / "collision" / "calibrated.toml").read_text()
    assert 'lookup = "cell"' in text
    (tmp_path / "calibrated.toml").write_text(text.replace('lookup = "cell"', 'lookup = "trilinear"'))
    assert study_label(f"calibrated:{tmp_path / 'calibrated.toml'}") == "calibrated collision (trilinear)"
    assert study_label("calibrated:baselines/calibrated/collision/calibrated.toml") == "calibrated collision"
