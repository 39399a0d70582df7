"""A reference whose specular manifold sampling is rendered as a pass of its own (``sms_split``).

The sampled solutions' light is added to the rest's as distinct paths (``mneevolpath``'s 7.), so an image
rendered without sampling plus one that holds only the sampled light (``sms_only``) has the expectation of
the whole, and the costly part may take fewer samples (:class:`harness.reference.jobs.RenderSetup`).

* **The parts add up to the whole, through the whole pipeline.** On a thin slab lit at a grazing angle, where
  the chain ``RT`` (in through the top, reflected off the bottom inside) carries 7-14 % of the image, a
  reference rendered with the split (``sms_split = 4``) agrees with one rendered whole: each channel's image
  mean within 4 standard errors (independent seeds). The test has power: the sampled part is more than 4
  standard errors of the image in at least one channel, so a split that drops it, counts the rest in it, or
  samples in the rest would fail (planted errors ``sms_split_drops_sampled_part``,
  ``sms_only_keeps_the_rest``, ``sms_split_rest_samples_too``).
* **The per-seed sums** (no Mitsuba): the sampled part's jobs take ``ceil(n / split)`` of the ``n`` samples
  handed out to a seed so far, whatever the rounds; a seed's image is the sum of its parts' means; the
  sampled part is not counted in the samples done; a rolled-back round restores the count handed out.
* **The cost per sample** of a seed weighs the sampled part by its share of the samples (planted error
  ``sms_split_cost_unweighted``), so a render capped by ``max_seconds`` plans its steps from what they cost.
* **Bad input:** a split outside ``[1, MAX_SMS_SPLIT]``, or on a scene without sampling, is refused with one
  line; so is ``sms_only`` without ``sms_trials``.
"""

import dataclasses

import numpy as np
import pytest

from harness.errors import InputError


def _specs(split=True, channels=(0, 1, 2)):
    from harness.reference.jobs import PassSpec

    parts = ("rest", "sampled") if split else (None,)
    return [PassSpec("full", c, p) for c in channels for p in parts]


def test_the_sampled_part_takes_one_sample_in_split():
    from harness.reference.jobs import _Estimate

    est = _Estimate(_specs(channels=(None,)), [0, 1], split=4)
    got = {}
    for spp in (4, 12, 1, 47):           # the pilot's rounds, then uneven steps
        for job in est.jobs(spp, chunk_spp=5):
            got.setdefault((job.pass_name, job.seed), []).append(job.spp)
    assert sum(got[("full_rest", 0)]) == 64 and max(got[("full_rest", 0)]) <= 5
    # ceil(4/4) = 1, ceil(16/4) = 4, ceil(17/4) = 5, ceil(64/4) = 16: the rounding never accumulates
    assert sum(got[("full_sampled", 0)]) == 16 and sum(got[("full_sampled", 1)]) == 16
    snap = est.snapshot()
    est.jobs(8, chunk_spp=5)
    est.restore(snap)
    assert sum(j.spp for j in est.jobs(8, chunk_spp=5) if j.pass_name == "full_sampled") == 2 * 2


def test_a_seed_image_is_the_sum_of_its_parts():
    from harness.reference.jobs import _Estimate

    est = _Estimate(_specs(), [3, 4], split=2)
    rng = np.random.default_rng(1)
    want = {}
    for job in est.jobs(6, chunk_spp=6):
        value = rng.random((2, 2, 3))
        est.merge(job, {"sum": value * job.spp, "spp": job.spp})
        want.setdefault(job.seed, np.zeros((2, 2, 3)))
        c = int("rgb".index(job.pass_name.split("_")[1]))
        want[job.seed][..., c] += value[..., c]
    stack = est.stack("full")
    assert np.allclose(stack, np.stack([want[3], want[4]]))
    assert est.samples_done() == 12          # 6 per seed over the rest's passes; the sampled part's 3 not counted


@pytest.mark.parametrize("split, why", [(0, "outside"), (65, "outside"), (4, "samples no specular manifolds")])
def test_a_split_out_of_range_or_without_sampling_is_refused(split, why):
    pytest.importorskip("harness.reference.mitsuba_scene")
    from harness.reference import halfspace
    from harness.reference.jobs import RenderSetup

    scene = halfspace.validation_scene(1.5, size=4)          # a smooth dielectric, sms_trials 0
    with pytest.raises(InputError, match=why) as exc:
        RenderSetup(scene, sms_split=split)
    assert "\n" not in str(exc.value) and "sms_split" in str(exc.value)


