"""Specular manifold sampling in ``mneevolpath`` (:mod:`harness.reference.mnee_sms`): chains with a reflection
vertex and the further solutions of a refraction, each against an independent route.

* **The reflection chain against the mirror point.** In a slab with flat faces (100 x 1 x 100, air above and
  below) the light that enters the top, reflects off the bottom inside and reaches a point is the
  half-space's single refraction to the point mirrored in the bottom face, times the Fresnel reflectance
  there (:func:`harness.reference.halfspace.reflected_irradiance`, NumPy, no Mitsuba). The chain
  ``("R", "T")``'s estimate, averaged over 2,048 samples at each of six points, must agree within 4 standard
  errors at every point and channel, at eta 1.33 and 1.5; the same estimates against the NumPy value with
  the Fresnel *transmittance* at the reflection must not (planted error).
* **The outside reflection chain against the mirrored light.** With a second dielectric part above the light
  (one mesh of two boxes), the light that reflects off that part's lower face and enters the slab is the
  half-space's single refraction from the light mirrored in that face, times the Fresnel reflectance there
  (``reflected_irradiance(..., ceiling=)``); the chain ``("T", "r")`` must agree within 4 standard errors
  at eta 1.33 and 1.5, with half its seeds traced from the light and with all of them (``LIGHT_SIDE_SHARE``).
* **One solution is not counted twice.** On the slab the single refraction has one solution, which the
  straight seed's walk already connects: the sampled further refractions (``("T",)``) deliver exactly 0.
* **Bad input:** a chain that ends inside the medium or names an unknown kind, and ``sms_trials`` outside
  ``[0, MAX_TRIALS_LIMIT]``, are refused with one line.

The torus lit through its hole, where these chains carry a tenth of the first-scattered light, is
measured against the photon tracer of :mod:`harness.reference.specular_paths` by
``benchmarks/mnee_sms.py`` (``docs/benchmarks/mnee_sms.md``; too slow for the suite).
"""

import numpy as np
import pytest

ms = pytest.importorskip("harness.reference.mitsuba_scene")

SAMPLES = 2048
POINTS = np.array([[0.0, -0.3, 0.0], [0.5, -0.5, 0.3], [1.0, -0.8, -0.4], [-0.6, -0.6, 0.9], [1.5, -0.2, 1.0],
                   [0.2, -0.9, -1.2]])


@pytest.fixture(scope="module")
def mi():
    return ms.use_variant("llvm_ad_rgb")


def _slab(eta):
    from harness.reference import halfspace

    setup = dict(halfspace.SETUP, half_width=50.0, depth=1.0, light=(0.3, 1.0, 0.2))
    return halfspace.validation_scene(eta, size=4, setup=setup), setup


def _sampled(scene, chains, samples=SAMPLES):
    from harness.reference import connection_power

    x = np.repeat(POINTS, samples, axis=0)
    parts, _ = connection_power.connection_values(scene, x, inside=np.ones(len(x), bool),
                                                  integrator={"sms_trials": 64, "sms_chains": chains})
    return [v.reshape(len(POINTS), samples, 3) for v in parts]


def _against_mirror(scene, setup, eta, chain, what, **mirror):
    """The sampled chain's estimate at :data:`POINTS` against ``reflected_irradiance`` (``mirror``: its
    ``ceiling``), and against the planted Fresnel transmittance at the reflection."""
    from harness.reference import halfspace

    v = _sampled(scene, chain)[-1]
    mean, se = v.mean(1), v.std(1, ddof=1) / np.sqrt(v.shape[1])
    args = (POINTS, setup["light"], setup["intensity"], eta, setup["sigma_t"], 1.0)
    ref = halfspace.reflected_irradiance(*args, **mirror)
    wrong = halfspace.reflected_irradiance(*args, fresnel="transmit", **mirror)
    z, zw = (mean - ref) / se, (mean - wrong) / se
    found = (v[..., 0] > 0).mean(1)
    print(f"{what}: {chain} / mirror {np.round(mean / ref, 3).tolist()}, max |z| {np.abs(z).max():.2f}; found by "
          f"the first walk {np.round(found, 3).tolist()}; planted (1 - F at the reflection) min |z| "
          f"{np.abs(zw).min():.0f}")
    assert np.all(ref > 0) and np.all(found > 0.02), f"{what}: the scene no longer exercises the chain {chain}"
    assert np.abs(z).max() <= 4.0, f"{what}: {chain} disagrees with the mirror: z {np.round(z, 2).tolist()}"
    assert np.abs(zw).min() > 8.0, f"{what}: a reflection weighted by the transmittance would go unnoticed"


