"""Validation of the share missed on the photons' paths (:mod:`harness.reference.coverage`) and of the verdict
that decides with it (:mod:`harness.reference.losses`).

* **The points carry the traced power.** The first-scatter points drawn on the recorded segments (Eq. C1) sum,
  per channel, to the tracer's own first-scattered power within 4 standard errors of the within-segment
  draw (the segments' power computed by :func:`harness.reference.specular_paths._segment`, as the tracer does).
* **A convex sphere misses its reflections.** On a dense ball behind a smooth dielectric
  (``tests/test_specular_paths.py``'s sphere, sigma_t 2 / 3 / 4, so little light reaches the ball lens's
  caustic), without specular manifold sampling, no path with a reflection is found, and their share of the
  drawn weight is the reflected share that the sphere's quadrature gives (an independent route: Fresnel and
  attenuation integrated over the ball's face) within 10 % (the mesh is a faceted sphere); the refraction
  paths are found but for the caustic's (at least 98.5 %); and the share missed agrees with the power
  comparison's ``1 - delivered / traced`` (:func:`harness.reference.losses.consistent`).
* **A sampled chain is found.** On a flat slab lit so that light enters, reflects off the lower face and
  scatters (photon label ``ER``, chain ``RT`` from the medium vertex), the paths of that label are found with
  ``sms_chains = "RT"`` (a flat face has one mirror solution, which the trials find: covered >= 0.95) and never
  without it, and the share missed falls by at least 0.9 of that label's share.
* **The verdict** decides with the photons' paths where they are recorded, refuses a reference whose two
  routes disagree, and falls back to the power comparison for a reference measured before.
"""

import dataclasses

import numpy as np
import pytest

from .test_specular_paths import sphere_quadrature, thin_sphere

ms = pytest.importorskip("harness.reference.mitsuba_scene")


@pytest.fixture(scope="module")
def mi():
    return ms.use_variant("llvm_ad_rgb")


def test_points_carry_the_traced_power(mi):
    from harness.reference import coverage, specular_paths

    scene = thin_sphere(sigma_t=(2.0, 3.0, 4.0))
    record = []
    traced = specular_paths.trace(scene, photons=4096, seed=3, record=record)
    pts = coverage.draw_points(scene, record, np.random.default_rng(5))
    exact = np.concatenate([b["w"] * specular_paths._segment(scene.medium, b["o"], b["d"], b["t"])[0]
                            for b in record])
    total = sum(traced["by_label"].values())
    assert np.allclose(exact.sum(0), total, rtol=1e-9), "the recorded segments are not the traced ones"
    se = np.sqrt(np.square(pts["W"] - exact).sum(0))
    z = (pts["W"].sum(0) - total) / se
    print(f"points {len(pts['W'])}: drawn / traced {pts['W'].sum(0) / total}, z {z}")
    assert np.all(np.abs(z) < 4.0), z
    assert len(pts["verts"]) == len(pts["W"]) and all(len(v) == len(lab) for v, lab in zip(pts["verts"],
                                                                                            pts["label"]))


def _reflected_share(scene, photons=1 << 15):
    """The drawn points' share of weight on paths with a reflection, and its standard error over photons."""
    from harness.reference import coverage, specular_paths

    record = []
    specular_paths.trace(scene, photons=photons, seed=8, record=record)
    pts = coverage.draw_points(scene, record, np.random.default_rng(9))
    keys, group = np.unique(pts["photon"], return_inverse=True)
    a, b = np.zeros((len(keys), 3)), np.zeros((len(keys), 3))
    np.add.at(a, group, pts["W"] * (pts["label"] != "E")[:, None])
    np.add.at(b, group, pts["W"])
    m = a.sum(0) / b.sum(0)
    return m, np.sqrt(np.square(a - m * b).sum(0) * photons / (photons - 1)) / b.sum(0)


def test_a_convex_sphere_misses_its_reflections(mi):
    from harness.reference import coverage, losses

    scene = thin_sphere(sigma_t=(2.0, 3.0, 4.0))
    scene = dataclasses.replace(scene, boundary=dataclasses.replace(scene.boundary, sms_trials=0))
    got = coverage.missed(scene, photons=1 << 14, seed=11)
    direct, reflection = sphere_quadrature(scene)
    want = reflection / (direct + reflection)
    refl = {k: v for k, v in got["by_label"].items() if k != "E"}
    share, se = _reflected_share(scene)
    print(f"reflected share {share} ± {se}, the quadrature's {want}; refraction paths found "
          f"{got['by_label']['E']['covered']}; missed {got['missed_share']} ± {got['missed_share_se']}")
    assert all("R" in k and max(v["covered"]) == 0.0 for k, v in refl.items()), refl
    assert np.all(np.abs(share - want) <= 0.1 * want + 4.0 * se), (share, se, want)
    # the ball lens's caustic: the single walk finds one of several refraction paths (within the 1.5 % that
    # tests/test_connection_power.py allows the delivered power on this sphere)
    assert min(got["by_label"]["E"]["covered"]) >= 0.985
    fs = losses.first_scatter(scene, photons=1 << 16, points=1 << 16, seed=4)
    ok, why = losses.consistent({"coverage": got, "first_scatter": fs})
    print(f"by power {fs['missed_share']} ± {fs['missed_share_se']}")
    assert ok, why