def test_regenerate_applies_the_split_to_the_scenes_that_sample(monkeypatch, capsys):
    """``baselines regenerate-references --sms-split N`` over several scenes passes the split to those that sample
    (bunny_dielectric: ``sms_trials`` 4096) and renders the others in one pass; named only for scenes that do not
    sample, it is refused in one line, before anything renders."""
    pytest.importorskip("harness.reference.mitsuba_scene")
    from harness.cli import main
    from harness.regression import baselines

    got = {}
    monkeypatch.setattr(baselines, "regenerate_reference", lambda n, **kw: got.setdefault(n, kw["sms_split"]))
    argv = ["baselines", "regenerate-references", "--serial", "--no-progress", "--sms-split", "4", "--scenes"]
    assert main(argv + ["jade_veins,bunny_dielectric"]) == 0
    assert got == {"jade_veins": None, "bunny_dielectric": 4}
    got.clear()
    assert main(argv + ["jade_veins"]) == 2 and not got
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1 and err[0].startswith("error: --sms-split: sms_split: none of the scenes"), err


def test_sms_only_without_sampling_is_refused():
    ms = pytest.importorskip("harness.reference.mitsuba_scene")
    from harness.reference import halfspace

    mi = ms.use_variant("llvm_ad_rgb")
    d = ms.build_scene_dict(halfspace.validation_scene(1.5, size=4))
    d["integrator"]["sms_only"] = True
    with pytest.raises(Exception, match="sms_only = true needs sms_trials"):
        mi.load_dict(d)


def _slab(sms_trials):
    from harness.reference import halfspace
    from harness.scene import scene_hash

    setup = dict(halfspace.SETUP, half_width=50.0, depth=0.3, light=(3.0, 0.6, 0.2))
    scene = halfspace.validation_scene(1.5, size=8, setup=setup)
    scene = dataclasses.replace(scene, boundary=dataclasses.replace(scene.boundary, sms_trials=sms_trials,
                                                                       sms_chains="RT"))
    return dataclasses.replace(scene, content_hash=scene_hash(scene))


def _mean_and_se(folder):
    from harness.io.images import read_exr

    img = read_exr(folder / "subsurface.exr")
    n = img["rgb"][..., 0].size
    return img["rgb"].mean((0, 1)), np.sqrt(np.square(img["se"]).sum((0, 1))) / n


@pytest.mark.slow
def test_the_split_parts_add_up_to_the_whole(tmp_path):
    ms = pytest.importorskip("harness.reference.mitsuba_scene")
    from harness.reference.render import render_reference

    ms.use_variant("llvm_ad_rgb")
    got = {}
    for name, scene, split in (("whole", _slab(64), 1), ("split", _slab(64), 4), ("rest", _slab(0), None)):
        meta = render_reference(scene, tmp_path / name, spp=256, K=8, seed_base=11, judge_exactness=False,
                                sms_split=split)
        got[name] = _mean_and_se(tmp_path / name)
        if name == "split":
            assert meta["sms_split"] == 4 and "full_r_sampled" in meta["passes"], meta["passes"]
    (w, w_se), (s, s_se), (r, r_se) = got["whole"], got["split"], got["rest"]
    z = (s - w) / np.hypot(s_se, w_se)
    z_part = (w - r) / np.hypot(w_se, r_se)
    print(f"split / whole {np.round(s / w, 4).tolist()}, z {np.round(z, 2).tolist()}; sampled share "
          f"{np.round(1 - r / w, 3).tolist()}, z {np.round(z_part, 1).tolist()}")
    assert np.max(z_part) > 4.0, "the slab no longer exercises the sampled chain: the test would have no power"
    assert np.abs(z).max() <= 4.0, f"the split reference disagrees with the whole one: z {np.round(z, 2).tolist()}"


def test_the_cost_of_a_seed_sample_weighs_the_sampled_part_by_its_share():
    from harness.reference.noise import unit_cost

    # the rest: 1 s a sample; the sampled part: 10 s a sample, rendered at one sample in four
    jobs = [("full_rest", 8, 8.0, 8.0), ("full_sampled", 2, 20.0, 20.0)]
    assert unit_cost(jobs, weights={"full_sampled": 0.25}) == pytest.approx((1.0 + 10.0 / 4) / 2)
    assert unit_cost(jobs) == pytest.approx((1.0 + 10.0) / 2)


def test_the_split_is_on_by_default_only_where_the_scene_samples():
    pytest.importorskip("harness.reference.mitsuba_scene")
    from harness.reference.jobs import DEFAULT_SMS_SPLIT, RenderSetup

    assert RenderSetup(_slab(64)).split == DEFAULT_SMS_SPLIT > 1
    assert RenderSetup(_slab(64), sms_split=1).split == 1
    assert [p.name for p in RenderSetup(_slab(64), sms_split=1).passes()] == ["full_r", "full_g", "full_b"]
    assert RenderSetup(_slab(0)).split == 1 and RenderSetup(_slab(0), sms_split=1).split == 1