@pytest.mark.slow
@pytest.mark.parametrize("eta", [1.33, 1.5])
def test_reflection_chain_against_the_mirror_point(mi, eta):
    scene, setup = _slab(eta)
    _against_mirror(scene, setup, eta, "RT", f"slab, eta {eta}")


def _ceiling(eta):
    """The slab with a second dielectric part above the light (``y`` in ``[2, 3]``): one mesh of two boxes."""
    from harness.reference import halfspace

    setup = dict(halfspace.SETUP, half_width=50.0, depth=1.0, light=(0.3, 1.0, 0.2), slab=CEILING)
    return halfspace.validation_scene(eta, size=4, setup=setup), setup


#: The ceiling part ``(y, thickness, z0, z1)`` of :func:`_ceiling` (``harness.reference.halfspace._slab_box``).
CEILING = (2.0, 1.0, -50.0, 50.0)


@pytest.mark.slow
@pytest.mark.parametrize("eta,share", [(1.33, 0.5), (1.5, 0.5), (1.5, 1.0)])
def test_outside_reflection_chain_against_the_mirrored_light(mi, eta, share, monkeypatch):
    """``("T", "r")``: the light reflects off the ceiling outside, then enters the slab; the ceiling mirrors the
    light. ``share = 1`` takes every seed from the light's side (:func:`harness.reference.mnee_sms.seed_from_light`)."""
    from harness.reference import mnee_sms

    monkeypatch.setattr(mnee_sms, "LIGHT_SIDE_SHARE", share)
    scene, setup = _ceiling(eta)
    _against_mirror(scene, setup, eta, "Tr", f"ceiling, eta {eta}, light-side share {share}", ceiling=CEILING[0])


@pytest.mark.slow
def test_a_unique_refraction_is_not_counted_twice(mi):
    scene, _ = _slab(1.5)
    single, _chains, further = _sampled(scene, "T", samples=256)
    assert np.all(single > 0), "the straight seed's walk must connect every point of the slab"
    assert np.all(further == 0.0), "the sampled refraction counted the straight seed's solution again"


def test_chain_kinds_are_checked(mi):
    from harness.reference import mnee_sms

    assert mnee_sms.parse_chains("T, RT,Tr") == (("T",), ("R", "T"), ("T", "r"))
    for bad, words in (("TT", "end inside"), ("RX", "cannot follow"), ("rT", "cannot follow"), (" , ", "no chain")):
        with pytest.raises(ValueError, match=words) as exc:
            mnee_sms.parse_chains(bad)
        assert "\n" not in str(exc.value)


@pytest.mark.parametrize("value", [-1, 4097])
def test_sms_trials_out_of_range_is_refused(mi, value):
    from harness.reference import halfspace, mnee_sms

    assert value < 0 or value > mnee_sms.MAX_TRIALS_LIMIT
    d = ms.build_scene_dict(halfspace.validation_scene(1.5, size=4))
    d["integrator"]["sms_trials"] = value
    with pytest.raises(Exception, match="sms_trials"):
        mi.load_dict(d)


def test_the_scene_turns_sampling_on(mi):
    import dataclasses

    from harness.scene import scene_hash
    from harness.scene.model import SMS_CHAINS_DEFAULT

    def with_boundary(s, **change):
        out = dataclasses.replace(s, boundary=dataclasses.replace(s.boundary, **change))
        return dataclasses.replace(out, content_hash=scene_hash(out))

    scene, _ = _slab(1.5)
    off = ms.build_scene_dict(scene)["integrator"]
    assert "sms_trials" not in off and "sms_chains" not in off
    on_scene = with_boundary(scene, sms_trials=256)
    on = ms.build_scene_dict(on_scene)["integrator"]
    assert on["sms_trials"] == 256 and on["sms_chains"] == SMS_CHAINS_DEFAULT
    other = with_boundary(on_scene, sms_chains="RT")
    # the hash follows the sampling where it is on, and ignores its chains where it is off
    assert len({scene.content_hash, on_scene.content_hash, other.content_hash}) == 3
    assert with_boundary(scene, sms_chains="RT").content_hash == scene.content_hash
