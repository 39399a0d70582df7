"""Eq. (F8): a calibration form fitted on the render loss (C2) through the scan's interpolated images."""

import math

import numpy as np
import pytest

from harness.calibration.fit import SceneSamples, fit
from harness.calibration.form import fold_fits_loss
from harness.calibration.form_loss import fit_loss_form, loss_power, scan_grid, scene_table, table_loss
from harness.metrics import compute

SCAN = [2.0 ** k for k in range(-4, 7)]          # the calibration's sigma_scale scan


def synthetic_scene(rng, name, u_star, v_star, shape=(12, 10, 3)):
    """A scene whose image at ``u = ln s`` departs in shape from its reference as ``u`` leaves ``u_star`` (a
    per-pixel factor ``exp(w (u - u_star) / 2)``), at level ``exp(-v_star)``, with a fixed pixel noise of 10 %
    (so its best relMSE is not 0): its optimum is ``(u_star, v_star)``. -> (SceneSamples, ref, {s: image})."""
    ref = rng.uniform(0.1, 2.0, shape)
    w, noise = rng.normal(0.0, 1.0, shape), rng.lognormal(0.0, 0.1, shape)
    smp = SceneSamples(name, {"full": ref.ravel(), "half_a": ref.ravel(), "half_b": ref.ravel()})
    images = {}
    for s in SCAN:
        images[s] = ref * np.exp(0.5 * w * (math.log(s) - u_star) - v_star) * noise
        smp.add(s, images[s].ravel())
    return smp, ref, images


def material_suite(seed, n=10, slope_u=0.8, slope_v=0.4):
    """``n`` scenes with two terms; each scene's optimum is ``u* = 0.5 + slope_u x0``, ``v* = -0.3 + slope_v x1``."""
    rng = np.random.default_rng(seed)
    X = np.column_stack([rng.uniform(-1.0, 1.0, n), rng.normal(0.0, 1.0, n)])
    samples = [synthetic_scene(rng, f"s{i}", 0.5 + slope_u * X[i, 0], -0.3 + slope_v * X[i, 1])[0] for i in range(n)]
    grid = scan_grid(SCAN)
    return X, grid, [scene_table(smp, grid) for smp in samples], samples


class TestTable:
    def test_loss_at_a_sample_is_the_registered_relmse(self):
        """At a scanned ``s`` the table holds that render's (A, B, C): ln relMSE equals the metric's (a second route)."""
        rng = np.random.default_rng(1)
        smp, ref, images = synthetic_scene(rng, "a", 0.3, 0.2)
        grid = np.log(np.asarray(SCAN))                  # the scan's own samples as the grid
        tab = scene_table(smp, grid)
        mask = np.ones(ref.shape[:2], bool)
        for s in SCAN[2:9:3]:
            for r in (0.5, 1.3):
                want = compute("relmse", r * images[s], ref, mask).value
                got = table_loss(grid, tab, math.log(s), math.log(r))[0]
                assert got == pytest.approx(math.log(want), abs=1e-9)

    def test_derivatives_against_finite_differences(self):
        X, grid, tabs, _ = material_suite(2)
        h = 1e-6
        for tab in tabs[:4]:
            for u, v in ((0.31, -0.2), (1.7, 0.4), (-1.1, -0.9)):
                _, du, dv = table_loss(grid, tab, u, v)
                fu = (table_loss(grid, tab, u + h, v)[0] - table_loss(grid, tab, u - h, v)[0]) / (2 * h)
                fv = (table_loss(grid, tab, u, v + h)[0] - table_loss(grid, tab, u, v - h)[0]) / (2 * h)
                assert du == pytest.approx(fu, rel=1e-5, abs=1e-7) and dv == pytest.approx(fv, rel=1e-5, abs=1e-7)

    def test_u_beyond_the_scan_is_clamped(self):
        X, grid, tabs, _ = material_suite(3)
        end = table_loss(grid, tabs[0], grid[-1], 0.1)
        beyond = table_loss(grid, tabs[0], grid[-1] + 2.0, 0.1)
        assert beyond[0] == pytest.approx(end[0]) and beyond[1] == 0.0


class TestFit:
    def test_a_large_penalty_is_the_scalar_calibration(self):
        """lam -> inf: every slope 0 and the level the scalar fit's (C2), minimised by Brent on the image spline
        (:func:`harness.calibration.fit.fit`, a second route), within the table's grid spacing."""
        X, grid, tabs, samples = material_suite(4)
        sigma, radiance = fit_loss_form(X, grid, tabs, 1e9)
        assert max(map(abs, sigma[1:] + radiance[1:])) < 1e-5
        f = fit(samples)
        step = grid[1] - grid[0]
        assert sigma[0] == pytest.approx(math.log(f.s), abs=step) and radiance[0] == pytest.approx(math.log(f.r),
                                                                                                 abs=step)

    def test_recovers_how_the_optimum_depends_on_the_material(self):
        X, grid, tabs, _ = material_suite(5)
        sigma, radiance = fit_loss_form(X, grid, tabs, 0.1)
        assert sigma == pytest.approx([0.5, 0.8, 0.0], abs=0.03)
        assert radiance == pytest.approx([-0.3, 0.0, 0.4], abs=0.03)

    def test_leave_one_out_prefers_the_form_where_the_terms_predict(self):
        X, grid, tabs, _ = material_suite(6)
        power = loss_power(X, grid, tabs, 0.1)
        assert power["form"] < power["scalar"] - 1.0

    def test_a_term_one_scene_sets_apart_gets_no_slope(self):
        X, grid, tabs, _ = material_suite(7)
        X = np.column_stack([X, np.r_[np.full(len(X) - 1, 1.322), 1.253]])
        sigma, radiance = fit_loss_form(X, grid, tabs, 0.1)
        assert sigma[3] == 0.0 and radiance[3] == 0.0


def test_held_out_scene_never_reaches_its_fold():
    """Leave one scene out: the held-out scene's terms and table may be anything."""
    X, grid, tabs, _ = material_suite(8, n=7)
    names = [f"s{i}" for i in range(7)]
    Xd, T = {n: list(X[i]) for i, n in enumerate(names)}, {n: tabs[i] for i, n in enumerate(names)}
    a = fold_fits_loss(names, Xd, T, grid, "s3")
    X2, T2 = dict(Xd), dict(T)
    X2["s3"], T2["s3"] = [40.0, -9.0], tabs[0] * 7.0
    assert fold_fits_loss(names, X2, T2, grid, "s3") == a and "s3" not in a["scenes"] and len(a["scenes"]) == 6
