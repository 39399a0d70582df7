"""Step groups render every step count with that count's own parameters, for every mapping family.

A step group (:meth:`~sslpv_gl.renderer.SSLPVRenderer.render_steps`, the sweep's and the
nightly's groups) shares RSM and injection between its step counts. A calibrated mapping
has its own ``sigma_scale`` and ``radiance_scale`` per budget, so its counts may need
several propagations (one per distinct ``sigma_scale``) and a radiance scale per shading.
Each grouped image must be bit-identical to a single render at its count:

* every plain family (``literal``, ``collision``, ``diffusion``) over a mixed step list;
* the committed calibrations (``baselines/calibrated/``) at all their integer budgets, by
  the renderer, by the sweep worker and by two sweeps (grouped against one count alone);
* synthetic calibrated files whose budgets differ in ``radiance_scale`` only (one shared
  propagation, rescaled per count) and in both scales at every count.
"""

import numpy as np
import pytest

from harness.regression.accuracy import small_scene
from harness.scene import load_scene
from sslpv_gl.params import SSLPVParams

pytestmark = pytest.mark.gl

COMMITTED = {"diffusion": ("baselines/calibrated/diffusion/calibrated.toml", 0),
             "collision": ("baselines/calibrated/collision/calibrated.toml", 2)}
SETTINGS = """[settings]
skip = 0
outside = "vacuum"
resample = "box"
lookup = "cell"
inject_size = 64
inject_offset = 0.0
precision = "fp32"
eta2 = false
"""


def _budget(N, steps, s, r):
    steps = f'"{steps}"' if isinstance(steps, str) else steps
    return f"[[budget]]\nN = {N}\nsteps = {steps}\nsigma_scale = {s}\nradiance_scale = {r}\n"


def _calibrated(tmp_path, name, family, budgets):
    p = tmp_path / f"{name}.toml"
    p.write_text(f'format = "sslpv-calibrated-mapping"\nversion = 2\nfamily = "{family}"\n{SETTINGS}'
                 + "".join(_budget(16, *b) for b in budgets))
    return p


def _assert_grouped_is_single(renderer, scene, params, ks):
    group = renderer.render_steps(scene, params, ks)
    assert [r.steps_used for r in group] == sorted(set(ks))
    for r in group:
        alone = renderer.render(scene, params.replace(steps=r.steps_used))
        assert np.array_equal(r.subsurface, alone.subsurface), (params.mapping, r.steps_used)
        assert np.array_equal(r.full, alone.full), (params.mapping, r.steps_used)
        assert r.calibration == alone.calibration, r.steps_used
    return group


@pytest.mark.parametrize("mapping,skip", [("literal", 2), ("collision", 2), ("diffusion", 0)])
def test_plain_families(gl_renderer, mapping, skip):
    scene = load_scene("two_lights").with_resolution(32, 32)
    params = SSLPVParams(N=16, mapping=mapping, skip=skip, rsm_size=256, inject_size=64)
    _assert_grouped_is_single(gl_renderer, scene, params, [12, skip, 5, 12, 3])


@pytest.mark.parametrize("family", sorted(COMMITTED))
def test_committed_calibrations(gl_renderer, family):
    path, skip = COMMITTED[family]
    scene = small_scene("sphere_homogeneous")
    params = SSLPVParams(N=32, steps=8, mapping=f"calibrated:{path}", skip=skip)
    group = _assert_grouped_is_single(gl_renderer, scene, params, [32, 8, 64, 16])
    # power: the budgets really differ, so rendering every count with one budget would be seen
    sigmas = {r.calibration["steps"]: r for r in group}
    assert len(sigmas) == 4
    assert not np.array_equal(group[0].subsurface / group[0].subsurface.max(),
                              group[1].subsurface / group[1].subsurface.max())


def test_budgets_that_differ_in_radiance_scale_only(gl_renderer, tmp_path):
    """One propagation, shaded at each count with its own radiance scale (and 1 at one of them)."""
    p = _calibrated(tmp_path, "r_only", "collision", [(4, 1.5, 1.0), (9, 1.5, 2.5), (14, 1.5, 0.4)])
    scene = load_scene("two_lights").with_resolution(32, 32)
    params = SSLPVParams(N=16, steps=4, mapping=f"calibrated:{p}", skip=0, rsm_size=256, inject_size=64)
    group = _assert_grouped_is_single(gl_renderer, scene, params, [14, 4, 9])
    assert "host_material" in group[0].timings_ms["shared"]          # one material, one propagation


def test_budgets_that_differ_in_sigma_scale(gl_renderer, tmp_path):
    """Distinct sigma scales: a propagation each from the same injected grid; equal ones still share."""
    p = _calibrated(tmp_path, "mixed", "diffusion", [(3, 0.5, 1.2), (6, 2.0, 0.7), (11, 2.0, 1.9), (15, 6.0, 1.0)])
    scene = load_scene("two_lights").with_resolution(32, 32)
    params = SSLPVParams(N=16, steps=3, mapping=f"calibrated:{p}", skip=0, rsm_size=256, inject_size=64)
    group = _assert_grouped_is_single(gl_renderer, scene, params, [15, 3, 11, 6])
    assert "host_material" not in group[0].timings_ms["shared"]
    # each count's propagation time is its own group's steps: the count after a new material restarts
    props = {r.steps_used: r.timings_ms["propagation"] for r in group}
    assert props[11] >= props[6]


def test_sweep_worker_groups(tmp_path):
    """``harness.runs.worker.run_group`` (what a sweep runs) against a single configuration, per count."""
    from harness.regression.accuracy import load_case_reference
    from harness.runs.worker import reference_floors, run_group

    path, skip = COMMITTED["diffusion"]
    scene = small_scene("sphere_homogeneous")
    params = dict(N=32, mapping=f"calibrated:{path}", skip=skip)
    ref, _ = load_case_reference(scene)
    floors = reference_floors(ref)
    size = (scene.camera.width, scene.camera.height)
    grouped = run_group(scene.path, size, params, [8, 32], ref, floors)
    alone = run_group(scene.path, size, params, [32], ref, floors)[0]
    assert grouped[1]["status"] == alone["status"] == "ok", (grouped[1].get("error"), alone.get("error"))
    assert grouped[1]["calibration"]["steps"] == 32
    for part in ("subsurface", "full"):
        assert np.array_equal(grouped[1]["images"][part], alone["images"][part]), part
    value = {(m["image"], m["metric"]): m["value"] for m in alone["metrics"]}
    assert all(m["value"] == value[(m["image"], m["metric"])] for m in grouped[1]["metrics"])
