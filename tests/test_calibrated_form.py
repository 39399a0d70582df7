"""A calibration that depends on the material: the per-cell form (sslpv_gl.material_form, Eq. F1), its
version 3 file, its fit with leave-one-scene-out (harness.calibration.form) and its bad input."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from harness.calibration.form import (budget_terms, fold_anchor, fold_fits, fold_fits_radiance, form_toml,
                                     radiance_targets)
from harness.calibration.form_fit import fit_form, ridge, loo_testable_terms
from harness.errors import InputError
from sslpv_gl.calibrated import load_calibrated
from sslpv_gl.material import MAPPINGS, lpv_material
from sslpv_gl.material_form import TERMS, Form, cell_numbers, extent_cells

SETTINGS = {"skip": 2, "outside": "vacuum", "resample": "box", "lookup": "cell", "inject_size": 256,
            "inject_offset": 0.0, "precision": "fp32", "eta2": False, "phase_scaling": "none",
            "boundary_reflect": "none"}
SIGMA = [0.3, -0.4, 0.2, 0.5, 0.7, 0.25]          # [const, *TERMS]
RADIANCE = [-0.2, 0.1, -0.3, 0.4, 0.6, -0.15]


def numpy_terms(st, a, g, dx, eta, extent, K):
    """The terms of (F1) written out again, apart from sslpv_gl.material_form."""
    absorb = st - st * a                                        # sigma_a
    reduced = st * a - st * a * g                               # sigma_s (1 - g)
    sig_tr = np.sqrt(3.0 * absorb * (absorb + reduced))
    one_minus = np.divide(absorb, absorb + reduced, out=np.ones_like(st), where=(absorb + reduced) > 0)
    return [np.log(np.maximum(sig_tr * dx, 1e-6)), np.log(np.maximum(one_minus, 1e-6)), g,
            np.full_like(st, np.log(eta)), np.full_like(st, np.log(extent / K))]


def medium(N=6, seed=1):
    rng = np.random.default_rng(seed)
    shape = (N, N, N, 3)
    return SimpleNamespace(bbox_min=np.zeros(3), bbox_max=np.full(3, 3.0),
                           sigma_t=rng.uniform(0.5, 8.0, shape).astype(np.float32),
                           albedo=rng.uniform(0.3, 0.999, shape).astype(np.float32),
                           g=rng.uniform(-0.3, 0.8, shape).astype(np.float32))


def write_v3(path, budgets, version=3):
    """``budgets``: [(N, steps, sigma, radiance)] with coefficients [const, *TERMS]."""
    path.write_text(form_toml("collision", SETTINGS, [(N, k, TERMS, s, r) for N, k, s, r in budgets], {"loss": "t"}))
    return path


class TestCellForm:
    def test_terms_against_numpy(self):
        m = medium()
        st, a, g = (np.asarray(v, np.float64) for v in (m.sigma_t, m.albedo, m.g))
        got = cell_numbers(st, a, g, 0.5, 1.4, 5.0, 8)
        for term, want in zip(TERMS, numpy_terms(st, a, g, 0.5, 1.4, 5.0, 8)):
            np.testing.assert_allclose(got[term], want, rtol=1e-12, err_msg=term)

    def test_extent_is_the_inside_bounding_box(self):
        inside = np.zeros((8, 8, 8), bool)
        inside[2:5, 1:7, 3:4] = True
        assert extent_cells(inside, 8) == 6.0 and extent_cells(None, 8) == 8.0

    def test_material_sigma_and_radiance_per_cell(self):
        """lpv_material's per-cell factors equal an independent NumPy evaluation of (F1)."""
        m, N = medium(), 6
        inside = np.ones((N, N, N), bool)
        inside[0] = False
        form = Form(TERMS, tuple(SIGMA[1:]), tuple(RADIANCE[1:]), 8)
        plain = lpv_material(m, inside, N, "collision")
        got = lpv_material(m, inside, N, "collision", eta=1.4, form=form)
        st, a, g = (np.asarray(v, np.float64) for v in (m.sigma_t, m.albedo, m.g))   # N = medium grid: identity
        x = numpy_terms(st, a, g, 0.5, 1.4, 5.0, 8)            # 5 inside layers of 6: extent 6 along x and y
        x[4] = np.full_like(st, np.log(6.0 / 8))
        s = np.exp(sum(c * xi for c, xi in zip(SIGMA[1:], x)))
        r = np.exp(sum(c * xi for c, xi in zip(RADIANCE[1:], x)))
        np.testing.assert_allclose(got["sigma_lpv"], (plain["sigma_lpv"] * s).astype(np.float32), rtol=2e-7)
        np.testing.assert_allclose(got["radiance_factor"], r, rtol=1e-12)

    def test_renderer_applies_the_form_per_cell(self, tmp_path):
        """The GL renderer's material and radiance scale for a version 3 budget equal (F1) evaluated in NumPy."""
        from harness.scene import load_scene
        from sslpv_gl.params import SSLPVParams
        from sslpv_gl.renderer import SSLPVRenderer
        from sslpv_gl.steps import _with_global_scale

        p = write_v3(tmp_path / "f.toml", [(16, 8, SIGMA, RADIANCE)])
        scene = load_scene("jade_veins")
        r = SSLPVRenderer()
        params = SSLPVParams(N=16, steps=8, mapping=f"calibrated:{p}", **SETTINGS)
        mat = r.lpv_material(scene, params)
        plain = r.lpv_material(scene, SSLPVParams(N=16, steps=8, mapping="collision", **SETTINGS))
        from sslpv_gl.material import resample_medium

        st, a, g = resample_medium(scene.medium, 16, "box")
        dx = float(scene.medium.bbox_max[0] - scene.medium.bbox_min[0]) / 16
        x = numpy_terms(st, a, g, dx, 1.0, extent_cells(mat["inside"], 16), 8)
        s = math.exp(SIGMA[0]) * np.exp(sum(c * xi for c, xi in zip(SIGMA[1:], x)))
        rad = math.exp(RADIANCE[0]) * np.exp(sum(c * xi for c, xi in zip(RADIANCE[1:], x)))
        keep = plain["sigma_lpv"] > 0
        np.testing.assert_allclose(mat["sigma_lpv"][keep], (plain["sigma_lpv"] * s)[keep], rtol=3e-7)
        res = params.resolved()
        scale = _with_global_scale(mat, res.radiance_scale)["radiance_scale"]
        np.testing.assert_allclose(scale, plain["radiance_scale"] * rad, rtol=1e-12)

    def test_constant_form_renders_as_the_scalar_file(self, tmp_path):
        """A form of constants only is the version 2 budget with the same scales, bit for bit."""
        from harness.scene import load_scene
        from sslpv_gl.params import SSLPVParams
        from sslpv_gl.renderer import SSLPVRenderer

        zero = [0.0] * len(TERMS)
        v3 = write_v3(tmp_path / "c3.toml", [(16, 8, [0.4] + zero, [-0.3] + zero),
                                             (16, "steady", [0.2] + zero, [0.1] + zero)])
        v2 = tmp_path / "c2.toml"
        v2.write_text(v3.read_text().replace("version = 3", "version = 2").split("[form]")[0] + "".join(
            f"\n[[budget]]\nN = 16\nsteps = {k}\nsigma_scale = {math.exp(s)!r}\nradiance_scale = {math.exp(r)!r}\n"
            for k, s, r in ((8, 0.4, -0.3), ('"steady"', 0.2, 0.1))))
        scene = load_scene("skin_torus").with_resolution(32, 32)
        r = SSLPVRenderer()
        for steps in (8, "steady"):
            a, b = (r.render(scene, SSLPVParams(N=16, steps=steps, mapping=f"calibrated:{p}", **SETTINGS)).subsurface
                    for p in (v3, v2))
            assert np.array_equal(a, b), steps


    def test_budgets_that_differ_in_their_form_only(self, tmp_path):
        """Two budgets with the same constants and other per-cell coefficients: each count renders with its
        own form, grouped (render_steps) or alone, from a warm renderer or a fresh one."""
        from harness.scene import load_scene
        from sslpv_gl.params import SSLPVParams
        from sslpv_gl.renderer import SSLPVRenderer

        other = [SIGMA[0], 0.3, -0.2, 0.0, 0.0, -0.6]
        p = write_v3(tmp_path / "f.toml", [(16, 4, SIGMA, RADIANCE), (16, 8, other, RADIANCE)])
        scene = load_scene("thin_ring").with_resolution(32, 32)

        def params(k):
            return SSLPVParams(N=16, steps=k, mapping=f"calibrated:{p}", **SETTINGS)

        fresh = {k: SSLPVRenderer().render(scene, params(k)).subsurface for k in (4, 8)}
        assert not np.array_equal(fresh[4], fresh[8])
        warm = SSLPVRenderer()
        alone = {k: warm.render(scene, params(k)).subsurface for k in (4, 8)}
        grouped = [x.subsurface for x in warm.render_steps(scene, params(8), [4, 8])]
        for k, g in zip((4, 8), grouped):
            assert np.array_equal(alone[k], fresh[k]) and np.array_equal(g, fresh[k]), k


