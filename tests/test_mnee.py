"""Validation of ``mneevolpath`` (:mod:`harness.reference.mnee`) against independent routes.

What each group checks, and the tolerance it states:

* vertex math: the constraint's derivative ``J = dC/d(u, v)`` against central differences
  (2e-3 of max |J|); Mitsuba's ``dn_du, dn_dv`` against the derivative of the normalised
  interpolated normal (1e-5); the geometry term against the ray-tube irradiance of a flat
  interface computed in NumPy (median relative error 1e-5, worst 2e-3: float32), and its
  limit 1 / r^2 for eta -> 1;
* test 1, single scattering in a half-space (eta 1.33 and 1.5): the rendered image against
  the independent NumPy computation of :mod:`harness.reference.halfspace` with the
  Beer-Lambert test's z-statistics (>= 99 % of pixels within 4 SE, none beyond 8 SE, mean
  z^2 in [0.6, 1.6]) and the image mean within 1 % per channel; the same comparison must
  fail against NumPy images with the light-side Fresnel factor dropped, with the straight
  inverse-square law in place of the refracted ray tube, and without the eta^2 of the
  geometry term (power);
* test 2, eta -> 1: eta = 1.0001 against the index-matched ``volpath`` image of the same
  scene (jade_veins), per-pixel Welch statistics as above and the image mean within 4
  combined SE;
* test 3, the area-light limit: stock ``volpath`` with a sphere light of radius 0.25
  (radiance I / (pi r^2)) behind the same interface against the point-light image, image
  mean within 3 % + 4 SE (the finite radius; ``benchmarks/bench_mnee.py --part area-limit``
  reports the sequence). Its power is coarse, limited by the sphere light's own noise (found
  only by hitting it; SE about 2 %): planted in ``mnee.py``, the eta^2 of the geometry term
  dropped fails it (1.72 +- 0.04), the light-side Fresnel factor dropped (-10 %) passes it
  (0.899 +- 0.020) and is caught by test 1 (mean z^2 22.7, image +7.8 %);
* the harness: a smooth boundary is rendered with ``mneevolpath`` and recorded so, and its
  albedo-0 image is exactly black (so the absorber pass is skipped).
"""

import dataclasses
import json

import numpy as np
import pytest

from harness.scene import Boundary, load_scene

ms = pytest.importorskip("harness.reference.mitsuba_scene")


@pytest.fixture(scope="module")
def mi():
    return ms.use_variant("llvm_ad_rgb")


def render_stack(mi, scene_dict, seeds, spp):
    return ms.render_seeds(mi, scene_dict, seeds, spp)[0]


def area_light_ratio(mi, scene, radius, max_depth, full_seeds, full_spp, absorber_spp):
    """``(ratio, se, keep)``: the area-light limit's image (stock ``volpath`` with a sphere light of ``radius``,
    :func:`harness.reference.mitsuba_scene.area_light_limit`) over the point light's (the scene's integrator at
    ``max_depth``), per channel over the pixels ``keep`` that show no reflection of the bulb (its pure absorber is
    black there), with the ratio's standard error over the seeds of both."""
    from harness.reference import mitsuba_scene as ms

    light = scene.lights[0]
    area = ms.area_light_limit(light.position, light.intensity, radius, max_depth)
    full = render_stack(mi, ms.build_scene_dict(scene, **area), full_seeds, full_spp)
    absorber = render_stack(mi, ms.build_scene_dict(scene, albedo_override=0.0, **area), range(200, 202),
                            absorber_spp)
    keep = np.all(absorber.mean(0) <= 1e-3 * np.maximum(full.mean(0), 1e-12), axis=-1)
    point = render_stack(mi, ms.build_scene_dict(scene, max_depth=max_depth), range(8), 512)
    f, p = full[:, keep].mean(1), point[:, keep].mean(1)
    ratio = f.mean(0) / p.mean(0)
    se = ratio * np.sqrt(f.var(0, ddof=1) / len(f) / f.mean(0) ** 2 + p.var(0, ddof=1) / len(p) / p.mean(0) ** 2)
    return ratio, se, keep


