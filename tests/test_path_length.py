"""The path-length tracer (harness/reference/path_length.py) against independent routes.

* The invariance of the mean path length (Blanco and Fournier 2003): uniform isotropic incidence on
  a non-absorbing sphere spends ``4 V / S = 4 r / 3`` inside on average, whatever the scattering.
* The microscopic Beer-Lambert law: more absorption ``Delta`` (the same ``sigma_s``) weights every
  path by ``exp(-Delta l)``, so the energy at ``sigma_a + Delta`` follows from the path-length
  histogram at ``sigma_a``. This checks the lengths the tracer tallies, the camera connection's
  included.
* The image's energy against the committed Mitsuba references of four sphere scenes (back-lit,
  front-lit, g = 0.9, absorbing): a different renderer, another estimator, the same scene.
* The projection against the camera's own rays.
"""

import dataclasses

import numpy as np
import pytest

from harness.errors import InputError
from harness.reference import path_length as pl


@pytest.mark.parametrize("sigma_t,g", [(2.0, 0.0), (10.0, 0.8), (5.0, -0.5)])
def test_mean_path_is_four_volume_over_surface(sigma_t, g):
    r = 0.6
    mean, se = pl.mean_path_isotropic(r, sigma_t, g, photons=1 << 15, seed=3)
    want = 4.0 * r / 3.0
    print(f"sigma_t {sigma_t}, g {g}: mean path / (4r/3) = {mean / want:.4f} +- {se / want:.4f}")
    assert se < 0.01 * want
    assert abs(mean - want) < 4.0 * se


def _scene(name):
    from harness.calibration.run import _reference

    return _reference(name, None)


def test_more_absorption_weights_each_path_by_beer_lambert():
    scene, _ = _scene("backlit_sphere")
    sphere = pl.sphere_scene(scene)
    c, delta = 1, 1.0                                   # green; 1 per cm more absorption
    width = 0.005
    edges = np.arange(0.0, 12.0, width)
    base = pl.trace(sphere, c, edges, photons=1 << 15, batches=16, seed=1)
    st, al = sphere.sigma_t.copy(), sphere.albedo.copy()
    al[c] = al[c] * st[c] / (st[c] + delta)             # sigma_s unchanged
    st[c] = st[c] + delta
    more = pl.trace(dataclasses.replace(sphere, sigma_t=st, albedo=al), c, [0.0], photons=1 << 15, batches=16,
                    seed=2)
    weight = np.exp(-delta * (edges + 0.5 * width))
    pred = base.batch_hist @ weight
    pred_mean, pred_se = pred.mean(), pred.std(ddof=1) / np.sqrt(len(pred))
    z = (more.energy - pred_mean) / np.hypot(more.energy_se, pred_se)
    print(f"energy at sigma_a + {delta}: traced {more.energy:.5g} +- {more.energy_se:.2g}, from the path lengths "
          f"{pred_mean:.5g} +- {pred_se:.2g} (ratio {more.energy / pred_mean:.4f}, z {z:.2f}); "
          f"without the extra absorption {base.energy:.5g}")
    assert more.energy < 0.8 * base.energy              # the test has something to detect
    assert np.hypot(more.energy_se, pred_se) < 0.02 * pred_mean
    assert abs(z) < 4.0


@pytest.mark.parametrize("name", ["backlit_sphere", "sphere_homogeneous", "forward_sphere", "absorbing_sphere"])
def test_image_energy_matches_the_mitsuba_reference(name):
    from harness.io.images import read_exr

    scene, folder = _scene(name)
    ref = read_exr(folder / "subsurface.exr")
    mask = read_exr(folder / "mask.exr")["rgb"][..., 0] >= 0.999
    sphere = pl.sphere_scene(scene)
    for c in range(3):
        r = pl.trace(sphere, c, [0.0], photons=1 << 17, batches=16, seed=c, mask=mask)
        e_ref = float(ref["rgb"][..., c][mask].sum())
        se_ref = float(np.sqrt((ref["se"][..., c][mask] ** 2).sum()))
        se = float(np.hypot(r.energy_se, se_ref))
        z = (r.energy - e_ref) / se
        print(f"{name} channel {c}: traced / Mitsuba {r.energy / e_ref:.4f} +- {se / e_ref:.4f} (z {z:.2f})")
        assert se < 0.04 * e_ref
        assert abs(z) < 4.0


def test_projection_inverts_the_camera_rays():
    from harness.reference.mitsuba_scene import camera_rays

    scene, _ = _scene("backlit_sphere")
    cam = scene.camera
    o, d = camera_rays(cam, offsets=((0.5, 0.5), (0.1, 0.9)))
    H, W = cam.height, cam.width
    fwd = np.asarray(cam.target, float) - o
    fwd /= np.linalg.norm(fwd)
    for s in range(2):
        x = o + 2.5 * d[:, :, s].reshape(-1, 3)
        ix, iy, cos = pl.project(cam, x)
        want_y, want_x = np.mgrid[0:H, 0:W]
        assert np.array_equal(ix, want_x.ravel()) and np.array_equal(iy, want_y.ravel())
        np.testing.assert_allclose(cos, d[:, :, s].reshape(-1, 3) @ fwd, rtol=1e-12)
    ix, iy, _ = pl.project(cam, (o - fwd)[None])         # behind the camera
    assert ix[0] == -1 and iy[0] == -1


@pytest.mark.parametrize("name,field", [("jade_backlit_dielectric", "boundary.kind"), ("skin_torus", "mesh.kind"),
                                        ("backlit_slab", "mesh.kind"),
                                        ("jade_veins", "medium.sigma_t"), ("mixed_phase", "medium.g")])
def test_a_scene_it_cannot_model_is_one_line(name, field):
    from harness.scene import load_scene

    with pytest.raises(InputError) as err:
        pl.sphere_scene(load_scene(name))
    line = str(err.value)
    assert field in line and "\n" not in line, line
