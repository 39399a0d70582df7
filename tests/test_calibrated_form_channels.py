"""Eq. (F9): the loss form (F8) with each colour channel at its own terms.

SSLPV propagates each colour channel alone (``sigma_lpv`` is per colour), and a form's scales are per cell and
channel, so a channel's image depends on that channel's scales only and the relMSE (C1) is the mean of the
channels'. The synthetic scenes here give each channel its own optimum, set by that channel's terms.
"""

import math

import numpy as np
import pytest

from harness.calibration.fit import SceneSamples
from harness.calibration.form import fold_fits_loss, scene_terms
from harness.calibration.form_fit import loo_testable_terms
from harness.calibration.form_loss import (_losses, fit_loss_form, loss_power, scan_grid, scene_table,
                                           scene_table_channels, table_loss)
from harness.metrics import compute

SCAN = [2.0 ** k for k in range(-4, 7)]


def channel_scene(rng, name, u_star, v_star, shape=(12, 10)):
    """A scene whose channel ``c`` at ``u = ln s`` departs from the reference as in the (F8) tests, with its own
    optimum ``(u_star[c], v_star[c])`` -> (SceneSamples, ref, {s: image})."""
    ref = rng.uniform(0.1, 2.0, (*shape, 3))
    w, noise = rng.normal(0.0, 1.0, ref.shape), rng.lognormal(0.0, 0.1, ref.shape)
    u_star, v_star = np.asarray(u_star, np.float64), np.asarray(v_star, np.float64)
    smp = SceneSamples(name, {"full": ref.ravel(), "half_a": ref.ravel(), "half_b": ref.ravel()})
    images = {}
    for s in SCAN:
        images[s] = ref * np.exp(0.5 * w * (math.log(s) - u_star) - v_star) * noise
        smp.add(s, images[s].ravel())
    return smp, ref, images


def channel_suite(seed, n=10, slope_u=0.8, slope_v=0.4, same_means=False):
    """``n`` scenes, two terms per channel; channel ``c`` of scene ``i`` has its optimum at ``u* = 0.5 + slope_u
    x0_ic``, ``v* = -0.3 + slope_v x1_ic``. ``same_means``: ``x0`` differs between the channels of a scene but
    its mean over them is the same in every scene (the scene-level term is constant)."""
    rng = np.random.default_rng(seed)
    X = np.stack([rng.uniform(-1.0, 1.0, (n, 3)), rng.normal(0.0, 1.0, (n, 3))], axis=-1)      # (n, 3, 2)
    if same_means:
        X[..., 0] -= X[..., 0].mean(axis=1, keepdims=True)
    samples = [channel_scene(rng, f"s{i}", 0.5 + slope_u * X[i, :, 0], -0.3 + slope_v * X[i, :, 1])[0]
               for i in range(n)]
    grid = scan_grid(SCAN)
    return X, grid, [scene_table_channels(smp, grid) for smp in samples], samples


class TestChannelTable:
    def test_the_channels_mean_is_the_scene_table(self):
        """Every channel has the same pixels, so the mean of the channels' (A, B, C) is the scene's (C1)."""
        _, grid, tabs, samples = channel_suite(1, n=3)
        for tab, smp in zip(tabs, samples):
            assert np.allclose(tab.mean(axis=0), scene_table(smp, grid), rtol=1e-12, atol=0.0)

    def test_a_channels_loss_at_a_sample_is_the_registered_relmse_of_that_channel(self):
        """At a scanned ``s`` and one ``r`` per channel, the table's ln relMSE is the registered relMSE of the image
        with each channel scaled by its own ``r`` (a second route)."""
        rng = np.random.default_rng(2)
        smp, ref, images = channel_scene(rng, "a", [0.3, -0.5, 1.0], [0.2, 0.0, -0.4])
        grid = np.log(np.asarray(SCAN))
        tab = scene_table_channels(smp, grid)
        mask = np.ones(ref.shape[:2], bool)
        for s in SCAN[2:9:3]:
            r = np.array([0.5, 1.3, 0.9])
            want = compute("relmse", images[s] * r, ref, mask).value
            L, _, _ = _losses(grid, tab[None], np.full((1, 3), math.log(s)), np.log(r)[None])
            assert L[0] == pytest.approx(math.log(want), abs=1e-9)

    def test_derivatives_per_channel_against_finite_differences(self):
        _, grid, tabs, _ = channel_suite(3, n=2)
        T = tabs[0][None]
        u, v, h = np.array([[0.31, 1.7, -1.1]]), np.array([[-0.2, 0.4, -0.9]]), 1e-6
        _, du, dv = _losses(grid, T, u, v)
        for c in range(3):
            e = np.zeros((1, 3))
            e[0, c] = h
            fu = (_losses(grid, T, u + e, v)[0][0] - _losses(grid, T, u - e, v)[0][0]) / (2 * h)
            fv = (_losses(grid, T, u, v + e)[0][0] - _losses(grid, T, u, v - e)[0][0]) / (2 * h)
            assert du[0, c] == pytest.approx(fu, rel=1e-5, abs=1e-7)
            assert dv[0, c] == pytest.approx(fv, rel=1e-5, abs=1e-7)

    def test_one_channel_is_the_scene_level_loss(self):
        """(F9) with one row per scene is (F8): the same loss and derivatives."""
        _, grid, tabs, samples = channel_suite(4, n=2)
        tab = scene_table(samples[0], grid)
        L, du, dv = _losses(grid, tab[None, None], [[0.4]], [[-0.1]])
        assert (L[0], du[0, 0], dv[0, 0]) == table_loss(grid, tab, 0.4, -0.1)