def z_statistics(z):
    """(fraction of pixels with every channel within 4, max |z|, mean z^2), as the Beer-Lambert test."""
    return float(np.mean(np.all(np.abs(z) <= 4, axis=-1))), float(np.abs(z).max()), float(np.mean(z ** 2))


def agrees(z, mean_err, mean_tol):
    frac4, zmax, mz2 = z_statistics(z)
    return frac4 >= 0.99 and zmax <= 8 and 0.6 <= mz2 <= 1.6 and bool(np.all(np.abs(mean_err) <= mean_tol))


# --------------------------------------------------------------------------- vertex math

class TestVertexMath:
    @pytest.fixture(scope="class")
    @classmethod
    def sphere_hit(cls, mi):
        """A hit on the smooth-shaded icosphere of the suite, and its triangle's data in NumPy."""
        import drjit as dr

        mesh = load_scene("jade_veins").mesh
        scene = mi.load_dict({"type": "scene", "o": ms.mitsuba_mesh(mesh)})
        from harness.reference import mnee

        ray = mi.Ray3f(mi.Point3f(0.0, 0.0, 0.0), dr.normalize(mi.Vector3f(0.3, 0.5, 0.8)))
        si = scene.ray_intersect(ray, mnee.WALK_FLAGS, True)
        f = mesh.faces[int(si.prim_index[0])]
        return si, mesh.vertices[f], mesh.normals[f], float(si.uv.x[0]), float(si.uv.y[0])

    def test_normal_partials_are_the_normalised_interpolation(self, mi, sphere_hit):
        si, P, N, u, v = sphere_hit
        raw = N[0] + u * (N[1] - N[0]) + v * (N[2] - N[0])
        n = raw / np.linalg.norm(raw)
        for k, field in ((1, "dn_du"), (2, "dn_dv")):
            d = (N[k] - N[0]) / np.linalg.norm(raw)
            expect = d - n * (n @ d)                  # derivative of raw / |raw|
            np.testing.assert_allclose(np.asarray(getattr(si, field)).ravel(), expect, atol=1e-5)
        np.testing.assert_allclose(np.asarray(si.dp_du).ravel(), P[1] - P[0], atol=1e-6)

    def test_jacobian_matches_central_differences(self, mi, sphere_hit):
        import drjit as dr

        from harness.reference import mnee

        _, P, N, u, v = sphere_hit
        x0 = np.array([0.05, 0.1, 0.2])
        y = np.array([-1.6, 2.4, 2.2])
        V3 = lambda a: mi.Vector3f(*[float(c) for c in a])  # noqa: E731

        def constraint(uu, vv):
            p = P[0] + uu * (P[1] - P[0]) + vv * (P[2] - P[0])
            raw = N[0] + uu * (N[1] - N[0]) + vv * (N[2] - N[0])
            n = raw / np.linalg.norm(raw)
            dn = [((N[k] - N[0]) - n * (n @ (N[k] - N[0]))) / np.linalg.norm(raw) for k in (1, 2)]
            wi = x0 - p
            out = mnee.half_vector_constraint(V3(wi / np.linalg.norm(wi)), mi.Float(np.linalg.norm(wi)), V3(y), V3(p),
                                              V3(n), V3(P[1] - P[0]), V3(P[2] - P[0]), V3(dn[0]), V3(dn[1]),
                                              mi.Float(1.4))
            return np.array([float(dr.slice(c)) for c in out[:6]])

        c = constraint(u, v)
        J = c[2:6].reshape(2, 2)
        eps = 1e-3
        fd = np.stack([(constraint(u + eps, v)[:2] - constraint(u - eps, v)[:2]) / (2 * eps),
                       (constraint(u, v + eps)[:2] - constraint(u, v - eps)[:2]) / (2 * eps)], axis=1)
        assert np.abs(J).max() > 0.05
        np.testing.assert_allclose(J, fd, atol=2e-3 * np.abs(J).max())

    def test_geometry_term_is_the_ray_tube_irradiance(self, mi):
        """Flat interface (the validation half-space): G from the manifold Jacobian against the NumPy ray tube."""
        import drjit as dr

        from harness.reference import halfspace, mnee

        scene = halfspace.validation_scene(1.5, size=8)
        mscene = mi.load_dict(ms.build_scene_dict(scene))
        rng = np.random.default_rng(3)
        n = 4000
        pts = np.stack([rng.uniform(-1.5, 1.5, n), -rng.exponential(0.3, n).clip(1e-4, 3.5), rng.uniform(-1.5, 1.5, n)],
                       axis=1)
        light = np.array(scene.lights[0].position)
        x0 = mi.Point3f(pts.T.astype(np.float32))
        y = mi.Point3f(*[float(c) for c in light])
        integ = mnee.MNEEVolpathIntegrator(mi.Properties())
        si0 = mscene.ray_intersect(mi.Ray3f(x0, dr.normalize(y - x0)), mnee.WALK_FLAGS, True)
        conv, vertex, omega, dist, _, _ = integ._walk(mscene, x0, y, si0, dr.normalize(y - x0), mi.Float(1.5),
                                                      mi.Bool(True))
        g, _ = mnee.generalized_geometry(-omega, dist, y, *vertex, mi.Float(1.5))
        conv, g = np.asarray(conv), np.asarray(g, dtype=np.float64)
        assert conv.all(), f"{(~conv).sum()} of {n} walks failed on a flat interface"
        p = np.asarray(x0, dtype=np.float64).T
        z, rho = -p[:, 1], np.linalg.norm(p[:, [0, 2]] - light[[0, 2]], axis=1)
        h, eta = light[1], 1.5
        th = halfspace.refraction_angle(rho, z, h, eta)
        so, ci = eta * np.sin(th), np.cos(th)
        co = np.sqrt(1 - so ** 2)
        tube = so / (rho * ci * (h / co ** 2 + z / ci ** 2 * co / (eta * ci)))
        rel = np.abs(g / tube - 1)
        assert np.median(rel) < 1e-5 and rel.max() < 2e-3, (np.median(rel), rel.max())   # float32 arithmetic

    def test_geometry_term_tends_to_inverse_square(self, mi):
        import drjit as dr

        from harness.reference import mnee

        n = mi.Vector3f(0.0, 1.0, 0.0)
        p = mi.Point3f(0.2, 0.0, -0.1)
        x0 = mi.Point3f(0.0, -0.4, 0.3)
        y = p + 1.7 * dr.normalize(p - x0)                 # the straight line through p
        wi = x0 - p
        g, _ = mnee.generalized_geometry(dr.normalize(wi), dr.norm(wi), y, p, n, n, mi.Vector3f(0.1, 0, 0),
                                         mi.Vector3f(0, 0, 0.1), mi.Vector3f(0.0), mi.Vector3f(0.0), mi.Float(1.0))
        r = float(dr.norm(y - x0)[0])
        assert abs(float(g[0]) * r * r - 1) < 1e-5


