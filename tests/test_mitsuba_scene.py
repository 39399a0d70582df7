"""The Mitsuba scene builder (``harness.reference.mitsuba_scene``): each plugin it makes, asked directly.

Cheap checks that need no render: the loaded plugins are evaluated at chosen
arguments and compared with values computed here, independently.

* boundary: the ``roughdielectric`` BSDF's reflection, ``eval / cos_o``, against
  ``sslpv_gl.optics.ggx_reflection`` (the GGX reflection the SSLPV shader uses), and a
  smooth-looking check of its index: at normal incidence it reflects
  ``((eta - 1) / (eta + 1))^2`` times ``D(n) / 4`` (1e-5, fp32);
* lights: a ``point`` emitter seen from a point returns ``I / d^2`` per channel;
* medium: the ``heterogeneous`` medium's grids, read back with ``mi.traverse``, are the
  scene's ``sigma_t`` and albedo (same voxels, same channel order), and its phase
  function evaluates to Henyey-Greenstein ``(1 - g^2) / (4 pi (1 + g^2 - 2 g mu)^1.5)``
  with ``mu`` the cosine between the propagation directions before and after.
"""

import dataclasses

import numpy as np
import pytest

from harness.scene import Boundary, PointLight, load_scene, scene_hash
from sslpv_gl.optics import ggx_ndf, ggx_reflection

ms = pytest.importorskip("harness.reference.mitsuba_scene")


@pytest.fixture(scope="module")
def mi():
    return ms.use_variant("llvm_ad_rgb")


def vec3(mi, a):
    a = np.asarray(a, dtype=np.float32)
    return mi.Vector3f(mi.Float(a[:, 0]), mi.Float(a[:, 1]), mi.Float(a[:, 2]))


def channel0(spectrum):
    """The first channel of a Mitsuba RGB array (3, n) as float64 (n,)."""
    return np.asarray(spectrum, dtype=np.float64).reshape(3, -1)[0]


def hemisphere_dirs(n, seed):
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    d[:, 2] = np.abs(d[:, 2]) + 0.05
    return d / np.linalg.norm(d, axis=1, keepdims=True)


@pytest.mark.parametrize("eta,alpha", [(1.4, 0.2), (1.5, 0.45)])
def test_boundary_reflection_is_the_shaders_ggx(mi, eta, alpha):
    bsdf = mi.load_dict(ms.bsdf_dict(Boundary("dielectric", eta, alpha)))
    wi, wo = hemisphere_dirs(400, 1), hemisphere_dirs(400, 2)
    si = mi.SurfaceInteraction3f()
    si.wi = vec3(mi, wi)
    si.sh_frame = mi.Frame3f(vec3(mi, np.tile([0.0, 0.0, 1.0], (len(wi), 1))))
    ctx = mi.BSDFContext()
    got = channel0(bsdf.eval(ctx, si, vec3(mi, wo)))                            # f cos_o (grey)
    want = ggx_reflection(wi, wo, np.array([0.0, 0.0, 1.0]), alpha, eta) * wo[:, 2]
    np.testing.assert_allclose(got, want, rtol=2e-4, atol=1e-6 * want.max())
    # normal incidence: Fresnel ((eta-1)/(eta+1))^2 times D(1) / 4 (G = 1)
    up = np.array([[0.0, 0.0, 1.0]])
    si1 = mi.SurfaceInteraction3f()
    si1.wi = vec3(mi, up)
    si1.sh_frame = mi.Frame3f(vec3(mi, up))
    f = float(np.asarray(bsdf.eval(ctx, si1, vec3(mi, up))).ravel()[0])
    assert f == pytest.approx(((eta - 1) / (eta + 1)) ** 2 * float(ggx_ndf(1.0, alpha)) / 4.0, rel=1e-5)


def test_point_lights_give_intensity_over_distance_squared(mi):
    lights = (PointLight((0.5, 2.0, -1.0), (14.0, 9.0, 3.0)), PointLight((-2.0, 0.1, 0.3), (1.0, 2.0, 5.0)))
    p = np.array([0.1, -0.2, 0.4])
    for name, light in zip(sorted(ms.light_dicts(lights)), lights):
        emitter = mi.load_dict(ms.light_dicts(lights)[name])
        it = mi.Interaction3f()
        it.p = mi.Point3f(*map(float, p))
        _, spec = emitter.sample_direction(it, mi.Point2f(0.5, 0.5))
        got = np.asarray(spec, dtype=np.float64).ravel()[:3]
        d2 = float(np.sum((np.asarray(light.position) - p) ** 2))
        np.testing.assert_allclose(got, np.asarray(light.intensity) / d2, rtol=1e-5, err_msg=name)


@pytest.fixture(scope="module")
def coloured_scene():
    """A suite scene whose grids differ per channel and per voxel (so that an order error shows)."""
    base = load_scene("jade_veins")
    rng = np.random.default_rng(3)
    shape = base.medium.sigma_t.shape
    sigma = (rng.uniform(1.0, 9.0, shape) * np.array([1.0, 2.0, 3.0])).astype(np.float32)
    albedo = rng.uniform(0.2, 0.99, shape).astype(np.float32)
    return base.with_medium(sigma_t=sigma, albedo=albedo)


def test_medium_grids_are_the_scenes(mi, coloured_scene):
    med = mi.load_dict(ms.medium_dict(coloured_scene))
    params = mi.traverse(med)
    for name, grid in (("sigma_t", coloured_scene.medium.sigma_t), ("albedo", coloured_scene.medium.albedo)):
        key = next(k for k in params.keys() if k.startswith(name) and k.endswith("data"))
        got = np.asarray(params[key], dtype=np.float32).reshape(grid.shape)
        np.testing.assert_array_equal(got, grid, err_msg=f"{key}: not the scene's {name} grid ([z, y, x, c])")


def hg(g, mu):
    return (1 - g * g) / (4 * np.pi * (1 + g * g - 2 * g * mu) ** 1.5)


@pytest.mark.parametrize("g", [0.8, -0.3])
def test_phase_function_is_henyey_greenstein(mi, coloured_scene, g):
    scene = coloured_scene.with_medium(g=np.full_like(coloured_scene.medium.g, g))
    scene = dataclasses.replace(scene, content_hash=scene_hash(scene))
    d = ms.medium_dict(scene)
    assert d["phase"]["type"] == "hg"                      # constant g: the stock plugin
    phase = mi.load_dict(d["phase"])
    mu = np.linspace(-0.95, 0.95, 9)
    travel = np.array([0.0, 0.0, -1.0])                    # the light travels along -z before scattering
    wo = np.stack([np.sqrt(1 - mu * mu), np.zeros_like(mu), -mu], axis=-1)   # travel . wo = mu
    mei = mi.MediumInteraction3f()
    mei.wi = vec3(mi, np.tile(-travel, (len(mu), 1)))      # Mitsuba's wi points back along the path
    mei.sh_frame = mi.Frame3f(mei.wi)
    ctx = mi.PhaseFunctionContext(None)
    value = phase.eval_pdf(ctx, mei, vec3(mi, wo))[0]
    np.testing.assert_allclose(channel0(value), hg(g, mu), rtol=1e-5)
