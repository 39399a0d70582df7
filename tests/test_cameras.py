"""Cameras that are not square and not upright: GL and Mitsuba against the conventions, and each other.

``docs/conventions.md`` fixes the pinhole camera: forward = normalize(target - origin),
right = normalize(forward x up), true up = right x forward, and the ray through
pixel ``(px, py)`` (``py`` from the top) is
``forward + x tan(fov_y/2) (W/H) right + y tan(fov_y/2) up_true`` with
``x = (px + 0.5)/W*2 - 1``, ``y = 1 - (py + 0.5)/H*2``. It is written out again below
(:func:`convention_rays`), from the document, not imported.

The scene is the suite's ``wide_slab``: 160x96 (committed small size 60x36), a
vertical field of view of 26 degrees (42 horizontally), the object off centre and the
camera rolled (``up = (0.2, 1, 0)``). Further cameras replace its ``up`` with vectors
far from +y. An aspect ratio inverted, a field of view read as horizontal, a
mirrored ``right`` or a wrong roll moves the slab by many pixels.

* **GL against the conventions.** The slab is an axis-aligned box, so which pixel
  centres see it is known exactly (a slab test per ray). GL's coverage must match
  that everywhere except pixels whose centre ray passes within 0.02 pixels of an edge, and
  the world position GL shades at each covered pixel must lie on that pixel's ray
  (measured ~1e-7 rad; bound 1e-6, fp32).
* **Mitsuba against the conventions.** The ``perspective`` sensor that
  ``harness.reference.mitsuba_scene.sensor_dict`` builds is asked for the ray through
  every pixel centre (``sensor.sample_ray`` at film position ``(px + 0.5)/W``,
  ``(py + 0.5)/H``); its direction must equal the convention's (measured 1e-7 rad; bound 1e-6), and its line must
  pass through the camera origin (Mitsuba starts rays on the near plane).
* **GL against Mitsuba.** The committed Mitsuba reference of ``wide_slab`` (rendered
  through Mitsuba's own sensor, 60x36) is non-zero exactly on the pixels that see the
  slab (black background, index-matched, lit): every pixel GL covers has radiance in
  the reference, and every lit reference pixel that GL does not cover borders GL's
  coverage (a partly covered pixel at the silhouette).
"""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from harness.io.images import read_exr
from harness.reference.committed import small_scene
from harness.scene import load_scene, scene_hash
from sslpv_gl.params import SSLPVParams

REFS = Path(__file__).resolve().parent.parent / "baselines" / "refs"
#: The suite camera, and cameras whose up is far from +y (rolled 90 degrees, tilted).
UPS = {"suite": None, "up_x": (1.0, 0.0, 0.0), "up_tilted": (-0.6, 0.5, 0.6)}
PARAMS = SSLPVParams(N=16, steps=4, rsm_size=256, inject_size=64)


def with_up(scene, up):
    if up is None:
        return scene
    s = dataclasses.replace(scene, camera=dataclasses.replace(scene.camera, up=tuple(map(float, up))))
    return dataclasses.replace(s, content_hash=scene_hash(s))


