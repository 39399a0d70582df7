"""Validation of ``mneevolpath``'s chains through 3, 5, ... interfaces (:mod:`harness.reference.mnee_chain`).

What each group checks, and the tolerance it states:

* chain math: the block-tridiagonal Jacobian assembled from :func:`chain_blocks` against
  central differences of the constraint over all vertices' barycentric parameters, on a
  ray through the torus's two sides (2e-3 of max |J|); the block Thomas solve and its
  determinant against ``numpy.linalg`` (1e-4 relative, float32); a one-vertex chain's
  geometry term equals the single-vertex :func:`harness.reference.mnee.generalized_geometry`
  (1e-4 relative);
* test (a), eta -> 1 on a non-convex scene (the torus lit through its hole,
  :func:`harness.reference.nonconvex.torus_hole`, where about a fifth of the connections
  cross the boundary three times): eta = 1.0001 against index-matched ``volpath``, both in the
  reference's passes, image mean within 1 % or 3 combined SE per channel, >= 99 % of lit pixels
  (the reference noise figure's) within 4 SE; the same comparison with chains switched off
  (``max_crossings = 1``) must fail; and the same on the suite's scanned mesh
  (``bunny_dielectric``, lit from behind), with the same criteria;
* test (b), single scattering under a slab (three parallel interfaces): ``max_depth = 6``
  against the NumPy route of :mod:`harness.reference.halfspace` (``SLAB_SETUP``) at eta 1.33
  and 1.5, >= 99 % of pixels within 4 SE, none beyond 8, mean z^2 in [0.6, 1.6], image mean
  within 1 %; the same must fail against NumPy images with one Fresnel factor too few and
  with the straight inverse-square law;
* the bad input: ``max_crossings`` 0 or above the limit.
"""

import dataclasses

import numpy as np
import pytest

from harness.scene import Boundary

from .test_mnee import render_stack, z_statistics

ms = pytest.importorskip("harness.reference.mitsuba_scene")


@pytest.fixture(scope="module")
def mi():
    return ms.use_variant("llvm_ad_rgb")


# --------------------------------------------------------------------------- chain math

