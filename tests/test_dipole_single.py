"""Jensen et al. 2001's single-scattering term S^(1) (``dipole_gl/single.py``, ``single.comp``).

Four routes, each independent of the one it checks:

* GL against the NumPy twin (``dipole_gl/single_twin.py``) at every covered pixel of a chromatic
  scene behind a dielectric with two lights, one on each side: ``max |GL - twin| <= 1e-4`` of the
  largest value (float32 against float64, as ``tests/test_dipole_gl.py``);
* GL against the closed form on a half-space under a distant light
  (:func:`dipole_gl.single_twin.halfspace`), whose only stated approximation is the march's
  midpoint rule: for ``int_0^1 (1 - u)^a du = 1/(1 + a)`` its relative error
  ``|M_N(a)(1 + a) - 1|`` is computed per pixel and colour and is the tolerance, plus float32
  (``s_i = |y - x| - d_i`` is a difference of two distances of about ``d``, each to ``2^-24 d``:
  ``2^-23 d max(sigma_t)``, 1.5e-3 at ``d = 1000``) and the light's finite distance (the closed
  form is a plane wave with the irradiance at the exit point, the estimator spreads the beam over
  ``s'``: ``2 s'/d`` with ``s' <= 2/min(sigma_t)``, 5e-4);
* GL against Mitsuba's single-scattering image (``tests/data/single``, ``benchmarks/single_refs.py``:
  ``max_depth`` 2 index-matched, 4 through a smooth dielectric), index-matched and at ``eta = 1.3``,
  front- and back-lit, ``g = 0.5``, 24 x 24. The ratio of the image means over the pixels two
  pixels inside the footprint (the march does not see where the view ray leaves the object: at the
  edge of a slab it runs on into the air, a stated limit) must satisfy
  ``|ratio - 1| <= 3 SE + delta`` (``single_refs.compare_case``): ``SE`` the standard error of the reference's mean (its seeds),
  ``delta`` the estimator's known approximations, each bounded here by refining it: the march
  (64 against 256 nodes, twin), the light atlas (1024^2 against 2048^2 texels), the pixel (GL
  shades the pixel centre, Mitsuba averages the footprint: against 2 x 2 centres per pixel), and at
  ``eta != 1`` the straight line to the light (``single_refs.flat_exact``: the same estimator with the true
  refraction point on the slab's plane and the medium ending at the slab's far face);
* the loop budget: one invocation's march x lights x taps stays under ``ITERATION_BUDGET``.
"""

import sys
from pathlib import Path

import numpy as np
import pytest

from dipole_gl import budget, single, single_twin
from dipole_gl.glsl import MAX_LIGHTS
from dipole_gl.medium import scene_material
from dipole_gl.params import DipoleParams
from sslpv_gl.optics import fresnel_transmittance, refract

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import single_refs  # noqa: E402

DATA = Path(__file__).resolve().parent / "data" / "single"
#: The validation cases the test judges (``slab_front_eta1``, a thin slab lit from the camera's side,
#: shows the march's limit on the benchmark page; ``sphere_front_eta13`` has no flat-interface bound).
MITSUBA_CASES = ("sphere_front_eta1", "slab_back_eta1", "thick_front_eta1", "slab_back_eta13", "thick_front_eta13")


def test_march_within_loop_budget():
    assert single.iterations(MAX_LIGHTS) <= budget.ITERATION_BUDGET


@pytest.fixture
def without_self_check(monkeypatch):
    """The render's own check against the twin switched off (``dipole_gl.check``): a test against an
    independent route must catch an error of the shader by its own tolerance, not by the check's refusal
    (which ``test_gl_matches_twin`` and ``tests/test_dipole_check.py`` cover)."""
    from dipole_gl import check

    monkeypatch.setattr(check, "CHECK_RTOL", np.inf)


