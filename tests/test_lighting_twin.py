"""The lighting twin (``harness.study.twin``): the mirror, the bound (W3) against the study's own energy
metric, the verdict (W4), and the premises: the calibrated scales see no light, SSLPV is linear in the
radiance scale, and a scan's rows are the renderer's own."""

import dataclasses

import numpy as np
import pytest

from harness.calibration.run import _reference
from harness.errors import InputError
from harness.metrics import compute
from harness.study import twin


@pytest.fixture(scope="module")
def backlit():
    return _reference("backlit_sphere", None)[0]


def _view(scene):
    v = np.subtract(scene.camera.target, scene.camera.origin)
    return v / np.linalg.norm(v)


def test_the_twin_mirrors_each_light_to_the_other_side(backlit):
    front = twin.lighting_twin(backlit)
    c = np.asarray(backlit.mesh.vertices, float).mean(axis=0)
    v = _view(backlit)
    for a, b in zip(backlit.lights, front.lights):
        pa, pb = np.asarray(a.position), np.asarray(b.position)
        assert (pa - c) @ v > 0.5 and (pb - c) @ v == pytest.approx(-((pa - c) @ v))   # behind -> in front
        assert np.linalg.norm(pb - c) == pytest.approx(np.linalg.norm(pa - c))
        # what lies in the mirror plane is kept
        assert (pb - c) - ((pb - c) @ v) * v == pytest.approx((pa - c) - ((pa - c) @ v) * v)
        assert b.intensity == a.intensity
    back = twin.lighting_twin(front)
    assert np.allclose([lt.position for lt in back.lights], [lt.position for lt in backlit.lights])
    assert front.mesh is backlit.mesh and front.medium is backlit.medium and front.camera is backlit.camera
    assert front.content_hash != backlit.content_hash


def test_a_light_in_the_mirror_plane_is_refused(backlit):
    c = np.asarray(backlit.mesh.vertices, float).mean(axis=0)
    side = c + 3.0 * np.cross(_view(backlit), [0.0, 1.0, 0.0])
    scene = dataclasses.replace(backlit, lights=(dataclasses.replace(backlit.lights[0], position=tuple(side)),))
    with pytest.raises(InputError, match="lights.position"):
        twin.lighting_twin(scene)


def test_the_ratio_of_energy_ratios_is_a_weighted_mean_of_the_twin_factors():
    """(W1)-(W3) against the study's own metric on images whose channels are r_c e_c(s_c)."""
    rng = np.random.default_rng(7)
    mask = rng.random((12, 10)) < 0.6
    for _ in range(50):
        e_a, e_b, t_a, t_b = (rng.uniform(0.01, 5.0, 3) for _ in range(4))
        e_a *= 10.0 ** rng.uniform(-4, 1, 3)                       # far apart channels too
        r = 10.0 ** rng.uniform(-2, 2, 3)

        def image(total):
            img = rng.uniform(0.5, 1.5, (12, 10, 3))
            return img * total / img[mask].sum(axis=0)

        rho_a = compute("energy_ratio", image(r * e_a), image(t_a), mask).value
        rho_b = compute("energy_ratio", image(r * e_b), image(t_b), mask).value
        q = twin.twin_factors(e_a, t_a, e_b, t_b)
        u = r * e_b / t_b
        assert rho_a / rho_b == pytest.approx(float((u * q).sum() / u.sum()), rel=1e-9)
        low, high, _, _ = twin.attainable(q[None, :])
        assert low * (1 - 1e-12) <= rho_a / rho_b <= high * (1 + 1e-12)


def test_attainable_takes_the_extremes_over_scale_and_channel():
    q = np.array([[1.0, 1.1, 1.2],
                  [0.2, 1.0, 1.0],          # the least, channel R
                  [np.nan, 9.0, 9.0],       # a failed render: left out
                  [1.0, 1.0, 3.0],          # the largest, channel B
                  [1.5, 1.5, 1.5]])
    assert twin.attainable(q) == (0.2, 3.0, 1, 3)
    assert twin.attainable(np.full((2, 3), np.nan)) == (None, None, None, None)
    assert twin.twin_factors([1, 1, 1], [1, 1, 1], [0, 1, 1], [1, 1, 1])[0] != twin.twin_factors(
        [1, 1, 1], [1, 1, 1], [0, 1, 1], [1, 1, 1])[0]                  # a dark twin gives nan


def test_the_verdict_closes_the_band_and_bounds_the_twin():
    lo, hi = 0.8, 1.25
    assert twin.verdict(0.1, lo / hi)["possible"]
    assert not twin.verdict(0.1, lo / hi * (1 - 1e-9))["possible"]
    assert twin.verdict(hi / lo, 9.0)["possible"]
    assert not twin.verdict(hi / lo * (1 + 1e-9), 9.0)["possible"]
    v = twin.verdict(1e-4, 2e-4)
    assert v["band"] == (pytest.approx(0.64), pytest.approx(1.5625))
    assert v["twin_at_least"] == pytest.approx(0.8 / 2e-4)
    assert v["twin_at_most"] == pytest.approx(1.25 / 1e-4)


def test_the_calibrated_scales_see_no_light(backlit):
    """The premise: a form's terms (Eq. F1) are the same on a scene and its twin at every budget."""
    from harness.calibration.form import scene_terms

    settings = {"resample": "box", "phase_scaling": "none"}
    front = twin.lighting_twin(backlit)
    for steps in (32, "steady"):
        assert scene_terms(backlit, 16, steps, settings) == scene_terms(front, 16, steps, settings)


@pytest.fixture(scope="module")
def renderer():
    from sslpv_gl.renderer import SSLPVRenderer

    return SSLPVRenderer()


def test_sslpv_is_linear_in_the_radiance_scale_per_channel(backlit, renderer):
    """The premise of (W1): the masked energy of each channel is r_c e_c(s)."""
    from sslpv_gl.params import SSLPVParams

    mask = np.ones((backlit.camera.height, backlit.camera.width), bool)
    p = SSLPVParams(N=12, steps=12, sigma_scale=0.7)
    e1 = twin.channel_energies(renderer.render(backlit, p).subsurface, mask)
    e2 = twin.channel_energies(renderer.render(backlit, p.replace(radiance_scale=2.5)).subsurface, mask)
    assert (e1 > 0).all()
    assert e2 == pytest.approx(2.5 * e1, rel=1e-5)


def test_a_scan_is_the_renderers_own_and_refuses_a_varying_medium(backlit, renderer):
    from sslpv_gl.params import SSLPVParams

    front = twin.lighting_twin(backlit)
    mask = np.ones((backlit.camera.height, backlit.camera.width), bool)
    p = SSLPVParams(N=12, outside="absorb")
    out = twin.scan(renderer, backlit, front, p, (0.5, 2.0), (4, 8, "steady"), mask)
    assert set(out) == {4, 8, "steady"}
    for i, s in enumerate((0.5, 2.0)):
        for j, sc in enumerate((backlit, front)):
            for b in (8, "steady"):
                alone = twin.channel_energies(renderer.render(sc, p.replace(sigma_scale=s, steps=b)).subsurface, mask)
                assert out[b][j][i] == pytest.approx(alone, rel=1e-4)
    assert (out[8][1] > out[4][1]).all()                     # more steps, more light
    veins = _reference("jade_veins", None)[0]
    with pytest.raises(InputError, match="medium"):
        twin.scan(renderer, veins, veins, p, (1.0,), (4,), mask)