class TestChainMath:
    def test_tridiagonal_solve_matches_dense(self, mi):
        from harness.reference import mnee_chain as mc

        rng = np.random.default_rng(1)
        k = 4
        blocks = {name: [rng.normal(size=(2, 2)) for _ in range(k)] for name in "ABU"}
        for i in range(k):
            blocks["B"][i] += 3 * np.eye(2)          # diagonally dominant, as near a solution
        dense = np.zeros((2 * k, 2 * k))
        for i in range(k):
            dense[2 * i:2 * i + 2, 2 * i:2 * i + 2] = blocks["B"][i]
            if i:
                dense[2 * i:2 * i + 2, 2 * i - 2:2 * i] = blocks["A"][i]
            if i < k - 1:
                dense[2 * i:2 * i + 2, 2 * i + 2:2 * i + 4] = blocks["U"][i]
        rhs = rng.normal(size=2 * k)

        def t(m):
            return tuple(mi.Float(float(v)) for v in m.ravel())

        A = [None] + [t(blocks["A"][i]) for i in range(1, k)]
        U = [t(blocks["U"][i]) for i in range(k - 1)] + [None]
        x, det = mc.solve_tridiagonal(A, [t(b) for b in blocks["B"]], U,
                                      [(mi.Float(rhs[2 * i]), mi.Float(rhs[2 * i + 1])) for i in range(k)])
        got = np.array([float(c[0]) for xi in x for c in xi])
        np.testing.assert_allclose(got, np.linalg.solve(dense, rhs), rtol=1e-4, atol=1e-5)
        assert abs(float(det[0]) / np.linalg.det(dense) - 1) < 1e-4

    @pytest.fixture(scope="class")
    @classmethod
    def torus_chain(cls, mi):
        """Three crossings of a ray through the torus (leaves, enters the other side, leaves), with triangle data."""
        import drjit as dr

        from harness.reference import mnee_chain as mc
        from harness.reference import nonconvex

        mesh = nonconvex.torus_hole().mesh
        scene = mi.load_dict({"type": "scene", "o": ms.mitsuba_mesh(mesh)})
        x0 = np.array([0.0, 0.0, 0.0])
        # Start inside the ring: the point on its centre circle farthest along +x, found by casting.
        probe = scene.ray_intersect(mi.Ray3f(mi.Point3f(2.0, 0.0, 0.0), mi.Vector3f(-1.0, 0.0, 0.0)))
        t_in = float(probe.t[0])
        probe2 = scene.ray_intersect(mi.Ray3f(mi.Point3f(2.0 - t_in + 1e-3, 0.0, 0.0), mi.Vector3f(-1.0, 0.0, 0.0)))
        x0 = np.array([2.0 - t_in - 0.5 * float(probe2.t[0]), 0.0, 0.0])
        direction = np.array([-1.0, 0.05, 0.02])
        direction /= np.linalg.norm(direction)
        verts, dist, ok = mc.seed_chain(scene, mi.Point3f(*map(float, x0)), mi.Vector3f(*map(float, direction)), 3,
                                        dr.reinterpret_array(mi.UInt32, probe.shape), True)
        assert bool(ok[0]), "the test ray does not cross the torus three times"
        tri = []
        ray = mi.Ray3f(mi.Point3f(*map(float, x0)), mi.Vector3f(*map(float, direction)))
        for _ in range(3):
            si = scene.ray_intersect(ray, mc.WALK_FLAGS, True)
            f = mesh.faces[int(si.prim_index[0])]
            tri.append((mesh.vertices[f], mesh.normals[f], float(si.uv.x[0]), float(si.uv.y[0])))
            ray = si.spawn_ray(ray.d)
        return x0, tri

    @pytest.mark.parametrize("kinds", [None, ("R", "R", "T"), ("T", "r", "r")])
    def test_chain_jacobian_matches_central_differences(self, mi, torus_chain, kinds):
        """The whole 6 x 6 dC/dX (A, B, U blocks) against central differences over the six barycentric parameters;
        for refractions only and for chains with reflections inside and outside (the typed constraint of
        :mod:`harness.reference.mnee_sms`: the same index on both sides of a reflection)."""
        import drjit as dr

        from harness.reference import mnee_chain as mc

        x0, tri = torus_chain
        y = np.array([-3.2, 0.4, 0.4])
        V3 = lambda a: mi.Vector3f(*[float(c) for c in a])  # noqa: E731

        def vertex(P, N, u, v):
            p = P[0] + u * (P[1] - P[0]) + v * (P[2] - P[0])
            raw = N[0] + u * (N[1] - N[0]) + v * (N[2] - N[0])
            n = raw / np.linalg.norm(raw)
            dn = [((N[j] - N[0]) - n * (n @ (N[j] - N[0]))) / np.linalg.norm(raw) for j in (1, 2)]
            return [V3(p), V3(n), V3(n), V3(P[1] - P[0]), V3(P[2] - P[0]), V3(dn[0]), V3(dn[1])], p

        def evaluate(params):
            verts, first = [], None
            for i, (P, N, _, _) in enumerate(tri):
                v, p = vertex(P, N, params[2 * i], params[2 * i + 1])
                verts.append(v)
                first = p if i == 0 else first
            w = first - x0
            C, A, B, U, _ = mc.chain_blocks(V3(w / np.linalg.norm(w)), mi.Float(np.linalg.norm(w)), verts, V3(y),
                                            mi.Float(1.4), kinds)
            c = np.array([float(dr.slice(v)) for ci in C for v in ci])
            J = np.zeros((6, 6))
            for i in range(3):
                for name, blk, off in (("A", A[i], -1), ("B", B[i], 0), ("U", U[i], 1)):
                    if blk is not None:
                        J[2 * i:2 * i + 2, 2 * (i + off):2 * (i + off) + 2] = np.array(
                            [float(dr.slice(v)) for v in blk]).reshape(2, 2)
            return c, J

        params = np.array([q for (_, _, u, v) in tri for q in (u, v)])
        _, J = evaluate(params)
        eps = 1e-3
        fd = np.stack([(evaluate(params + eps * e)[0] - evaluate(params - eps * e)[0]) / (2 * eps)
                       for e in np.eye(6)], axis=1)
        assert np.abs(J).max() > 0.05
        np.testing.assert_allclose(J, fd, atol=2e-3 * np.abs(J).max())

    def test_one_vertex_chain_is_the_single_geometry_term(self, mi):
        import drjit as dr

        from harness.reference import mnee, mnee_chain as mc

        n = dr.normalize(mi.Vector3f(0.1, 1.0, 0.05))
        p = mi.Point3f(0.2, 0.0, -0.1)
        x0 = mi.Point3f(0.0, -0.4, 0.3)
        y = mi.Point3f(-1.0, 1.7, 0.8)
        du, dv = mi.Vector3f(0.1, -0.01, 0.0), mi.Vector3f(0.0, 0.0, 0.1)
        dnu, dnv = mi.Vector3f(0.05, 0.0, 0.01), mi.Vector3f(0.0, 0.02, 0.04)
        wi = x0 - p
        g1, _ = mnee.generalized_geometry(dr.normalize(wi), dr.norm(wi), y, p, n, n, du, dv, dnu, dnv, mi.Float(1.4))
        gk, _, _ = mc.chain_geometry(-dr.normalize(wi), dr.norm(wi), [[p, n, n, du, dv, dnu, dnv]], y, mi.Float(1.4))
        assert float(g1[0]) > 0 and abs(float(gk[0]) / float(g1[0]) - 1) < 1e-4