class TestChannelFit:
    def test_recovers_how_each_channels_optimum_depends_on_its_terms(self):
        X, grid, tabs, _ = channel_suite(5)
        sigma, radiance = fit_loss_form(X, grid, tabs, 0.1)
        assert sigma == pytest.approx([0.5, 0.8, 0.0], abs=0.03)
        assert radiance == pytest.approx([-0.3, 0.0, 0.4], abs=0.03)

    def test_a_dependence_within_the_scenes_is_seen_only_per_channel(self):
        """A term whose scene means are all equal: (F8) on the means has nothing to fit it on (no slope), while
        (F9) recovers it from the channels; leave-one-out says so in the loss."""
        X, grid, tabs, samples = channel_suite(6, same_means=True)
        sigma9, _ = fit_loss_form(X, grid, tabs, 0.1)
        assert sigma9[1] == pytest.approx(0.8, abs=0.05)
        means = X.mean(axis=1)
        sigma8, _ = fit_loss_form(means, grid, [scene_table(s, grid) for s in samples], 0.1)
        assert sigma8[1] == 0.0
        power = loss_power(X, grid, tabs, 0.1)
        assert power["form"] < power["scalar"] - 0.5

    def test_a_scenes_channels_are_left_out_together(self):
        """A term that only one scene's channels spread is not testable by leaving that scene out."""
        X, grid, tabs, _ = channel_suite(7)
        extra = np.full(X.shape[:2] + (1,), 0.7)
        extra[4, :, 0] = [0.1, 0.7, 1.3]
        X3 = np.concatenate([X, extra], axis=-1)
        assert list(loo_testable_terms(X3)) == [True, True, False]
        sigma, radiance = fit_loss_form(X3, grid, tabs, 0.1)
        assert sigma[3] == 0.0 and radiance[3] == 0.0


def test_held_out_scene_never_reaches_its_fold():
    X, grid, tabs, _ = channel_suite(8, n=7)
    names = [f"s{i}" for i in range(7)]
    Xd, T = {n: X[i].tolist() for i, n in enumerate(names)}, {n: tabs[i] for i, n in enumerate(names)}
    a = fold_fits_loss(names, Xd, T, grid, "s3")
    X2, T2 = dict(Xd), dict(T)
    X2["s3"], T2["s3"] = [[40.0, -9.0]] * 3, tabs[0] * 7.0
    assert fold_fits_loss(names, X2, T2, grid, "s3") == a and "s3" not in a["scenes"] and len(a["scenes"]) == 6


def test_scene_terms_per_channel_average_to_the_scene_level():
    """A suite scene's per-channel terms: their mean is the scene-level term (every channel has the same cells),
    and a medium whose colours differ has channels whose diffusion length differs."""
    from harness.regression.accuracy import small_scene
    from sslpv_gl.params import SSLPVParams

    settings = {k: getattr(SSLPVParams(), k) for k in ("resample", "phase_scaling")}
    scene = small_scene("skin_torus")
    level = scene_terms(scene, 16, 8, settings)
    chans = np.asarray(scene_terms(scene, 16, 8, settings, per_channel=True))
    assert chans.shape == (3, len(level))
    assert np.allclose(chans.mean(axis=0), list(level.values()), rtol=1e-10, atol=1e-12)
    assert np.ptp(chans[:, 0]) > 0.1                    # ln(sigma_tr dx) per colour


