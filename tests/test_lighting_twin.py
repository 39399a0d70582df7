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


def _verdict_file(folder, scene, grid=32, content_hash=None):
    """A verdicts file as ``benchmarks/lighting_twin.py --write`` writes it: at K = 32 no setting can put both in
    range (the closest, ``b``, reaches 0.02: the twin at least 0.8 / 0.02 = 40 times its truth); at steady one can."""
    import json

    rows32 = {"a": {"usable": True, "low": 1e-4, "high": 0.01, "possible": False, "twin_at_least": 80.0},
              "b": {"usable": True, "low": 0.005, "high": 0.02, "possible": False, "twin_at_least": 40.0},
              "c": {"usable": False}}
    rows_steady = {"a": {"usable": True, "low": 0.5, "high": 1.2, "possible": True, "twin_at_least": 0.667},
                   "b": {"usable": True, "low": 0.1, "high": 0.3, "possible": False, "twin_at_least": 2.67},
                   "c": {"usable": True, "low": 0.7, "high": 0.9, "possible": True, "twin_at_least": 0.889}}
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{scene.name}.json").write_text(json.dumps({
        "format": "sslpv-lighting-twin", "scene": scene.name, "content_hash": content_hash or scene.content_hash,
        "grid": grid, "budgets": {"32": rows32, "steady": rows_steady}, "page": "docs/benchmarks/x.md",
        "command": "python benchmarks/lighting_twin.py", "commit": "abc"}))


def test_committed_verdicts_count_the_settings_and_take_the_closest(backlit, tmp_path):
    _verdict_file(tmp_path, backlit)
    got = twin.committed_verdicts(backlit, 32, tmp_path)
    assert got["measured"] and got["page"] == "docs/benchmarks/x.md"
    assert got["budgets"]["32"] == {"possible": 0, "of": 3, "closest": "b", "largest": 0.02, "twin_at_least": 40.0}
    assert got["budgets"]["steady"] == {"possible": 2, "of": 3, "closest": "a", "largest": 1.2,
                                        "twin_at_least": 0.667}


def test_committed_verdicts_of_another_grid_or_a_changed_scene_are_not_used(backlit, tmp_path):
    _verdict_file(tmp_path / "g", backlit, grid=16)
    assert "N = 16" in twin.committed_verdicts(backlit, 32, tmp_path / "g")["why"]
    _verdict_file(tmp_path / "h", backlit, content_hash="0" * 64)
    assert "changed" in twin.committed_verdicts(backlit, 32, tmp_path / "h")["why"]
    assert "lighting_twin.py --scene backlit_sphere" in twin.committed_verdicts(backlit, 32, tmp_path / "none")["why"]


def test_the_studys_limits_say_what_the_lighting_twin_found(tmp_path, monkeypatch):
    """``harness.study.limits.lighting`` keeps the study's budgets, and the line of *What limits SSLPV here* names
    the count of settings per budget and, where none can, the least the other lighting renders at."""
    from harness.scene import load_scene
    from harness.study import limits, present

    _verdict_file(tmp_path, load_scene("backlit_sphere"))
    monkeypatch.setattr(twin, "VERDICTS", tmp_path)
    got = limits.lighting("backlit_sphere", {"grid": 32, "steps": [8, 32]})
    assert list(got["budgets"]) == ["32"]
    got = limits.lighting("backlit_sphere", {"grid": 32, "steps": [32, "steady"]})
    line = [x for x in present.limit_lines({
        "subject": "s", "relmse": 0.1, "floor": 0.01, "steps": {"measured": False, "why": "-"},
        "outside": {"measured": False, "why": "-"}, "boundary": {"measured": False, "why": "-"},
        "mapping": {"measured": False, "why": "-"}, "lighting": got}) if x.startswith("Lighting twin")]
    assert len(line) == 1
    assert "K = 32: 0 of 3 (with the closest, b, the other lighting renders at least 40 times" in line[0]
    assert "steady: 2 of 3." in line[0]
    assert not limits.lighting("sphere_homogeneous", {"grid": 32, "steps": [32]})["measured"]


def test_the_committed_verdicts_are_of_the_scenes_as_they_are():
    """Every committed verdicts file judges its scene as the scene's file declares it now (a changed scene is
    reported as not measured, so a stale file would silently drop its line from the study)."""
    import json

    from harness.scene import load_scene

    files = sorted(twin.VERDICTS.glob("*.json"))
    for path in files:
        data = json.loads(path.read_text())
        got = twin.committed_verdicts(load_scene(data["scene"]), data["grid"])
        assert got["measured"], (path.name, got)
        assert set(got["budgets"]) == {"8", "16", "32", "64", "steady"}