# --------------------------------------------------------------------------- test (a): eta -> 1, non-convex

@pytest.mark.slow
def test_eta_one_through_the_hole_reproduces_index_matched_volpath(mi):
    """torus_hole at 32 x 32: eta = 1.0001 (mneevolpath, stats) against index-matched volpath, K = 8 x 64 spp each.

    32 x 32 gives about 420 covered pixels, 302 of them lit (at 20 x 20, 106 covered: one pixel in the heavy
    tail of a 16-spp seed already decides the 99 % criterion).
    """
    from harness.reference import nonconvex

    results = eta_one_comparison(mi, nonconvex.torus_hole(1.0001, size=32), nonconvex.torus_hole(1.0, size=32), 64,
                                 (5, 1))
    for ok, text, cross3 in results.values():
        print(f"eta -> 1 through the hole, {text}")
        assert cross3 > 0.1, "the scene no longer exercises chains"
    assert results[5][0], "chains: eta = 1.0001 disagrees with index-matched volpath (see the printed line)"
    assert not results[1][0], "without chains the comparison must fail (the scene no longer tests them)"


def eta_one_comparison(mi, smooth, matched, spp, crossings):
    """eta = 1.0001 (``smooth``, stats) against index-matched volpath (``matched``), K = 8 x ``spp`` each, per
    ``max_crossings`` in ``crossings``, both in the reference's passes.

    Returns ``{max_crossings: (ok, text, share of connections through 3 crossings)}``; ``ok``: within 4 SE on
    >= 99 % of lit pixels and image mean within 1 % or 3 combined SE per channel. Lit, as the reference's noise
    figure counts it (:func:`harness.reference.noise.lit_mask` of the index-matched image): a fully covered
    pixel's channel above 1 % of that channel's 99th percentile; a pixel is within when its lit channels are.
    Where a channel is far darker than that (blue through the scan's body), volpath's shadow rays estimate the
    transmittance as 0 or 1 (delta tracking in a homogeneous medium), so its per-pixel standard error from eight
    seeds is mostly 0 and says nothing.
    """
    from harness.reference import mnee
    from harness.reference.noise import lit_mask, stack_agreement

    b, _ = ms.render_in_passes(mi, matched, range(100, 108), spp)
    lit_c = lit_mask(b.mean(0), ms.coverage_mask(matched))
    out = {}
    for mc in crossings:
        a, _ = ms.render_in_passes(mi, smooth, range(8), spp, {"stats": True, "max_crossings": mc})
        img, aov = a[..., :3], a[..., 3:].sum((1, 2)).mean(0)
        ag = stack_agreement(img, b, lit_c)
        ratio, diff, se_mean = ag["ratio"], ag["diff"], ag["diff_se"]
        ok = ag["within"] >= 0.99 and bool(np.all((np.abs(ratio - 1) <= 0.01) | (np.abs(diff) <= 3 * se_mean)))
        st = dict(zip(mnee.STATS_AOVS, aov))
        cross3 = st["mnee_cross3"] / st["mnee_started"]
        out[mc] = (ok, f"max_crossings = {mc}: within 4 SE {ag['within']:.4f} of {ag['pixels']} pixels, image mean "
                       f"ratio {np.round(ratio, 4)} (|diff| / SE {np.round(np.abs(diff) / se_mean, 2)}); 3 crossings "
                       f"{cross3:.3f} of the connections", cross3)
    return out