class TestFile:
    def test_round_trip(self, tmp_path):
        p = write_v3(tmp_path / "f.toml", [(32, 8, SIGMA, RADIANCE), (32, "steady", SIGMA[:5] + [0.0],
                                                                         RADIANCE[:5] + [0.0])])
        cal = load_calibrated(p, tuple(MAPPINGS))
        b = cal.budget(32, 8)
        assert (b.sigma_scale, b.radiance_scale) == (math.exp(SIGMA[0]), math.exp(RADIANCE[0]))
        assert b.form == Form(TERMS, tuple(SIGMA[1:]), tuple(RADIANCE[1:]), 8)
        assert cal.budget(32, "steady").form.sigma == tuple(SIGMA[1:5]) + (0.0,)
        assert cal.settings == SETTINGS | {"exitance": "isotropic", "inject_depth": 0.0, "shade_depth": 0.0}   # predating them: the paper's

    def test_terms_a_budget_uses(self):
        assert "ln_extent_per_step" in budget_terms(8) and "ln_extent_per_step" not in budget_terms("steady")

    @pytest.mark.parametrize("edit, field, problem", [
        (('"g", ', '"gamma", '), "form.terms[2]", "'gamma' is not a term of the form"),
        (("[0.3, -0.4", "[nan, -0.4"), "budget[0].sigma_form[0]", "finite"),
        (("[0.3, -0.4", "[0.3, inf"), "budget[0].sigma_form[1]", "finite"),
        (("version = 3", "version = 2"), "form", "is not part of version 2"),
        (("[0.3, -0.4", "[400.0, -0.4"), "budget[0].sigma_form[0]", "400 is outside [-300, 300]"),
        (('steps = 8', 'steps = "steady"'), "budget[0].sigma_form", "uses ln_extent_per_step"),
    ])
    def test_bad_file_is_one_line(self, tmp_path, edit, field, problem):
        p = write_v3(tmp_path / "f.toml", [(32, 8, SIGMA, RADIANCE)])
        p.write_text(p.read_text().replace(*edit, 1))
        with pytest.raises(InputError) as exc:
            load_calibrated(p, tuple(MAPPINGS))
        msg = str(exc.value)
        assert "\n" not in msg and msg.startswith(f"{p}: {field}: ") and problem in msg and "; " in msg, msg

    def test_other_settings_are_refused(self, tmp_path):
        from sslpv_gl.params import SSLPVParams

        p = write_v3(tmp_path / "f.toml", [(32, 8, SIGMA, RADIANCE)])
        with pytest.raises(InputError, match=r"^--skip: skip: .*was calibrated with skip=2.*; pass --skip 2"):
            SSLPVParams(N=32, steps=8, mapping=f"calibrated:{p}", **(SETTINGS | {"skip": 0}))

    def test_other_grid_is_refused(self, tmp_path):
        from sslpv_gl.params import SSLPVParams

        p = write_v3(tmp_path / "f.toml", [(32, 8, SIGMA, RADIANCE)])
        with pytest.raises(InputError, match=r"^--grid: N: .*was fitted for N=32, this render has N=16.*; render "
                                             r"with --grid 32"):
            SSLPVParams(N=16, steps=8, mapping=f"calibrated:{p}", **SETTINGS)