def test_a_limit_is_judged_after_the_fewest_photons(mi):
    """With a limit the share is measured with at least ``min_photons`` even where the first batch decides (the
    weights' tail: :mod:`harness.reference.coverage`); without one, with one batch."""
    from harness.reference import coverage

    scene = thin_sphere(sigma_t=(2.0, 3.0, 4.0))
    scene = dataclasses.replace(scene, boundary=dataclasses.replace(scene.boundary, sms_trials=0))
    judged = coverage.missed(scene, photons=1 << 10, seed=3, limit=0.5, min_photons=3 << 10)
    assert judged["photons"] == 3 << 10
    once = coverage.missed(scene, photons=1 << 10, seed=3)
    assert once["photons"] == 1 << 10
    assert all(0.0 < h <= 1.0 for h in judged["heaviest_share"]), judged["heaviest_share"]


def _slab(sms_chains):
    from harness.reference import halfspace
    from harness.scene import scene_hash

    setup = dict(halfspace.SETUP, half_width=50.0, depth=1.0, light=(0.3, 1.0, 0.2))
    scene = halfspace.validation_scene(1.5, size=4, setup=setup)
    boundary = dataclasses.replace(scene.boundary, sms_trials=64 if sms_chains else 0, sms_chains=sms_chains or "T")
    scene = dataclasses.replace(scene, boundary=boundary)
    return dataclasses.replace(scene, content_hash=scene_hash(scene))


def test_a_sampled_reflection_chain_is_found(mi):
    from harness.reference import coverage

    sampled = coverage.missed(_slab("RT"), photons=1 << 13, seed=2)
    plain = coverage.missed(_slab(None), photons=1 << 13, seed=2)
    er_s, er_p = sampled["by_label"]["ER"], plain["by_label"]["ER"]
    print(f"ER: share {er_s['share']}, covered sampled {er_s['covered']} / plain {er_p['covered']}; missed "
          f"sampled {sampled['missed_share']} ± {sampled['missed_share_se']}, plain {plain['missed_share']}")
    assert min(er_s["covered"]) >= 0.95 and max(er_p["covered"]) == 0.0
    assert np.all(np.asarray(plain["missed_share"]) - np.asarray(sampled["missed_share"])
                  > 0.9 * np.asarray(er_s["share"]))


class TestVerdict:
    LIMIT = 0.25 * 0.04

    def found(self, cov=None, fs=None):
        ch = {"lost_image_share": 0.0, "lost": 0.0, "over_max": 0.0}
        out = {"max_crossings": 5, "channels": {c: dict(ch) for c in "RGB"}}

        def route(m, se):
            return {"missed_share": [m, 0.0, 0.0], "missed_share_se": [se, 0.0, 0.0], "points": 1 << 16,
                    "reflection_share": [0.0, 0.0, 0.0]}
        if cov:
            out["coverage"] = route(*cov)
        if fs:
            out["first_scatter"] = route(*fs)
        return out

    def test_the_photons_paths_decide(self):
        from harness.reference import losses

        lim = self.LIMIT
        # the power comparison alone is undecided (0.7 +- 0.25 of the limit); the photons' paths decide
        assert not losses.verdict(self.found(fs=(0.7 * lim, 0.25 * lim)), 0.04)[0]
        exact, note = losses.verdict(self.found(cov=(0.66 * lim, 0.05 * lim), fs=(0.7 * lim, 0.25 * lim)), 0.04)
        assert exact and "photons' paths" in note, note
        exact, note = losses.verdict(self.found(cov=(0.95 * lim, 0.05 * lim), fs=(0.9 * lim, 0.25 * lim)), 0.04)
        assert not exact and "undecided" in note, note

    def test_routes_that_disagree_are_refused(self):
        from harness.reference import losses

        lim = self.LIMIT
        exact, note = losses.verdict(self.found(cov=(0.2 * lim, 0.02 * lim), fs=(2.0 * lim, 0.1 * lim)), 0.04)
        assert not exact and "in doubt" in note and "channel R" in note, note
        # a power comparison above the photons' by less than CONSISTENT_SE combined errors is noise
        exact, _ = losses.verdict(self.found(cov=(0.2 * lim, 0.02 * lim), fs=(0.45 * lim, 0.1 * lim)), 0.04)
        assert exact

    def test_an_older_reference_is_judged_by_power(self):
        from harness.reference import losses

        lim = self.LIMIT
        exact, note = losses.verdict(self.found(fs=(0.3 * lim, 0.1 * lim)), 0.04)
        assert exact and "photons' paths" not in note
