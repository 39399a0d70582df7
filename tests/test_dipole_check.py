"""Every rival render checks a few points against the NumPy twin (``dipole_gl.check``) and refuses a wrong result.

A wrong result is planted by scaling the twin's answer by 1.01 (ten times the tolerance
``CHECK_RTOL`` = 1e-3): the renderer must raise ``ResultRefused``, the ``render`` command must print
one line and exit 1 without writing its folder, and a sweep's worker must record a failed
configuration. Unchanged, the check passes with its figures in ``info["check"]``.
"""

import numpy as np
import pytest

from harness.errors import ResultRefused
from dipole_gl import check, twin
from dipole_gl.params import DipoleParams
from harness.scene import load_scene

pytestmark = pytest.mark.gl

SCENE = "two_lights"
CONFIGS = [("dipole", DipoleParams(spacing=3.0)), ("dirpole", DipoleParams(spacing=3.0)),
           ("dipole", DipoleParams(gather="vertex", density=0.25, range=2.0)),
           ("dirpole", DipoleParams(gather="vertex", density=0.25, range=2.0))]


@pytest.fixture
def wrong_twin(monkeypatch):
    """The twin's dense and vertex gathers off by 1 %."""
    for name in ("dense_gather", "vertex_gather"):
        real = getattr(twin, name)
        monkeypatch.setattr(twin, name, lambda *a, _real=real, **k: 1.01 * _real(*a, **k))


def test_compare():
    ref = np.array([[1.0, 2.0, 0.0], [0.5, 1.0, 0.0]])
    assert check.compare(ref * (1 + 0.5 * check.CHECK_RTOL), ref, "x") <= check.CHECK_RTOL
    with pytest.raises(ResultRefused, match=r"^x: the GL result disagrees with the NumPy twin at 2 checked points"):
        check.compare(ref * (1 + 2 * check.CHECK_RTOL), ref, "x")
    with pytest.raises(ResultRefused):
        check.compare(np.where(ref > 1.5, np.nan, ref), ref, "x")


@pytest.mark.parametrize("kernel,params", CONFIGS, ids=lambda x: getattr(x, "gather", x))
def test_render_records_its_check(dipole_renderer, kernel, params):
    res = dipole_renderer.render(load_scene(SCENE).with_resolution(16, 16), kernel, params)
    c = res.info["check"]
    print(f"{kernel} {params.gather}: {c}")
    assert c["points"] == check.CHECK_POINTS and c["max_rel_diff"] <= check.CHECK_RTOL and c["twin_evaluations"] > 0


@pytest.mark.parametrize("kernel,params", CONFIGS, ids=lambda x: getattr(x, "gather", x))
def test_a_wrong_result_is_refused(dipole_renderer, wrong_twin, kernel, params):
    with pytest.raises(ResultRefused, match=f"{SCENE}: {kernel} {params.gather} gather: the GL result disagrees"):
        dipole_renderer.render(load_scene(SCENE).with_resolution(16, 16), kernel, params)


def test_render_command_exits_1_with_one_line(wrong_twin, tmp_path, capsys):
    from harness.cli.main import main

    code = main(["render", SCENE, "--method", "dipole", "--spacing", "3", "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1 and len(err) == 1 and err[0].startswith(f"error: {SCENE}: dipole dense gather: the GL result "
                                                             "disagrees with the NumPy twin"), (code, err)
    assert not (tmp_path / "r").exists()


def test_sweep_records_a_failed_configuration(wrong_twin):
    from harness.runs.worker import run_method

    scene = load_scene(SCENE)
    out = run_method(str(scene.path), (16, 16), "dirpole", {"gather": "dense", "spacing": 3.0}, None, None)
    assert out["status"] == "failed" and out["error"].startswith("ResultRefused: "), out