@pytest.mark.gl
def test_calibrate_form_channels_end_to_end(tmp_path, capsys, gl_renderer):
    """``calibrate`` then ``calibrate-form --slopes channels`` on four scenes at N = 8: the scan is served from the
    result cache (the form renders only its validation), the file reads back as a version 3 form, and a scene's
    in-sample figures are a single render of the written file measured with ``harness.metrics``."""
    import json

    from harness.cli import main
    from harness.regression.accuracy import load_case_reference, small_scene
    from sslpv_gl.calibrated import load_calibrated
    from sslpv_gl.material import MAPPINGS
    from sslpv_gl.params import SSLPVParams

    scenes = ["sphere_homogeneous", "thin_ring", "skin_torus", "apple_sphere"]
    cal = tmp_path / "cal"
    assert main(["calibrate", "--family", "collision", "--scenes", ",".join(scenes), "--grid", "8", "--steps", "4",
                 "--points", "5", "--no-progress", "--out", str(cal)]) == 0
    form = tmp_path / "form"
    assert main(["calibrate-form", "--from", str(cal), "--out", str(form), "--slopes", "channels", "--json"]) == 0
    capsys.readouterr()
    info = json.loads((form / "calibration.json").read_text())
    assert info["slopes"] == "channels" and info["served_from_cache"] == len(scenes) * 5
    res = info["results"]["N=8 steps=4"]
    for n in scenes:
        level = [res["scene_terms"][n][i] for i in range(len(res["terms"]))]
        assert np.allclose(np.mean(res["channel_terms"][n], axis=0), level, rtol=1e-10, atol=1e-12)
    c = load_calibrated(form / "calibrated.toml", tuple(MAPPINGS))
    assert c.fit["slopes"] == "channels" and any(b.form is not None for b in c.budgets)   # a version 3 form
    scene = small_scene("skin_torus")
    ref, _ = load_case_reference(scene)
    img = gl_renderer.render(scene, SSLPVParams(N=8, steps=4, mapping=f"calibrated:{form / 'calibrated.toml'}",
                                                **c.settings)).subsurface
    want = res["in_sample"]["skin_torus"]
    assert compute("relmse", img, ref["subsurface"], ref["mask"]).value == pytest.approx(want["relmse"], rel=1e-6)
    assert compute("energy_ratio", img, ref["subsurface"], ref["mask"]).value == pytest.approx(want["energy_ratio"],
                                                                                              rel=1e-6)


def test_a_radiance_scale_beyond_the_float_range_is_the_worst_loss():
    """An optimiser's trial step far out in ``v = ln r`` overflows ``r^2``: the loss there is the largest, not the
    relMSE floor's (which would draw the fit to it), and no warning is printed."""
    import warnings

    _, grid, tabs, _ = channel_suite(9, n=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        L, du, dv = _losses(grid, tabs[0][None], [[0.1, 0.2, 0.3]], [[800.0, 0.0, 0.0]])
    assert L[0] >= 1e3 - 1e-9 and np.all(du == 0.0) and np.all(dv == 0.0)
    assert L[0] > _losses(grid, tabs[0][None], [[0.1, 0.2, 0.3]], [[30.0, 0.0, 0.0]])[0][0]


@pytest.mark.gl
def test_a_channels_image_depends_on_its_own_scales_only(tmp_path, gl_renderer):
    """The premise of (F9), on the renderer: a homogeneous scene rendered with a form whose scales differ per
    channel is, channel by channel, the scene rendered with that channel's scales as scalars."""
    from harness.calibration.form import form_toml
    from harness.regression.accuracy import small_scene
    from sslpv_gl.calibrated import load_calibrated
    from sslpv_gl.material import MAPPINGS
    from sslpv_gl.material_form import TERMS
    from sslpv_gl.params import SSLPVParams

    settings = {k: getattr(SSLPVParams(), k) for k in ("skip", "outside", "resample", "lookup", "inject_size",
                                                       "inject_offset", "precision", "eta2", "phase_scaling",
                                                       "boundary_reflect")}
    scene, N, K = small_scene("skin_torus"), 8, 4
    x = np.asarray(scene_terms(scene, N, K, settings, per_channel=True))
    assert np.ptp(x[:, 0]) > 0.1                       # the channels' diffusion lengths differ
    sigma, radiance = [0.2, 0.6, -0.3, 0.0, 0.0, 0.0], [-0.1, 0.4, 0.2, 0.0, 0.0, 0.0]
    path = tmp_path / "f.toml"
    path.write_text(form_toml("collision", settings, [(N, K, TERMS, sigma, radiance)], {"loss": "t"}))
    load_calibrated(path, tuple(MAPPINGS))
    form = gl_renderer.render(scene, SSLPVParams(N=N, steps=K, mapping=f"calibrated:{path}", **settings)).subsurface
    for c in range(3):
        s = math.exp(sigma[0] + sigma[1] * x[c, 0] + sigma[2] * x[c, 1])
        r = math.exp(radiance[0] + radiance[1] * x[c, 0] + radiance[2] * x[c, 1])
        alone = gl_renderer.render(scene, SSLPVParams(N=N, steps=K, mapping="collision", sigma_scale=s,
                                                      radiance_scale=r, **settings)).subsurface
        assert np.allclose(form[..., c], alone[..., c], rtol=1e-4, atol=1e-7), c