class TestFit:
    def test_ridge_without_penalty_is_least_squares(self):
        rng = np.random.default_rng(3)
        X = rng.normal(size=(12, 3))
        y = 0.7 + X @ [0.5, -1.0, 2.0]
        a0, a = ridge(X, y, 0.0)
        np.testing.assert_allclose([a0, *a], [0.7, 0.5, -1.0, 2.0], atol=1e-10)

    def test_anchor_sets_the_level_at_the_mean(self):
        rng = np.random.default_rng(4)
        X = rng.normal(size=(8, 2))
        f = fit_form(X, X @ [1.0, 0.5], X @ [-0.5, 0.2], anchor=(0.3, -0.1))
        mx = X.mean(axis=0)
        assert f["sigma"][0] + mx @ f["sigma"][1:] == pytest.approx(0.3)
        assert f["radiance"][0] + mx @ f["radiance"][1:] == pytest.approx(-0.1)

    def test_held_out_scene_never_reaches_its_fold(self):
        """Leave one scene out: the held-out scene's terms, oracle and anchor may be anything."""
        rng = np.random.default_rng(5)
        names = [f"s{i}" for i in range(7)]
        X = {n: list(rng.normal(size=3)) for n in names}
        ln_s = {n: float(rng.normal()) for n in names}
        ln_r = {n: float(rng.normal()) for n in names}
        a = fold_fits(names, X, ln_s, ln_r, "s3", anchor=(0.1, 0.2))
        X2, s2, r2 = dict(X), dict(ln_s), dict(ln_r)
        X2["s3"], s2["s3"], r2["s3"] = [40.0, -9.0, 3.0], 25.0, -30.0
        b = fold_fits(names, X2, s2, r2, "s3", anchor=(0.1, 0.2))
        assert a == b and "s3" not in a["scenes"] and len(a["scenes"]) == 6

    def test_fold_anchor_is_the_scalar_fit_without_the_scene(self):
        res = {"sigma_scale": 2.0, "radiance_scale": 0.5,
               "held_out": {"a": {"s": 3.0, "r": 0.25}, "b": {"s": 4.0, "r": 0.125}}}
        assert fold_anchor(res, "a") == (math.log(3.0), math.log(0.25))
        assert fold_anchor(res, None) == (math.log(2.0), math.log(0.5))