def convention_rays(camera):
    """(H, W, 3) unit ray directions through pixel centres, row 0 at the top (docs/conventions.md)."""
    o = np.asarray(camera.origin, dtype=np.float64)
    forward = np.asarray(camera.target, dtype=np.float64) - o
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.asarray(camera.up, dtype=np.float64))
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    W, H = camera.width, camera.height
    t = np.tan(np.radians(camera.fov_y_deg) / 2.0)
    x = (np.arange(W) + 0.5) / W * 2.0 - 1.0
    y = 1.0 - (np.arange(H) + 0.5) / H * 2.0
    d = forward + (x[None, :, None] * t * (W / H)) * right + (y[:, None, None] * t) * up
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def angle_between(a, b):
    """Angle between direction arrays (float64; atan2 of |a x b| and a . b stays accurate near 0)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))


def box_hits(origin, dirs, lo, hi):
    """Slab test: (hit, distance to the nearest box edge along the ray's entry face, in world units)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (lo - origin) / dirs
        t2 = (hi - origin) / dirs
    t_in = np.nanmax(np.minimum(t1, t2), axis=-1)
    t_out = np.nanmin(np.maximum(t1, t2), axis=-1)
    hit = (t_out >= t_in) & (t_out > 0)
    p = origin + np.where(hit, t_in, 0.0)[..., None] * dirs
    # how far the entry point lies inside its face: a small margin means the ray grazes an edge
    margin = np.minimum(p - lo, hi - p)
    margin = np.sort(margin, axis=-1)[..., 1]           # the smallest is ~0 (the face itself)
    return hit, np.abs(margin), t_in


@pytest.fixture(scope="module")
def wide():
    return small_scene(load_scene("wide_slab"))


def test_scene_is_wide_rolled_and_small_keeps_the_aspect(wide):
    full = load_scene("wide_slab")
    assert (full.camera.width, full.camera.height) == (160, 96)
    assert (wide.camera.width, wide.camera.height) == (60, 36)           # 5:3 exactly
    assert abs(full.camera.up[0]) > 0.1                                    # not +y


@pytest.mark.gl
@pytest.mark.parametrize("which", sorted(UPS))
def test_gl_against_conventions(gl_renderer, wide, which):
    scene = with_up(wide, UPS[which])
    cam = scene.camera
    res = gl_renderer.render(scene, PARAMS)
    rays = convention_rays(cam)
    origin = np.asarray(cam.origin, dtype=np.float64)
    lo, hi = scene.mesh.bbox
    hit, margin, _ = box_hits(origin, rays, lo, hi)
    # a pixel's footprint on the slab at this distance is ~0.06 units: 0.02 px ~ 1e-3
    pixel = 2.0 * np.tan(np.radians(cam.fov_y_deg) / 2.0) * np.linalg.norm(origin) / cam.height
    sure = ~hit | (margin > 0.02 * pixel)
    wrong = (res.mask != hit) & sure
    assert hit.sum() > 0.15 * hit.size, f"{which}: the slab covers only {hit.mean():.3f} of the image"
    assert not wrong.any(), (f"{which}: GL coverage differs from the conventions' rays at {wrong.sum()} pixels "
                             f"(of {hit.sum()} covered), e.g. row/col {np.argwhere(wrong)[0].tolist()}")
    angle = angle_between(res.position[res.mask].astype(np.float64) - origin, rays[res.mask]).max()
    print(f"{which}: GL coverage = conventions on every sure pixel ({sure.sum()}); worst ray angle {angle:.2e} rad")
    assert angle <= 1e-6, f"{which}: GL shades off the pixel's ray by {angle:.2e} rad"


@pytest.mark.parametrize("which", sorted(UPS))
def test_mitsuba_sensor_against_conventions(which):
    from harness.reference import mitsuba_scene as ms

    mi = ms.use_variant("llvm_ad_rgb")
    scene = with_up(load_scene("wide_slab"), UPS[which])
    cam = scene.camera
    sensor = mi.load_dict(ms.sensor_dict(cam))
    W, H = cam.width, cam.height
    py, px = np.mgrid[0:H, 0:W]
    u = ((px + 0.5) / W).astype(np.float32).ravel()
    v = ((py + 0.5) / H).astype(np.float32).ravel()
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(mi.Float(u), mi.Float(v)), mi.Point2f(0.5, 0.5))
    d = np.stack([np.asarray(ray.d.x), np.asarray(ray.d.y), np.asarray(ray.d.z)], axis=-1).reshape(H, W, 3)
    o = np.stack([np.asarray(ray.o.x), np.asarray(ray.o.y), np.asarray(ray.o.z)], axis=-1).reshape(H, W, 3)
    want = convention_rays(cam)
    angle = angle_between(d, want).max()
    # each ray starts on the near plane, on the line through the camera's origin
    miss = np.linalg.norm(np.cross(np.asarray(cam.origin) - o, d), axis=-1).max()
    print(f"{which}: Mitsuba sensor vs conventions, worst ray angle {angle:.2e} rad, line misses the origin "
          f"by {miss:.1e}")
    assert miss <= 1e-5, f"{which}: Mitsuba's rays do not pass through the camera origin ({miss:.2e})"
    assert angle <= 1e-6, f"{which}: Mitsuba's ray through a pixel centre is off by {angle:.2e} rad"


@pytest.mark.gl
def test_gl_against_committed_mitsuba_reference(gl_renderer, wide):
    ref = REFS / "wide_slab"
    info = json.loads((ref / "reference.json").read_text())
    assert info["content_hash"] == wide.content_hash, (
        "the committed wide_slab reference is for another scene version; run "
        "`sslpv-harness baselines regenerate-references --scenes wide_slab`")
    H, W = wide.camera.height, wide.camera.width
    full = read_exr(ref / "full.exr", expect_shape=(H, W))["rgb"]
    lit = full.max(axis=-1) > 0.0
    res = gl_renderer.render(wide, PARAMS)
    gl = res.mask
    near = gl.copy()                                     # GL's coverage grown by one pixel
    near[1:] |= gl[:-1]
    near[:-1] |= gl[1:]
    near[:, 1:] |= gl[:, :-1]
    near[:, :-1] |= gl[:, 1:]
    dark_in_gl = gl & ~lit
    lit_far = lit & ~near
    print(f"wide_slab {W}x{H}: GL covers {gl.sum()} pixels, Mitsuba lights {lit.sum()}; GL-covered but black in "
          f"Mitsuba: {dark_in_gl.sum()}; lit in Mitsuba away from GL's silhouette: {lit_far.sum()}")
    assert not dark_in_gl.any(), f"{dark_in_gl.sum()} pixels GL covers are black in the Mitsuba reference"
    assert not lit_far.any(), f"{lit_far.sum()} pixels lit in the Mitsuba reference lie away from GL's coverage"
