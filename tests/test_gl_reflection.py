"""The GLSL direct reflection (``shade.frag`` + ``optics.glsl``) against ``sslpv_gl.optics``, pixel by pixel.

A scene where the reflection dominates: the suite's sphere behind a rough
dielectric (eta 1.5, GGX alpha 0.3) with an absorbing interior (albedo 0, so the
subsurface part is tiny: sigma_t 60 per unit in every LPV cell, ``outside = material``, so a
cell passes on e^-8 of its light), lit by two differently coloured point lights. For every
covered pixel, GL's reflection (``full - subsurface``) must equal

    sum_lights  I / d^2  f_r(w_i, w_o)  cos_i,   f_r = optics.ggx_reflection (D F G / (4 cos_i cos_o)),

evaluated in float64 at the GL-rasterised position and normal of that pixel (the
shading point is not what is being tested; the BRDF and the light loop are).

Shadowing: on a convex object a lit point sees the light, and the shadow map's
visibility is 1 except near the terminator, so pixels where some light arrives at
``cos_i < 0.25`` are left out (the count is printed and bounded).

Tolerance: per pixel 2e-5 of the pixel's own value (fp32; measured worst 5.5e-6, median
2.8e-7 on llvmpipe). A 1.5 % error in D, a 10 % error in Smith's alpha^2 or a swapped light
colour is off by 1e-3 or more on most pixels.
"""

import dataclasses

import numpy as np
import pytest

from harness.scene import Boundary, PointLight, load_scene, scene_hash
from sslpv_gl.optics import ggx_reflection
from sslpv_gl.params import SSLPVParams

pytestmark = pytest.mark.gl

ETA, ALPHA = 1.5, 0.3
LIGHTS = (PointLight((2.5, 1.8, 2.2), (14.0, 9.0, 5.0)), PointLight((-2.0, 0.6, 2.8), (3.0, 6.0, 11.0)))
RTOL = 2e-5
MIN_COS = 0.25


@pytest.fixture(scope="module")
def glossy():
    base = load_scene("sphere_homogeneous").with_resolution(64, 64)
    # a dense pure absorber: the little light that enters dies within a cell
    s = base.with_medium(albedo=np.zeros_like(base.medium.albedo), sigma_t=np.full_like(base.medium.sigma_t, 60.0))
    s = dataclasses.replace(s, boundary=Boundary("dielectric", ETA, ALPHA), lights=LIGHTS)
    return dataclasses.replace(s, content_hash=scene_hash(s))


def expected_reflection(scene, pos, nrm):
    cam = np.asarray(scene.camera.origin, dtype=np.float64)
    wo = cam - pos
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    out = np.zeros_like(pos)
    min_cos = np.full(len(pos), np.inf)
    for light in scene.lights:
        to_l = np.asarray(light.position, dtype=np.float64) - pos
        d2 = np.sum(to_l * to_l, axis=1)
        wi = to_l / np.sqrt(d2)[:, None]
        cos_i = np.sum(wi * nrm, axis=1)
        f = ggx_reflection(wi, wo, nrm, scene.boundary.roughness, scene.boundary.eta)
        out += np.asarray(light.intensity)[None, :] * (f * np.maximum(cos_i, 0.0) / d2)[:, None]
        min_cos = np.where(cos_i > 0, np.minimum(min_cos, cos_i), min_cos)
    return out, min_cos


def test_reflection_matches_optics_per_pixel(gl_renderer, glossy):
    res = gl_renderer.render(glossy, SSLPVParams(N=16, steps=8, rsm_size=1024, inject_size=64, outside="material"))
    m = res.mask
    gl_refl = (res.full - res.subsurface)[m].astype(np.float64)
    pos = res.position[m].astype(np.float64)
    nrm = res.normal[m].astype(np.float64)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    want, min_cos = expected_reflection(glossy, pos, nrm)
    # the reflection dominates: it is what the image shows
    share = gl_refl.sum() / res.full[m].astype(np.float64).sum()
    assert share > 0.9, f"reflection is only {share:.3f} of the image; the scene does not test it"
    keep = (min_cos >= MIN_COS) & (want.max(axis=1) > 1e-3 * want.max())
    assert keep.sum() >= 0.5 * m.sum(), f"only {keep.sum()} of {m.sum()} pixels compared"
    rel = np.abs(gl_refl[keep] - want[keep]) / np.maximum(np.abs(want[keep]), 1e-30)
    worst = float(rel.max())
    print(f"GL reflection vs optics.ggx_reflection: {keep.sum()} pixels, worst relative error {worst:.2e}, "
          f"median {np.median(rel):.2e}, share of the image {share:.3f}")
    assert worst <= RTOL, (f"GL reflection off by {worst:.2e} (relative) at the worst of {keep.sum()} pixels; "
                           f"median {np.median(rel):.2e}")