class TestConditionalFit:
    """Eq. (F7): sigma_scale the scalar fit's, ln r regressed on each training scene's best ln r at that s."""

    def test_target_is_the_least_relmse_radiance_scale(self):
        """ln(B / A) of Eq. (C1) against a brute-force scan of the registered relMSE over r (a second route)."""
        from harness.calibration.fit import relmse_coefficients
        from harness.metrics import compute

        rng = np.random.default_rng(6)
        ref = rng.uniform(0.01, 2.0, (9, 7, 3))
        img = ref * rng.uniform(0.3, 0.9) * rng.lognormal(0.0, 0.3, ref.shape)
        mask = np.ones((9, 7), bool)
        t = radiance_targets(lambda n, s: relmse_coefficients(img.ravel(), ref.ravel()), ["a"], 1.0)
        rs = np.exp(np.linspace(-1.0, 2.0, 3001))
        rel = [compute("relmse", r * img, ref, mask).value for r in rs]
        assert t["a"] == pytest.approx(math.log(rs[int(np.argmin(rel))]), abs=2e-3)

    def test_a_scene_without_an_image_is_left_out(self):
        t = radiance_targets(lambda n, s: None if n == "b" else (2.0, 1.0, 1.0), ["a", "b"], 1.0)
        assert t == {"a": pytest.approx(math.log(0.5))}

    def test_sigma_is_the_anchor_and_radiance_is_anchored_at_the_mean(self):
        rng = np.random.default_rng(7)
        names = [f"s{i}" for i in range(8)]
        X = {n: list(rng.normal(size=3)) for n in names}
        targets = {n: 0.3 + float(np.dot(X[n], [0.5, -0.2, 0.1])) for n in names}
        f = fold_fits_radiance(names, X, targets, None, anchor=(0.4, -0.7))
        assert f["sigma"] == [0.4, 0.0, 0.0, 0.0]
        mx = np.mean([X[n] for n in names], axis=0)
        assert f["radiance"][0] + mx @ f["radiance"][1:] == pytest.approx(-0.7)
        assert f["radiance"][1:] == pytest.approx([0.5, -0.2, 0.1], abs=0.05)     # exact data, a light penalty

    def test_held_out_scene_never_reaches_its_fold(self):
        rng = np.random.default_rng(8)
        names = [f"s{i}" for i in range(7)]
        X = {n: list(rng.normal(size=3)) for n in names}
        targets = {n: float(rng.normal()) for n in names}
        a = fold_fits_radiance(names, X, targets, "s2", anchor=(0.1, 0.2))
        X2, t2 = dict(X), dict(targets)
        X2["s2"], t2["s2"] = [50.0, -7.0, 9.0], 40.0
        assert fold_fits_radiance(names, X2, t2, "s2", anchor=(0.1, 0.2)) == a and "s2" not in a["scenes"]