@pytest.mark.slow
def test_eta_one_on_the_scanned_bunny_reproduces_index_matched_volpath(mi):
    """bunny_dielectric (the suite's scanned mesh, lit from behind) at 32 x 32: eta = 1.0001 against index-matched
    volpath, K = 8 x 64 spp each, in the reference's passes (one grey pass per channel: skin1 is chromatic).

    Sampling is off (``sms_trials = 0``): at eta -> 1 the sampled chains carry the boundary's reflectance (about
    1e-9) and a refraction has one solution, the straight one. On this scene about 1 % of the connections cross
    the boundary three times (body, air, ear) and their light is below the test's noise (with ``max_crossings =
    1`` the image means move by 0.2 %), so the chains are tested by the torus above; here it is the rest of the
    integrator on a faceted scan with interpolated normals (the camera's refractions, the paths that leave the
    body and enter it again) and the passes. Limits: the image means' standard errors are 0.8-1.2 %, so an error
    of about 1 % passes (choosing the medium after a crossing by the shading normal's side instead of the
    geometric one read 0.989 / 0.993 / 0.984 of volpath's means, within 1.4 SE). Rendering the chromatic medium in one RGB pass
    instead reads red 11 % apart (there volpath's per-seed image means spread 2.7 times as far as
    mneevolpath's): planted error ``reference_chromatic_in_one_pass``.
    """
    from harness.scene import load_scene

    base = load_scene("bunny_dielectric").with_resolution(32, 32)
    matched = dataclasses.replace(base, boundary=Boundary("index-matched"))
    smooth = dataclasses.replace(base, boundary=dataclasses.replace(base.boundary, eta=1.0001, sms_trials=0))
    ok, text, cross3 = eta_one_comparison(mi, smooth, matched, 64, (5,))[5]
    print(f"eta -> 1 on the scanned bunny, {text}")
    assert cross3 > 0.0, "no connection crosses the boundary three times: the scan is no longer non-convex to its light"
    assert ok, "eta = 1.0001 disagrees with index-matched volpath on the scan (see the printed line)"


@pytest.mark.slow
@pytest.mark.parametrize("name", ["skin_torus_dielectric", "jade_backlit_dielectric"])
def test_eta_one_on_the_other_suite_smooth_scenes_reproduces_index_matched_volpath(mi, name):
    """The suite's other smooth-dielectric scenes (the skin torus lit through its hole, the back-lit jade sphere)
    at 24 x 24: eta = 1.0001 against index-matched volpath, K = 8 x 64 spp each, in the reference's passes,
    sampling off (as the scan's test above). On the skin torus about a sixth of the connections cross three
    times, through the near side of the ring; its dense medium lets little of that light through (with
    ``max_crossings = 1`` red reads 0.980 of volpath, 2.7 SE: not caught), but a chain that crosses the other
    part without its transmittance reads 1.19 / 1.18 / 1.17 (planted error ``chain_other_part_transparent``).
    The jade sphere is convex: one refraction through a heterogeneous medium. Limits: as the scan's test (image
    means to about 1 %); taking the jade's medium as homogeneous along a connection is not caught.
    """
    from harness.scene import load_scene

    base = load_scene(name).with_resolution(24, 24)
    matched = dataclasses.replace(base, boundary=Boundary("index-matched"))
    smooth = dataclasses.replace(base, boundary=dataclasses.replace(base.boundary, eta=1.0001, sms_trials=0))
    ok, text, _ = eta_one_comparison(mi, smooth, matched, 64, (5,))[5]
    print(f"eta -> 1 on {name}, {text}")
    assert ok, f"eta = 1.0001 disagrees with index-matched volpath on {name} (see the printed line)"


