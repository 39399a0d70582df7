"""The planted errors in how a reference is rendered in parts: specular manifold sampling as a pass of its own
(``sms_split``: :class:`harness.reference.jobs.RenderSetup`, ``mneevolpath``'s ``sms_only``); the rest are in
:mod:`.catalogue`."""

from .runner import Mutation

ST = "tests/test_sms_split.py"

REFERENCE = (
    Mutation("sms_split_drops_sampled_part", "mitsuba", "harness/reference/jobs.py",
             "            for p in specs:\n                mean = self.sums[(p.name, s)] / self.counts[(p.name, s)]",
             "            for p in [q for q in specs if q.part != \"sampled\"]:\n"
             "                mean = self.sums[(p.name, s)] / self.counts[(p.name, s)]",
             (f"{ST}::test_a_seed_image_is_the_sum_of_its_parts",),
             "a split reference's seed image leaves out the sampled solutions' part, so the reference is darker "
             "by their light"),
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
)