class TestTestableTerms:
    """A term that one training scene alone sets apart gets no slope in the conditional form (Eq. F7)."""

    def suite_like(self, rng, n=10):
        """``n`` scenes: term 0 varies, term 1 is shared by all but ``odd``, whose target is far off (as
        ``ln_extent_per_step`` and ``backlit_slab`` at K = 8 on the suite)."""
        names = [f"s{i}" for i in range(n)]
        X = {m: [float(rng.normal()), 1.322] for m in names}
        X["odd"] = [float(rng.normal()), 1.253]
        targets = {m: 0.2 * X[m][0] + float(rng.normal(0.0, 0.05)) for m in names}
        targets["odd"] = 0.2 * X["odd"][0] + 3.3
        return names + ["odd"], X, targets

    def test_loo_testable_terms_rule(self):
        X = np.array([[0.0, 1.0, 1.0, 5.0], [0.0, 1.0, 2.0, 5.0], [0.0, 2.0, 3.0, 5.0], [0.0, 2.0, 1.0, 6.0]])
        assert list(loo_testable_terms(X)) == [False, True, True, False]

    def test_a_term_one_scene_sets_apart_gets_no_slope(self):
        names, X, targets = self.suite_like(np.random.default_rng(9))
        f = fold_fits_radiance(names, X, targets, None, anchor=(0.1, 0.2))
        assert f["radiance"][2] == 0.0

    def test_a_held_out_scene_beyond_it_does_not_extrapolate(self):
        """The held-out scene has its own value of the term, beyond the odd scene's (``thin_ring``): its
        prediction stays within the training targets' range."""
        names, X, targets = self.suite_like(np.random.default_rng(10))
        X["beyond"], targets["beyond"] = [0.0, 1.179], 0.0
        f = fold_fits_radiance(names + ["beyond"], X, targets, "beyond", anchor=(0.1, 0.0))
        pred = f["radiance"][0] + np.dot(f["radiance"][1:], X["beyond"])
        assert abs(pred) < 1.0

    def test_two_scenes_that_share_a_value_keep_the_term(self):
        names, X, targets = self.suite_like(np.random.default_rng(11))
        X["odd2"], targets["odd2"] = [0.3, 1.253], 0.06 + 3.3
        f = fold_fits_radiance(names + ["odd2"], X, targets, None, anchor=(0.1, 0.2))
        assert f["radiance"][2] < -10.0     # two scenes set it apart: leave-one-out tests it


def test_command_line_offers_every_form():
    """``sslpv-harness calibrate-form --slopes`` takes exactly the forms :func:`run_form` fits."""
    from harness.calibration.form import SLOPES
    from harness.cli.main import build_parser, walk

    parser = next(p for path, p in walk(build_parser()) if path == ("calibrate-form",))
    action = next(a for a in parser._actions if "--slopes" in a.option_strings)
    assert tuple(action.choices) == SLOPES


class TestBadInputCommandLine:
    """Through ``sslpv-harness render``: exit 2, one line, nothing left behind."""

    @pytest.fixture
    def cli(self, tmp_path, capsys, monkeypatch):
        from tests.test_bad_input import one_line_runner

        return one_line_runner(tmp_path, capsys, monkeypatch)

    @pytest.mark.parametrize("edit, grid, needles", [
        (('"g", ', '"gamma", '), "32", ("form.terms[2]: 'gamma' is not a term of the form; use some of",)),
        (("[0.3, -0.4", "[0.3, nan"), "32", ("budget[0].sigma_form[1]: must be a finite number",)),
        (None, "16", ("--grid: N: ", "was fitted for N=32, this render has N=16", "; render with --grid 32")),
    ])
    def test_one_line(self, cli, tmp_path, edit, grid, needles):
        p = write_v3(tmp_path / "f.toml", [(32, 8, SIGMA, RADIANCE)])
        if edit:
            p.write_text(p.read_text().replace(*edit, 1))
        cli(["render", "thin_ring", "--out", "o", "--grid", grid, "--steps", "8", "--skip", "2",
             "--mapping", f"calibrated:{p}"], *needles)