# --------------------------------------------------------------------------- test 1: the half-space

@pytest.mark.slow
class TestHalfSpace:
    """Single scattering (max_depth = 4) in the validation half-space against the NumPy route.

    K = 16 seeds x 32 spp at 24 x 24. NumPy: 4 x 4 rays per pixel, 32 Gauss-Legendre nodes
    (2e-4 of a pixel from the converged value, far below the 3-6 % per-pixel noise).
    """

    @pytest.mark.parametrize("eta", [1.33, 1.5])
    def test_against_numpy(self, mi, eta):
        from harness.reference import halfspace

        scene = halfspace.validation_scene(eta, size=24)
        stack = render_stack(mi, ms.build_scene_dict(scene, max_depth=4), range(16), 32)
        mean, se = stack.mean(0), stack.std(0, ddof=1) / np.sqrt(len(stack))
        ref = halfspace.setup_image(scene, sub=4, nodes=32)
        lit = np.all(se > 0, axis=-1)
        assert lit.mean() > 0.9
        z = ((mean - ref) / np.where(se > 0, se, 1.0))[lit]
        mean_err = mean.mean((0, 1)) / ref.mean((0, 1)) - 1
        frac4, zmax, mz2 = z_statistics(z)
        msg = (f"eta {eta}: within 4 SE {frac4:.4f} (>= 0.99), max |z| {zmax:.2f} (<= 8), mean z^2 {mz2:.3f} "
               f"([0.6, 1.6]), image mean - 1 {np.round(mean_err, 5)} (|.| <= 0.01)")
        print(f"half-space: {msg}")
        assert agrees(z, mean_err, 0.01), f"half-space: {msg}"

        # Power: the same image against NumPy images with a planted error must fail.
        planted = {"no light-side Fresnel": halfspace.setup_image(scene, sub=2, nodes=32, fresnel_light=False),
                   "straight inverse square": halfspace.setup_image(scene, sub=2, nodes=32, geometry="straight"),
                   "no eta^2 in G": ref / eta ** 2}
        for name, wrong in planted.items():
            zw = ((mean - wrong) / np.where(se > 0, se, 1.0))[lit]
            err = mean.mean((0, 1)) / wrong.mean((0, 1)) - 1
            print(f"half-space eta {eta}, planted '{name}': mean z^2 {np.mean(zw ** 2):.1f}, image {np.round(err, 4)}")
            assert not agrees(zw, err, 0.01), f"a planted error ({name}) would go unnoticed"