# --------------------------------------------------------------------------- test (b): the slab

@pytest.mark.slow
class TestSlab:
    """Single scattering (max_depth = 6) under the slab against NumPy, K = 16 seeds x 32 spp at 16 x 16.

    NumPy: 4 x 4 rays per pixel, 32 Gauss-Legendre nodes (as the half-space test).
    """

    @pytest.mark.parametrize("eta", [1.33, 1.5])
    def test_against_numpy(self, mi, eta):
        from harness.reference import halfspace

        setup = halfspace.SLAB_SETUP
        scene = halfspace.validation_scene(eta, size=16, setup=setup)
        assert halfspace.slab_outside_share(scene) < 1e-6
        stack = render_stack(mi, ms.build_scene_dict(scene, max_depth=6), range(16), 32)
        mean, se = stack.mean(0), stack.std(0, ddof=1) / np.sqrt(len(stack))
        ref = halfspace.setup_image(scene, setup=setup, sub=4, nodes=32)
        lit = np.all(se > 0, axis=-1)
        assert lit.mean() > 0.9
        z = ((mean - ref) / np.where(se > 0, se, 1.0))[lit]
        mean_err = mean.mean((0, 1)) / ref.mean((0, 1)) - 1
        frac4, zmax, mz2 = z_statistics(z)

        def agrees(zz, err):
            f4, zm, m2 = z_statistics(zz)
            return f4 >= 0.99 and zm <= 8 and 0.6 <= m2 <= 1.6 and bool(np.all(np.abs(err) <= 0.01))

        msg = (f"eta {eta}: within 4 SE {frac4:.4f} (>= 0.99), max |z| {zmax:.2f} (<= 8), mean z^2 {mz2:.3f} "
               f"([0.6, 1.6]), image mean - 1 {np.round(mean_err, 5)} (|.| <= 0.01)")
        print(f"slab: {msg}")
        assert agrees(z, mean_err), f"slab: {msg}"
        planted = {"two Fresnel factors": halfspace.setup_image(scene, setup=setup, sub=2, nodes=32, fresnel_count=2),
                   "straight inverse square": halfspace.setup_image(scene, setup=setup, sub=2, nodes=32,
                                                                    geometry="straight")}
        for name, wrong in planted.items():
            zw = ((mean - wrong) / np.where(se > 0, se, 1.0))[lit]
            err = mean.mean((0, 1)) / wrong.mean((0, 1)) - 1
            print(f"slab eta {eta}, planted '{name}': mean z^2 {np.mean(zw ** 2):.1f}, image {np.round(err, 4)}")
            assert not agrees(zw, err), f"a planted error ({name}) would go unnoticed"


# --------------------------------------------------------------------------- bad input

@pytest.mark.parametrize("value", [0, 11])
def test_max_crossings_out_of_range_is_refused(mi, value):
    from harness.reference import halfspace, mnee_chain

    assert value == 0 or value > mnee_chain.MAX_CROSSINGS_LIMIT
    d = ms.build_scene_dict(halfspace.validation_scene(1.5, size=4))
    d["integrator"]["max_crossings"] = value
    with pytest.raises(Exception, match="max_crossings"):
        mi.load_dict(d)


def test_slab_scene_is_one_closed_shape():
    from harness.reference import halfspace
    from harness.scene.geometry import check_closed

    scene = halfspace.validation_scene(1.5, size=4, setup=halfspace.SLAB_SETUP)
    check_closed(scene.mesh.vertices, scene.mesh.faces)
    assert dataclasses.replace(scene, boundary=Boundary("index-matched")).mesh is scene.mesh


# --------------------------------------------------------------------------- reporting what is lost

