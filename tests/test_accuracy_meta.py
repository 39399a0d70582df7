"""Meta-tests of the accuracy tests: a deliberate error in the method must fail them,
and a reference re-rendered with new seeds must not (no false alarm from noise)."""

import numpy as np
import pytest

from harness.regression.accuracy import cases, check_case, small_scene
from harness.regression.baselines import BASELINE_DIR
from harness.runs.sweep import load_reference
from harness.runs.worker import reference_floors
from sslpv_gl.params import SSLPVParams

pytestmark = [pytest.mark.accuracy, pytest.mark.gl]
RESEEDED = BASELINE_DIR / "refs_reseeded"
TOL = dict(cases()[0][2])


@pytest.fixture()
def renderer():
    from sslpv_gl.renderer import SSLPVRenderer

    return SSLPVRenderer()


def sabotage(renderer, monkeypatch, change):
    original = renderer.lpv_material

    def broken(scene, params):
        return change(dict(original(scene, params)))

    monkeypatch.setattr(renderer, "lpv_material", broken)


# The check is one-sided (it fails on worse, never on better), so each sabotage is paired
# with a case where it makes SSLPV less accurate; benchmarks/accuracy_sensitivity.py lists
# which cases catch which sabotage over the whole matrix.
DOUBLE_ABSORPTION = lambda m: dict(m, sigma_lpv=m["sigma_lpv"] * 2)  # noqa: E731
NO_SCATTERING = lambda m: dict(m, sigma_s_prime=np.zeros_like(m["sigma_s_prime"]))  # noqa: E731


@pytest.mark.parametrize("scene,params,change,why", [
    ("absorbing_sphere", SSLPVParams(N=32, steps=32), DOUBLE_ABSORPTION, "doubled absorption"),
    ("backlit_slab", SSLPVParams(N=16, steps=8), DOUBLE_ABSORPTION, "doubled absorption"),
    ("two_lights", SSLPVParams(N=16, steps=8), NO_SCATTERING, "Eq. 3 scattering dropped"),
    ("thin_ring", SSLPVParams(N=32, steps=8), NO_SCATTERING, "Eq. 3 scattering dropped"),
])
def test_deliberate_error_fails(renderer, monkeypatch, tmp_path, scene, params, change, why):
    clean = check_case(renderer, scene, params, TOL, artifacts=tmp_path)
    assert not clean.failed, clean.message()
    sabotage(renderer, monkeypatch, change)
    broken = check_case(renderer, scene, params, TOL, artifacts=tmp_path)
    assert broken.failed, f"{why} went unnoticed:\n{broken.message()}"
    # The failure leaves what a person needs: images, error map, and the accepting command.
    assert (broken.artifacts / "error_map.png").is_file()
    assert (broken.artifacts / "store.sqlite").is_file()
    assert "sslpv-harness baselines update --scene" in broken.message()


@pytest.mark.parametrize("scene", sorted(p.name for p in RESEEDED.iterdir()) if RESEEDED.is_dir() else [])
def test_reseeded_reference_does_not_fail(renderer, tmp_path, scene):
    s = small_scene(scene)
    ref = load_reference(RESEEDED / scene, (s.camera.height, s.camera.width))
    floors = reference_floors(ref)
    for name, params, tol in cases():
        if name != scene:
            continue
        result = check_case(renderer, scene, params, tol, ref=ref, floors=floors, artifacts=tmp_path)
        assert not result.failed, result.message()


def test_reseeded_references_exist():
    """The meta-test above must run on at least two scenes, not silently on none."""
    assert RESEEDED.is_dir() and len(list(RESEEDED.iterdir())) >= 2


def test_matrix_also_tables_add_cases_once():
    """[[also]] tables add further products to the accuracy matrix; a case already there is not repeated."""
    from harness.regression.accuracy import cases

    m = {"scenes": ["thin_ring"], "params": {"grid": [16], "steps": [8], "mapping": ["collision"]},
         "also": [{"grid": [16, 32], "steps": [8], "mapping": ["collision", "diffusion"], "skip": [2]}]}
    got = [(p.N, p.mapping, p.skip) for _, p, _ in cases(m)]
    assert got == [(16, "collision", 2), (16, "diffusion", 2), (32, "collision", 2), (32, "diffusion", 2)]
