"""The planted errors in how a reference is rendered in parts: specular manifold sampling as a pass of its own
(``sms_split``: :class:`harness.reference.jobs.RenderSetup`, ``mneevolpath``'s ``sms_only``), and in the share
of the light the reference misses, counted on the photons' paths (:mod:`harness.reference.coverage`) and judged
(:mod:`harness.reference.losses`); the rest are in :mod:`.catalogue`."""

from .runner import Mutation

ST = "tests/test_sms_split.py"
CV = "tests/test_coverage.py"

REFERENCE = (
    Mutation("sms_split_drops_sampled_part", "mitsuba", "harness/reference/jobs.py",
             "            for p in specs:\n                mean = self.sums[(p.name, s)] / self.counts[(p.name, s)]",
             "            for p in [q for q in specs if q.part != \"sampled\"]:\n"
             "                mean = self.sums[(p.name, s)] / self.counts[(p.name, s)]",
             (f"{ST}::test_a_seed_image_is_the_sum_of_its_parts",),
             "a split reference's seed image leaves out the sampled solutions' part, so the reference is darker "
             "by their light"),
    Mutation("regenerate_split_to_every_scene", "mitsuba", "harness/regression/baselines.py",
             "sms_split=args.sms_split if samples[n] else None)", "sms_split=args.sms_split)",
             (f"{ST}::test_regenerate_applies_the_split_to_the_scenes_that_sample",),
             "regenerate-references --sms-split over several scenes hands the split to a scene that does not "
             "sample, which refuses it, so the command stops at the first such scene"),
    Mutation("reference_chromatic_in_one_pass", "mitsuba", "harness/reference/mitsuba_scene.py",
             "return (None,) if np.all(st == st[..., :1]) else (0, 1, 2)", "return (None,)",
             ("tests/test_mnee_chain.py::test_eta_one_on_the_scanned_bunny_reproduces_index_matched_volpath",),
             "a chromatic medium's reference is rendered in one RGB pass, where volpath's spectral weights are "
             "heavy-tailed in the channel whose paths are longest (red through the scanned bunny)"),
    Mutation("chain_other_part_transparent", "mitsuba", "harness/reference/mnee_connect.py",
             "            if inside:\n                tr *= self._ratio_track(medium, verts[i - 1][0], verts[i][0], sampler, conn)",
             "            if False:\n                tr *= self._ratio_track(medium, verts[i - 1][0], verts[i][0], sampler, conn)",
             ("tests/test_mnee_chain.py::test_eta_one_on_the_other_suite_smooth_scenes_reproduces_index_matched_volpath"
              "[skin_torus_dielectric]",),
             "a chain's light crosses the other part of the object (the skin torus's near side of the ring) without "
             "its medium's transmittance"),
    Mutation("sms_only_keeps_the_rest", "mitsuba", "harness/reference/mnee.py",
             "rest = 0.0 if self.sms_only else 1.0", "rest = 1.0",
             (f"{ST}::test_the_split_parts_add_up_to_the_whole",),
             "mneevolpath's sms_only image holds all the light, so a split reference counts the rest twice"),
    Mutation("sms_split_rest_samples_too", "mitsuba", "harness/reference/mitsuba_scene.py",
             'if scene.boundary.sms_trials and part != "rest":', "if scene.boundary.sms_trials:",
             (f"{ST}::test_the_split_parts_add_up_to_the_whole",),
             "the rest's pass of a split reference samples the specular manifolds too, so their light is counted "
             "twice"),
    Mutation("sms_split_cost_unweighted", "mitsuba", "harness/reference/noise.py",
             "w = {p: (weights or {}).get(p, 1.0) for p in passes}", "w = {p: 1.0 for p in passes}",
             (f"{ST}::test_the_cost_of_a_seed_sample_weighs_the_sampled_part_by_its_share",),
             "the seconds per sample of a split reference count the sampled part's pass at every sample, so a "
             "capped render plans too few samples"),
    Mutation("coverage_point_weight_without_choice", "mitsuba", "harness/reference/coverage.py",
             "* h[:, None] / qk[:, None])", "* h[:, None])",
             (f"{CV}::test_points_carry_the_traced_power",),
             "a first-scatter point's weight is not divided by the probability of its sub-interval, so the points "
             "carry a fraction of the traced power and the share missed is weighed by the wrong light"),
    Mutation("coverage_path_not_reversed", "mitsuba", "harness/reference/coverage.py",
             "return tuple(KIND_OF_EVENT[c] for c in reversed(label))", "return tuple(KIND_OF_EVENT[c] for c in label)",
             (f"{CV}::test_a_sampled_reflection_chain_is_found",),
             "a photon's path is read from the light instead of from the medium vertex, so a sampled chain with a "
             "reflection (ER is RT from the vertex) is looked for as another chain and counted missed"),
    Mutation("coverage_straight_walk_ignored", "mitsuba", "harness/reference/coverage.py",
             "            found |= conn & same\n", "",
             (f"{CV}::test_a_convex_sphere_misses_its_reflections",),
             "the paths the straight seed's walk connects are not counted as found, so every refraction is "
             "called missed where no sampling finds it"),
    Mutation("verdict_ignores_disagreeing_routes", "mitsuba", "harness/reference/losses.py",
             "    ok, why = consistent(losses)\n    if not ok:\n        return False, why\n", "",
             (f"{CV}::TestVerdict::test_routes_that_disagree_are_refused",),
             "a reference whose connections deliver less light than the paths they find carry is judged exact "
             "by the share of paths found alone"),
    Mutation("coverage_judged_after_one_batch", "mitsuba", "harness/reference/coverage.py",
             "len(batches) * photons < min(min_photons, max_photons) or undecided()", "undecided()",
             (f"{CV}::test_a_limit_is_judged_after_the_fewest_photons",),
             "the share missed on the photons' paths is judged as soon as one batch decides, so a batch that drew "
             "none of the heavy grazing photons can call a reference exact"),
)