class TestReporting:
    @staticmethod
    def losses(share, lost=0.1, over=0.05):
        ch = {"lost_image_share": share, "lost": lost, "over_max": over}
        return {"max_crossings": 5, "channels": {"R": dict(ch), "G": dict(ch, lost_image_share=share / 2),
                                                 "B": dict(ch, lost_image_share=0.0)}}

    def test_verdict_against_the_noise_target(self):
        from harness.reference import losses

        limit = losses.LOSS_FRACTION_OF_TARGET * 0.04
        exact, note = losses.verdict(self.losses(0.99 * limit), 0.04)
        assert exact and note.startswith("exact")
        exact, note = losses.verdict(self.losses(1.01 * limit), 0.04)
        assert not exact and "channel R" in note and "max_crossings = 5" in note

    def test_verdict_takes_the_first_scattered_light_missed(self):
        """The larger of the two estimates decides: a first-scatter shortfall above the limit makes it not exact."""
        from harness.reference import losses

        limit = losses.LOSS_FRACTION_OF_TARGET * 0.04
        found = self.losses(0.5 * limit)
        found["first_scatter"] = {"missed_share": [0.2 * limit, 1.5 * limit, 0.0], "reflection_share": [0.0, 0.01, 0.0]}
        exact, note = losses.verdict(found, 0.04)
        assert not exact and "channel G" in note and "first-scattered" in note and "1.00% of it through reflections" \
            in note, note
        found["first_scatter"]["missed_share"] = [0.2 * limit, 0.9 * limit, 0.0]
        exact, note = losses.verdict(found, 0.04)
        assert exact, note

    def test_verdict_decides_only_beyond_two_standard_errors(self):
        """A first-scatter shortfall is exact only 2 SE below the limit, not exact 2 SE above it, else undecided
        (and not exact)."""
        from harness.reference import losses

        limit = losses.LOSS_FRACTION_OF_TARGET * 0.04
        found = self.losses(0.0)

        def judged(missed, se):
            found["first_scatter"] = {"missed_share": [missed, 0.0, 0.0], "missed_share_se": [se, 0.0, 0.0],
                                      "reflection_share": [0.0, 0.0, 0.0], "points": 1 << 20}
            return losses.verdict(found, 0.04)

        assert judged(0.5 * limit, 0.2 * limit)[0]
        exact, note = judged(0.9 * limit, 0.1 * limit)
        assert not exact and "undecided" in note and "1048576 points" in note, note
        exact, note = judged(1.5 * limit, 0.1 * limit)
        assert not exact and "undecided" not in note and "±" in note, note

    def test_first_scatter_adds_points_until_the_limit_can_be_decided(self, monkeypatch):
        """Batches of delivered power are pooled while the verdict is open, until the missed share's SE is at most a
        quarter of the limit."""
        from harness.reference import connection_power, losses, specular_paths

        traced = {"by_class": {"direct": np.array([2.0, 2.0, 2.0])}, "by_label": {"E": np.array([2.0, 2.0, 2.0])}}
        monkeypatch.setattr(specular_paths, "trace", lambda *a, **k: traced)
        calls = []

        def fake(scene, points, seed, variant):
            calls.append(seed)
            return np.full(3, 1.96), np.full(3, 0.039), 0.5          # missed 2 %: at the limit, undecided

        monkeypatch.setattr(connection_power, "delivered", fake)
        scene = type("S", (), {"boundary": Boundary("dielectric", 1.4, 0.0)})()
        fs = losses.first_scatter(scene, points=1000, limit=0.02, max_points=10 ** 6)
        # SE of one batch: 0.039 / 2 = 0.0195; n batches: 0.0195 / sqrt(n) <= 0.005 from n = 16
        assert len(calls) == 16 and calls == list(range(16)) and fs["points"] == 16000
        assert fs["missed_share_se"][0] == pytest.approx(0.0195 / 4)
        assert fs["missed_share"][0] == pytest.approx(0.02)
        calls.clear()
        losses.first_scatter(scene, points=1000, limit=0.02, max_points=4000)
        assert len(calls) == 4                                           # the cap on points
        calls.clear()
        losses.first_scatter(scene, points=1000)
        assert len(calls) == 1                                           # no limit: one batch
        calls.clear()
        losses.first_scatter(scene, points=1000, limit=0.002, max_points=10 ** 6)
        # decided (not exact) once 2 % - 2 SE clears 0.2 %: 2 * 0.0195 / sqrt(n) < 0.018 at n = 5, long before
        # the SE reaches a quarter of the limit (about 1,500 batches; capped at 1,000)
        assert len(calls) == 5

    def test_first_scatter_counts_the_tracers_noise(self, monkeypatch):
        """The missed share's standard error holds the traced total's (``total_se``) beside the delivered power's."""
        from harness.reference import connection_power, losses, specular_paths

        traced = {"by_class": {"direct": np.full(3, 2.0)}, "by_label": {"E": np.full(3, 2.0)},
                  "total_se": np.full(3, 0.03)}
        monkeypatch.setattr(specular_paths, "trace", lambda *a, **k: traced)
        monkeypatch.setattr(connection_power, "delivered",
                            lambda scene, points, seed, variant: (np.full(3, 1.9), np.full(3, 0.02), 0.5))
        scene = type("S", (), {"boundary": Boundary("dielectric", 1.4, 0.0)})()
        fs = losses.first_scatter(scene, points=1000)
        want = np.hypot(0.02 / 2.0, 1.9 * 0.03 / 4.0)
        assert fs["missed_share_se"][0] == pytest.approx(want) and fs["traced_se"][0] == pytest.approx(0.03)

    def test_first_scatter_traces_photons_until_their_noise_is_small(self, monkeypatch):
        """Photon batches (new seeds) are pooled while the traced total's relative SE exceeds an eighth of the limit,
        up to ``max_photons``; without a limit, one batch."""
        from harness.reference import connection_power, losses, specular_paths

        seeds = []

        def fake_trace(scene, photons, seed):
            seeds.append(seed)
            return {"by_class": {"direct": np.full(3, 2.0)}, "by_label": {"E": np.full(3, 2.0)},
                    "total_se": np.full(3, 0.019)}                       # 0.95 % of the total per batch

        monkeypatch.setattr(specular_paths, "trace", fake_trace)
        monkeypatch.setattr(connection_power, "delivered",
                            lambda scene, points, seed, variant: (np.full(3, 1.9), np.full(3, 1e-4), 0.5))
        scene = type("S", (), {"boundary": Boundary("dielectric", 1.4, 0.0)})()
        fs = losses.first_scatter(scene, photons=10, points=1000, limit=0.02, max_photons=10 ** 6)
        # 0.95 % / sqrt(n) <= 0.25 % from n = 15
        assert len(seeds) == 15 and len(set(seeds)) == 15 and fs["photons"] == 150
        assert fs["traced_se"][0] == pytest.approx(0.019 / np.sqrt(15))
        seeds.clear()
        losses.first_scatter(scene, photons=10, points=1000, limit=0.02, max_photons=40)
        assert len(seeds) == 4                                           # the cap on photons
        seeds.clear()
        losses.first_scatter(scene, photons=10, points=1000)
        assert len(seeds) == 1                                           # no limit: one batch

    def test_inexact_reference_is_refused_without_the_opt_in(self, tmp_path, monkeypatch):
        import json

        from harness.errors import InputError
        from harness.reference import losses
        from harness.runs.sweep import load_reference

        monkeypatch.delenv(losses.ALLOW_ENV, raising=False)
        (tmp_path / "reference.json").write_text(json.dumps({"exact": False, "exact_note": "not exact: because"}))
        with pytest.raises(InputError) as err:
            load_reference(tmp_path, (4, 4))
        line = str(err.value)
        assert "exact" in line and "not exact: because" in line and losses.ALLOW_ENV in line, line
        monkeypatch.setenv(losses.ALLOW_ENV, "1")
        losses.check_exact(tmp_path)                     # the opt-in: no refusal
        (tmp_path / "reference.json").write_text(json.dumps({"exact": True}))
        monkeypatch.delenv(losses.ALLOW_ENV)
        losses.check_exact(tmp_path)

    def test_a_reference_rendered_without_the_verdict_is_refused(self, mi, tmp_path, monkeypatch):
        """``judge_exactness=False`` (timing benchmarks) skips the verdict and records ``"exact": false``, "not
        judged": an accuracy verdict against that folder is refused like one against an inexact reference."""
        import json

        from harness.errors import InputError
        from harness.reference import losses, nonconvex
        from harness.reference.render import render_reference

        monkeypatch.delenv(losses.ALLOW_ENV, raising=False)
        scene = nonconvex.torus_hole(1.0001, size=4)
        meta = render_reference(scene, tmp_path / "ref", spp=1, K=2, judge_exactness=False)
        assert meta["exact"] is False and meta["exact_note"].startswith("not judged"), meta.get("exact_note")
        assert "mnee_losses" not in meta
        assert json.loads((tmp_path / "ref" / "reference.json").read_text())["exact"] is False
        with pytest.raises(InputError, match="not judged"):
            losses.check_exact(tmp_path / "ref")

    @pytest.mark.slow
    def test_reference_records_losses_and_exactness(self, mi, tmp_path):
        """torus_hole (grey: one pass) at 12 x 12, eta 1.0001: without chains the reference says it is not exact, with
        them exact (at eta 1.4 it is not exact either way: reflections and further solutions, ``first_scatter``)."""
        import json

        from harness.reference import nonconvex
        from harness.reference.render import render_reference
        from harness.scene.load import scene_hash

        base = nonconvex.torus_hole(1.0001, size=12)
        grey = np.ones_like(base.medium.sigma_t)
        base = base.with_medium(sigma_t=2.0 * grey, albedo=0.85 * grey)
        for mc, want in ((1, False), (5, True)):
            scene = dataclasses.replace(base, boundary=dataclasses.replace(base.boundary, max_crossings=mc))
            scene = dataclasses.replace(scene, content_hash=scene_hash(scene))
            render_reference(scene, tmp_path / f"ref{mc}", spp=4, K=2)
            meta = json.loads((tmp_path / f"ref{mc}" / "reference.json").read_text())
            r = meta["mnee_losses"]["channels"]["R"]
            print(f"max_crossings = {mc}: {meta['exact_note']}; crossings {r['crossings']}")
            assert meta["exact"] is want, meta["exact_note"]
            assert r["crossings"]["3"] > 0.1 and set(meta["mnee_losses"]["channels"]) == {"R", "G", "B"}
            assert meta["mnee_losses"]["channels"]["G"]["lost_image_share"] > 0
            fs = meta["mnee_losses"]["first_scatter"]
            print(f"  first scatter: missed {fs['missed_share']} +- {fs['missed_share_se']}, reflections "
                  f"{fs['reflection_share']}")
            assert max(fs["reflection_share"]) < 1e-3, "eta 1.0001 reflects almost nothing"


def test_the_exactness_page_reads_the_connections_a_committed_reference_was_rendered_with():
    """``benchmarks/reference_exactness.py``'s ``committed`` way: a reference rendered as one grey pass per channel
    keeps one integrator block per channel; the connections are read from them, not taken as one crossing."""
    import json
    import sys

    from harness.paths import REPO
    from harness.scene import load_scene

    sys.path.insert(0, str(REPO / "benchmarks"))
    from reference_exactness import committed_boundary

    for name in ("skin_torus_dielectric", "jade_backlit_dielectric"):
        integ = json.loads((REPO / "baselines" / "refs" / name / "reference.json").read_text())["integrator"]
        block = integ.get("R", integ)
        got = committed_boundary(name, load_scene(name).boundary)
        assert (got.max_crossings, got.sms_trials, got.sms_chains) == (
            block["max_crossings"], block["sms_trials"], block["sms_chains"]), f"{name}: {got}"
    assert set(json.loads((REPO / "baselines" / "refs" / "skin_torus_dielectric" / "reference.json").read_text())[
        "integrator"]) == set("RGB"), "the skin torus's reference no longer has one block per channel"