def _scene_two_lights():
    from harness.scene.load import PointLight, scene_hash
    import dataclasses

    sc = single_refs.case_scene("slab_back_eta13")
    m = sc.medium
    g = np.broadcast_to(np.array([0.5, 0.3, -0.2], np.float32), m.g.shape).copy()
    st = np.broadcast_to(np.array([6.0, 8.0, 11.0], np.float32), m.sigma_t.shape).copy()
    sc = sc.with_medium(g=g, sigma_t=st).with_resolution(16, 16)
    lights = sc.lights + (PointLight((0.7, -0.4, 2.6), (3.0, 4.0, 5.0)),)
    sc = dataclasses.replace(sc, lights=lights, content_hash="")
    return dataclasses.replace(sc, content_hash=scene_hash(sc))


@pytest.mark.gl
def test_gl_matches_twin(dipole_renderer, without_self_check):
    sc = _scene_two_lights()
    res = dipole_renderer.render(sc, "dipole", DipoleParams(terms="single"), debug=True)
    d = res.debug
    m = d["mask"]
    assert m.sum() > 100
    twin = single_twin.single_scattering(d["position"][m], d["normal"][m], sc.camera.origin, d["atlas"], d["views"],
                                         sc.lights, scene_material(sc), sc.boundary.eta, 1024)
    gl = d["single"][m]
    assert np.abs(gl - twin).max() <= 1e-4 * np.abs(twin).max()
    assert np.all(twin.max(axis=0) > 0)
    assert np.array_equal(res.subsurface, d["single"])              # terms = single: S1 alone


@pytest.mark.gl
def test_both_adds_single_to_the_gathers(dipole_renderer):
    """``terms = both`` is the ``diffusion`` image plus S^(1), for every gather."""
    sc = _scene_two_lights()
    for kw in ({"gather": "dense", "spacing": 2.0}, {"gather": "vertex", "density": 0.5, "range": 2.0},
               {"gather": "cubemap", "samples": 8, "frames": 1, "cube_size": 32, "light_size": 64},
               {"gather": "hierarchical", "spacing": 2.0}):
        diff = dipole_renderer.render(sc, "dipole", DipoleParams(terms="diffusion", **kw)).subsurface
        both = dipole_renderer.render(sc, "dipole", DipoleParams(terms="both", **kw), debug=True)
        s1 = both.debug["single_pass"]["single"]
        assert np.abs(both.subsurface - (diff + s1)).max() <= 1e-5 * np.abs(both.subsurface).max()
        assert both.info["single"]["max_rel_diff"] <= 1e-4


@pytest.mark.gl
@pytest.mark.parametrize("gather", ["dense", "vertex"])
def test_a_wrong_single_result_is_refused(dipole_renderer, monkeypatch, gather):
    """The render's check covers S^(1): a twin off by 1 % (ten times ``CHECK_RTOL``) refuses the result."""
    from harness.errors import ResultRefused

    real = single_twin.single_scattering
    monkeypatch.setattr(single_twin, "single_scattering", lambda *a, **k: 1.01 * real(*a, **k))
    kw = {"spacing": 3.0} if gather == "dense" else {"density": 0.25, "range": 2.0}
    with pytest.raises(ResultRefused, match="single scattering: the GL result disagrees"):
        dipole_renderer.render(_scene_two_lights(), "dipole", DipoleParams(gather=gather, **kw))


def _halfspace_scene(eta, light_dir, dist=1000.0):
    import dataclasses

    from harness.scene.load import Boundary, PointLight, scene_hash

    sc = single_refs.case_scene("thick_front_eta1").with_resolution(16, 16)
    mesh = dataclasses.replace(sc.mesh, vertices=sc.mesh.vertices * np.array([3.0, 3.0, 10.0 / 3.0]))
    m = sc.medium
    st = np.broadcast_to(np.array([8.0, 10.0, 13.0], np.float32), m.sigma_t.shape).copy()
    g = np.broadcast_to(np.array([0.5, 0.0, -0.3], np.float32), m.g.shape).copy()
    sc = sc.with_medium(sigma_t=st, g=g)
    w = np.asarray(light_dir, float) / np.linalg.norm(light_dir)
    light = PointLight(tuple(w * dist), (dist**2, dist**2, dist**2))       # irradiance about 1 at the slab
    b = Boundary("index-matched") if eta == 1.0 else Boundary("dielectric", eta=eta, roughness=0.0)
    sc = dataclasses.replace(sc, mesh=mesh, lights=(light,), boundary=b, content_hash="")
    return dataclasses.replace(sc, content_hash=scene_hash(sc)), w