# --------------------------------------------------------------------------- test 2: eta -> 1

@pytest.mark.slow
def test_eta_one_reproduces_index_matched_volpath(mi):
    """jade_veins at 16 x 16: eta = 1.0001 (mneevolpath) against index-matched volpath, K = 8 x 128 spp each."""
    base = load_scene("jade_veins").with_resolution(16, 16)
    smooth = dataclasses.replace(base, boundary=Boundary("dielectric", 1.0001, 0.0))
    a = render_stack(mi, ms.build_scene_dict(smooth), range(8), 128)
    b = render_stack(mi, ms.build_scene_dict(base), range(100, 108), 128)
    ma, mb = a.mean(0), b.mean(0)
    va, vb = a.var(0, ddof=1) / len(a), b.var(0, ddof=1) / len(b)
    se = np.sqrt(va + vb)
    lit = np.all(se > 0, axis=-1)
    z = ((ma - mb) / np.where(se > 0, se, 1.0))[lit]
    pa, pb = a.mean((1, 2)), b.mean((1, 2))
    se_mean = np.sqrt(pa.var(0, ddof=1) / len(pa) + pb.var(0, ddof=1) / len(pb))
    diff = pa.mean(0) - pb.mean(0)
    frac4, zmax, mz2 = z_statistics(z)
    msg = (f"within 4 SE {frac4:.4f}, max |z| {zmax:.2f}, mean z^2 {mz2:.3f}, image mean ratio "
           f"{np.round(pa.mean(0) / pb.mean(0), 4)} (|diff| / SE {np.round(np.abs(diff) / se_mean, 2)} <= 4)")
    print(f"eta -> 1: {msg}")
    assert lit.sum() > 100
    assert frac4 >= 0.99 and zmax <= 8 and 0.6 <= mz2 <= 1.6 and np.all(np.abs(diff) <= 4 * se_mean), msg


# --------------------------------------------------------------------------- test 3: the area-light limit

AREA_RADIUS = 0.25
AREA_TOLERANCE = 0.03