class TestCommittedForm:
    """The committed forms' figures are single renders through ``--mapping calibrated:FILE``: in-sample with the
    committed file, held out with a file rebuilt from the fold's coefficients in calibration.json, measured with
    ``harness.metrics`` (never the fit's own code), on one of its scenes at every budget (about a minute: the
    steady solve at N = 32)."""

    @pytest.mark.gl
    @pytest.mark.slow
    @pytest.mark.parametrize("folder_name", ["baselines/calibrated/collision_form",
                                             "baselines/calibrated/collision_radiance_form",
                                             "baselines/calibrated/collision_loss_form"])
    def test_in_sample_and_held_out_figures_are_single_renders(self, tmp_path, folder_name):
        import json
        from pathlib import Path

        from harness.metrics import compute
        from harness.regression.accuracy import load_case_reference, small_scene
        from sslpv_gl.params import SSLPVParams
        from sslpv_gl.renderer import SSLPVRenderer

        folder = Path(__file__).resolve().parent.parent / folder_name
        info = json.loads((folder / "calibration.json").read_text())
        cal = load_calibrated(folder / "calibrated.toml", tuple(MAPPINGS))
        renderer = SSLPVRenderer()
        for name in ("thin_ring",):
            rows = []
            for b in cal.budgets:
                res = info["results"][f"N={b.N} steps={b.steps}"]
                fold = res["folds"][name]
                rows.append((b.N, b.steps, res["terms"], fold["sigma"], fold["radiance"]))
            held = tmp_path / f"{name}.toml"
            held.write_text(form_toml(cal.family, cal.settings, rows, {"held_out": name}))
            scene = small_scene(name)
            ref, _ = load_case_reference(scene)
            for b in cal.budgets:
                res = info["results"][f"N={b.N} steps={b.steps}"]
                for path, want in ((folder / "calibrated.toml", res["in_sample"][name]), (held, res["held_out"][name])):
                    img = renderer.render(scene, SSLPVParams(N=b.N, steps=b.steps, mapping=f"calibrated:{path}",
                                                             **cal.settings)).subsurface
                    rel = compute("relmse", img, ref["subsurface"], ref["mask"]).value
                    energy = compute("energy_ratio", img, ref["subsurface"], ref["mask"]).value
                    assert rel == pytest.approx(want["relmse"], rel=1e-5), (name, b.steps, str(path))
                    assert energy == pytest.approx(want["energy_ratio"], rel=1e-5), (name, b.steps, str(path))


class TestSources:
    """Calibrations of one family at several grids are taken together; anything else is refused in one line."""

    def folder(self, tmp_path, name, family="collision", grid=32, skip=2):
        import json

        d = tmp_path / name
        d.mkdir()
        text = form_toml(family, SETTINGS | {"skip": skip}, [(grid, 8, TERMS, SIGMA, RADIANCE)], {})
        (d / "calibrated.toml").write_text(text)
        res = {"oracle": {}, "held_out": {}, "sigma_scale": 1.0, "radiance_scale": 1.0}
        (d / "calibration.json").write_text(json.dumps({"family": family, "mapping": family, "scenes": ["a", "b"],
                                                        "budgets": [[grid, 8]], "results": {f"N={grid} steps=8": res}}))
        return d

    def test_grids_together(self, tmp_path):
        from harness.calibration.form_files import read_sources as _sources

        cal, settings = _sources([self.folder(tmp_path, "a"), self.folder(tmp_path, "b", grid=16)])
        assert cal["budgets"] == [[32, 8], [16, 8]] and settings == SETTINGS | {"exitance": "isotropic", "inject_depth": 0.0, "shade_depth": 0.0}
        assert cal["results"]["N=16 steps=8"]["source"] == str(tmp_path / "b")

    @pytest.mark.parametrize("other, field", [({"grid": 32}, "budgets"), ({"family": "diffusion", "grid": 16}, "family"),
                                              ({"skip": 0, "grid": 16}, "settings")])
    def test_refused(self, tmp_path, other, field):
        from harness.calibration.form_files import read_sources as _sources

        b = self.folder(tmp_path, "b", **other)
        with pytest.raises(InputError) as exc:
            _sources([self.folder(tmp_path, "a"), b])
        assert str(exc.value).startswith(f"{b / 'calibration.json'}: {field}: ") and "\n" not in str(exc.value)