def _midpoint_error(a, n=single.N_MARCH):
    """Relative error of the march's midpoint rule for ``int_0^1 (1 - u)^a du = 1/(1 + a)``."""
    u = (np.arange(n) + 0.5) / n
    return np.abs(np.mean((1.0 - u)[None, :] ** a[..., None], axis=-1) * (1.0 + a) - 1.0)


@pytest.mark.gl
@pytest.mark.parametrize("eta", [1.0, 1.3])
def test_halfspace_closed_form(dipole_renderer, without_self_check, eta):
    sc, w = _halfspace_scene(eta, (0.5, 0.3, 1.0))
    res = dipole_renderer.render(sc, "dipole", DipoleParams(terms="single"), debug=True)
    d = res.debug
    pos = d["position"]
    inner = d["mask"] & np.all(np.abs(pos[..., :2]) < 1.5, axis=-1) & (d["normal"][..., 2] > 0.99)
    assert inner.sum() > 100
    xo = pos[inner]
    n = np.array([0.0, 0.0, 1.0])
    wo = np.asarray(sc.camera.origin) - xo
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    mat = scene_material(sc)
    ss, st, g = single_twin.exit_material(mat, xo, np.broadcast_to(n, xo.shape))
    cos_v, cos_l = wo @ n, np.full(len(xo), w @ n)
    dv = refract(-wo, np.broadcast_to(n, xo.shape), eta)
    dl = refract(np.broadcast_to(-w, xo.shape), np.broadcast_to(n, xo.shape), eta)
    cos_ph = np.sum(dl * -dv, axis=1)
    irr = sc.lights[0].intensity[0] / np.sum((np.asarray(sc.lights[0].position) - xo) ** 2, axis=1)
    exact = single_twin.halfspace(ss, st, g, eta, cos_v[:, None], cos_l[:, None], cos_ph[:, None], irr[:, None])
    # the march's nodes in u for sigma_ref: (1 - u)^a with a = (sigma_t - sigma_ref + sigma_t mu_o'/mu_i') / sigma_ref
    mo = -dv @ -n
    mi = -dl @ -n
    sref = st.min(axis=1, keepdims=True)
    a = (st - sref + st * (mo / mi)[:, None]) / sref
    dist = np.linalg.norm(sc.lights[0].position)
    tol = _midpoint_error(a) + 2.0**-23 * dist * st.max() + 4.0 / (st.min() * dist)
    rel = np.abs(d["single"][inner] / exact - 1.0)
    assert np.all(rel <= tol), f"worst {rel.max():.3g} against {tol[np.unravel_index(rel.argmax(), rel.shape)]:.3g}"
    assert np.all(fresnel_transmittance(cos_v, eta) <= 1.0)


# ----------------------------------------------------------------- against Mitsuba

@pytest.mark.gl
@pytest.mark.parametrize("case", MITSUBA_CASES)
def test_against_mitsuba_single_scattering(dipole_renderer, without_self_check, case):
    c = single_refs.compare_case(dipole_renderer, case)
    assert c["pixels"] >= 100
    assert abs(c["ratio"] - 1.0) <= c["tolerance"], (
        f"{case}: GL / Mitsuba = {c['ratio']:.4f}, tolerance {c['tolerance']:.4f} = 3 SE {3 * c['se']:.4f} + "
        f"march {c['march']:.4f} + atlas {c['atlas']:.4f} + pixel {c['pixel']:.4f} + straight line {c['line']:.4f}")