@pytest.mark.slow
def test_small_sphere_light_approaches_point_light(mi):
    """Grey half-space (sigma_t 1.6, albedo 0.8), single scattering, 8 x 8 pixels.

    Stock volpath with a sphere light of radius 0.25 (K = 8 x 8192 spp) against mneevolpath
    with the point light (K = 8 x 512 spp): image mean within 3 % + 4 SE.
    """
    from harness.reference import halfspace

    setup = dict(halfspace.SETUP, sigma_t=(1.6, 1.6, 1.6), albedo=(0.8, 0.8, 0.8))
    scene = halfspace.validation_scene(1.33, size=8, setup=setup)
    point = render_stack(mi, ms.build_scene_dict(scene, max_depth=4), range(8), 512).mean((1, 2))
    d = ms.build_scene_dict(scene, **ms.area_light_limit(setup["light"], setup["intensity"], AREA_RADIUS, 4))
    area = render_stack(mi, d, range(100, 108), 8192).mean((1, 2))
    ratio = area.mean(0)[0] / point.mean(0)[0]
    se = ratio * np.sqrt(area[:, 0].var(ddof=1) / len(area) / area.mean(0)[0] ** 2
                         + point[:, 0].var(ddof=1) / len(point) / point.mean(0)[0] ** 2)
    msg = f"sphere light r = {AREA_RADIUS} / point light: {ratio:.4f} +- {se:.4f} (|. - 1| <= {AREA_TOLERANCE} + 4 SE)"
    print(f"area-light limit: {msg}")
    assert abs(ratio - 1) <= AREA_TOLERANCE + 4 * se, msg


# --------------------------------------------------------------------------- the harness

class TestHarness:
    def test_smooth_boundary_uses_mneevolpath(self, mi):
        scene = load_scene("skin_torus_dielectric")
        d = ms.build_scene_dict(scene)
        assert d["integrator"]["type"] == "mneevolpath"
        assert d["integrator"]["max_depth"] == -1 and d["integrator"]["newton_iterations"] > 0
        notes = ms.scene_notes(scene)
        # sigma_t differs between channels, so the reference renders one grey pass per channel, each with
        # the integrator of its channel's albedo (mitsuba_scene.channel_passes, rr_depth_for).
        per_pass = notes["integrator"] if "type" not in notes["integrator"] else {"RGB": notes["integrator"]}
        assert all(v["type"] == "mneevolpath" and v["newton_iterations"] == d["integrator"]["newton_iterations"]
                   for v in per_pass.values()), per_pass
        assert notes["boundary_note"].startswith("exact")
        assert ms.bsdf_dict(scene.boundary)["type"] == "dielectric"
        rough = dataclasses.replace(scene, boundary=Boundary("dielectric", 1.4, 0.2))
        assert ms.build_scene_dict(rough)["integrator"]["type"] == "volpath"
        assert ms.scene_notes(rough)["boundary_note"].startswith("approximation")

    @pytest.mark.slow
    def test_albedo_zero_is_black_and_reference_records_integrator(self, mi, tmp_path):
        from harness.reference.render import render_reference

        scene = load_scene("skin_torus_dielectric").with_resolution(16, 16)
        # without the scene's specular manifold sampling: its exactness verdict alone takes minutes
        scene = dataclasses.replace(scene, boundary=dataclasses.replace(scene.boundary, sms_trials=0))
        black = np.asarray(mi.render(mi.load_dict(ms.build_scene_dict(scene, albedo_override=0.0)), seed=1, spp=16))
        assert np.all(black == 0), "the absorber pass of a smooth boundary is not black"
        meta = render_reference(scene, tmp_path / "ref", spp=4, K=2)
        on_disk = json.loads((tmp_path / "ref" / "reference.json").read_text())
        passes = on_disk["integrator"] if "type" not in on_disk["integrator"] else {"RGB": on_disk["integrator"]}
        assert passes and all(v["type"] == "mneevolpath" for v in passes.values()), passes
        assert on_disk["absorber_pass"].startswith("skipped")
        assert meta["boundary_roughness"] == 0.0 and "absorber.exr" not in meta["files"]