def test_study_names_a_form_apart_from_its_scalar_family(tmp_path):
    """The study's tables key a calibrated mapping by its label: a per-cell form, a form of the radiance scale alone
    (Eq. F7) and the scalar fit of the same family must not share a column."""
    from harness.study.spec import study_label

    scalar = study_label("calibrated:baselines/calibrated/collision/calibrated.toml")
    form = study_label("calibrated:baselines/calibrated/collision_form/calibrated.toml")
    assert scalar == "calibrated collision" and form == "calibrated collision form"
    conditional = write_v3(tmp_path / "r.toml", [(32, 8, [0.3, 0, 0, 0, 0, 0], RADIANCE),
                                                 (32, 16, [0.2, 0, 0, 0, 0, 0], [0.1, 0, 0, 0, 0, 0])])
    assert study_label(f"calibrated:{conditional}") == "calibrated collision radiance form"
    mixed = write_v3(tmp_path / "m.toml", [(32, 8, [0.3, 0, 0, 0, 0, 0], RADIANCE), (32, 16, SIGMA, RADIANCE)])
    assert study_label(f"calibrated:{mixed}") == "calibrated collision form"
    loss = tmp_path / "l.toml"
    loss.write_text(form_toml("collision", SETTINGS, [(32, 8, TERMS, SIGMA, RADIANCE)], {"loss": "t", "slopes": "loss"}))
    assert study_label(f"calibrated:{loss}") == "calibrated collision loss form"
    channels = tmp_path / "c.toml"
    channels.write_text(form_toml("collision", SETTINGS, [(32, 8, TERMS, SIGMA, RADIANCE)],
                                  {"loss": "t", "slopes": "channels"}))
    assert study_label(f"calibrated:{channels}") == "calibrated collision channel form"
    assert study_label("collision") == "collision"


def test_study_names_a_calibration_after_its_extensions():
    """Two calibrations of one family fitted with other extensions are two columns: the extensions beyond the
    family's own settings are in the label (the transport family's own outside = absorb is not), in parentheses so
    that the column stays a calibration, not an extension family (harness.study.extensions.is_extension)."""
    from pathlib import Path

    from harness.study.extensions import is_extension
    from harness.study.spec import study_label

    root = Path(__file__).resolve().parents[1]
    labels = {p.parent.name: study_label(f"calibrated:{p}")
              for p in sorted((root / "baselines" / "calibrated").glob("*/calibrated.toml"))}
    assert labels["diffusion"] == "calibrated diffusion"
    assert labels["diffusion_exitance"] == "calibrated diffusion (extrapolated, J exitance)"
    assert labels["transport"] == "calibrated transport"
    assert labels["transport_interior"] == "calibrated transport (interior)"
    assert labels["collision_delta_eddington"] == "calibrated collision (δ-Eddington)"
    assert labels["collision_interior_shade_trilinear"] == \
        "calibrated collision (interior, depth 1 mfp', read 1 cell deep, trilinear)"
    assert labels["collision_interior_depth05_shade_trilinear"] == \
        "calibrated collision (interior, depth 0.5 mfp', read 1 cell deep, trilinear)"
    same_fit = {"best", "collision_n16", "collision_n64", "diffusion_n16",      # the same fits at another grid
                "collision_interior_shade_trilinear_n16", "collision_interior_shade_trilinear_n64",
                "collision_interior_depth05_shade_trilinear_n16", "collision_interior_depth05_shade_trilinear_n64"}
    assert len({v for k, v in labels.items() if k not in same_fit}) == len(labels) - len(same_fit)
    assert not any(is_extension({"method": "sslpv", "family": v}) for v in labels.values())
