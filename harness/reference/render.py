"""Render a ground-truth reference folder for one scene, with per-pixel noise estimates.

:func:`render_reference` renders the scene (``full``) and, when it can differ
from zero, the same scene with albedo 0 (``absorber``: surface reflection and
unscattered transmission only). ``subsurface = full - absorber``. Each image is
the mean of ``K`` independent renders (distinct ``seed``); the per-pixel
standard error is ``std(ddof=1) / sqrt(K)`` per channel, and
``se_subsurface = sqrt(se_full^2 + se_absorber^2)`` (disjoint seeds). A medium whose
σt differs between channels is rendered as one grey pass per channel
(:func:`harness.reference.mitsuba_scene.channel_passes`); a seed's image then takes
channel c from pass c.

With an index-matched boundary (``null`` BSDF) or a smooth dielectric one, a black
background and only point lights, the absorber image is exactly zero (no surface
reflection is ever seen: a delta light reflected by a delta interface reaches the
pinhole with probability zero, camera rays that leave the object see black, and a delta
light is never hit), so its pass is skipped and ``subsurface = full``; ``reference.json``
says so (:func:`.mitsuba_scene.absorber_is_black`). The integrator is chosen by
:func:`.mitsuba_scene.integrator_dict` (``mneevolpath`` behind a smooth dielectric).

Choosing the sample count: unless ``spp`` is given, a pilot (4 seeds at
``PILOT_SPP``, rendered in two rounds: after the first, ``PILOT_EARLY_SPP`` samples per
seed, the log already gives a prediction beside the cost model's, so that a scene the
model mispredicts is corrected early) measures the median relative standard error ``r_p`` of the
subsurface image over lit pixels at ``N_p`` samples per pixel, and the total is
``N = N_p (r_p / target)^2`` (SE ~ 1/sqrt(N); the low bias of a median of SEs
estimated from few seeds is corrected, :func:`se_median_factor`), split over
``K`` seeds and capped by ``max_spp_per_seed`` and by ``max_seconds``. The final
render then runs in up to ``STEPS`` steps (every seed gets an equal share of its
samples per step; one step per ``STEP_MIN_SPP`` samples per seed, so a small render
is one step); after each step the noise is measured, which is the progress the
``reference`` command shows, and the render stops as soon as the target is met.
The steps follow from the sample counts alone, never from measured times or the
executor's size: a step's samples are a seed's next chunks (Mitsuba seeds), so a
timing-dependent step plan would make the serial and the cluster's image differ.
Heavy tails (rough dielectric boundaries, forward-peaked phase functions) make a short pilot
optimistic: the noise then falls by less than 2 between the pilot's two rounds, and the prediction
is raised by :func:`harness.reference.cost.tail_factor` (the log says so); when
all planned samples are in and the target is still missed, every seed is topped up
(new Mitsuba seeds) from a new prediction, at most three times. The figure written
to ``reference.json`` is the one *measured* on the final render (``target_met``
says whether it meets the target; ``capped_by`` names a cap that stopped it).

Specular manifold sampling in a pass of its own. Behind a smooth dielectric with ``[boundary] sms_trials``,
the sampled solutions' light (``mneevolpath``'s 7.) is a few per cent of the image and much of its
cost, and it adds to the rest's as distinct paths. So each full pass is split in two (``sms_split``,
:class:`.jobs.RenderSetup`; :data:`.jobs.DEFAULT_SMS_SPLIT` where none is given): the rest, with sampling
off, and the sampled light alone (``sms_only``) with one sample for every ``sms_split`` of the rest.
A seed's image is the sum of its two parts' means, so its expectation is the whole's and the seeds'
spread still gives the noise (``tests/test_sms_split.py``; the time to the target,
``docs/benchmarks/bench_sms_split.md``). ``sms_split = 1`` renders one pass.

Scheduling. The work is a set of independent *jobs*, one ``mi.render`` call
each: a pass, a seed, the seed's chunk index and a sample count
(:class:`.jobs.Job`). :func:`.jobs.render_job` is the unit a worker runs (it builds each
pass's Mitsuba scene once per process and keeps it); :class:`.plan.ReferencePlan`
decides the jobs round by round (pilot, the steps of the final render, top-ups)
and merges what comes back; an executor runs the rounds: :class:`SerialExecutor`
(this module) in this process, or :class:`harness.reference.distributed.DaskDriver` on a Dask
cluster. The noise figure is measured by :mod:`harness.reference.noise`. A job's result is its image times its sample count (float64); per (pass,
seed) the results are added in chunk order, whoever rendered them and in whatever
order they arrived, so a reference rendered on a cluster is bit-identical to the
serial one for the same seeds *and the same Dr.Jit thread count per render*
(``threads``: Mitsuba 3.9.1's image of one seed differs between 1, 2 and 3 threads
on this machine, while 2, 4 and 16 agree). A job whose worker died is run again
and merged once, by its (pass, seed, chunk): nothing is counted twice.

``max_seconds`` caps the wall time: each step is sized to end before the cap
(from the measured seconds per sample and the executor's parallel slots), and a
step still running at the cap is abandoned and rolled back, so every seed keeps
the same sample count. The pilot and the first step (at least 1 spp per seed)
always complete, so there is always a reference to write.

Noise figure: lit pixels are fully covered by the mesh (coverage >= 0.999) and,
per channel, brighter than 1 % of that channel's 99th percentile over covered
pixels; the figure is the median of ``se / mean`` over the lit (pixel, channel)
pairs.
"""

from .jobs import (CHUNK_SEEDS, DEFAULT_K, SEED_STRIDE, Job, PassSpec, RenderSetup,  # noqa: F401
                   render_job)
from .noise import LIT_FRACTION, lit_mask, median_rel_se, se_median_factor, seed_stats, unit_cost  # noqa: F401
from .plan import (MAX_LANES, MAX_SPP_PER_SEED, MAX_TOPUPS, PILOT_EARLY_SPP, PILOT_K, PILOT_SPP,  # noqa: F401
                   REFERENCE_FILES, STEP_MIN_SPP, STEPS, ReferencePlan, check_max_seconds)


# --------------------------------------------------------------------------- executors

class SerialExecutor:
    """Runs a plan's jobs one after another in this process (Dr.Jit uses every core per render)."""

    slots = 1
    name = "serial"

    def run(self, plan):
        try:
            jobs = plan.start()
            while jobs is not None:
                for job in jobs:
                    if plan.abortable() and plan.past_deadline():
                        plan.abort_round()
                        break
                    plan.merge(job, render_job(plan.setup, job))
                jobs = plan.next_jobs()
            return plan.finish()
        finally:
            plan.close_progress()


def render_reference(scene, out_dir, spp=None, K=None, target_rel_se=0.05, variant=None, max_seconds=None,
                     max_spp_per_seed=MAX_SPP_PER_SEED, seed_base=0, extra_emitters=None, threads=None,
                     client=None, progress=False, steps=None, judge_exactness=True, sms_split=None):
    """Render the reference folder of ``scene`` into ``out_dir`` (atomically) and return its metadata.

    Parameters
    ----------
    scene : harness.scene.Scene
    out_dir : path; replaced as a whole on success.
    spp : samples per pixel per seed; ``None`` chooses it from a pilot to meet ``target_rel_se``.
    K : number of independent seeds (default 8; at least 2).
    target_rel_se : median relative SE of the subsurface image over lit pixels to aim for.
    variant : ``llvm_ad_rgb`` (default) or ``cuda_ad_rgb``.
    max_seconds : cap on the wall time of the whole render, or ``None`` (see the module docstring).
    max_spp_per_seed : cap on the chosen ``spp``.
    seed_base : first seed; the final render uses ``seed_base + i``, i < K.
    extra_emitters : emitters added to the scene (validation scenes); forces the absorber pass.
    threads : Dr.Jit threads per render (None: Dr.Jit's default). The image depends on it.
    client : a ``dask.distributed.Client``: render the jobs on its workers; None renders here.
    progress : show progress on stderr (:class:`harness.progress.Progress`).
    steps : steps of the final render (None: one per ``STEP_MIN_SPP`` samples per seed, at most ``STEPS``).
    judge_exactness : measure a smooth-dielectric scene's exactness verdict (:mod:`harness.reference.losses`)
        after the render. ``False`` (timing benchmarks only) skips it and records ``"exact": false``,
        "not judged", so that no accuracy verdict is drawn against the folder.
    sms_split : with specular manifold sampling, render the sampled solutions' light in a pass of its own with
        one sample per ``sms_split`` of the rest (:class:`.jobs.RenderSetup`); None or 1 renders one pass.

    Returns the dict written to ``reference.json``.
    """
    setup = RenderSetup(scene, variant=variant, threads=threads, extra_emitters=extra_emitters, sms_split=sms_split)
    if client is None:
        executor = SerialExecutor()
        plan = ReferencePlan(setup, out_dir, spp=spp, K=K, target_rel_se=target_rel_se, max_seconds=max_seconds,
                             max_spp_per_seed=max_spp_per_seed, seed_base=seed_base, progress=progress, steps=steps,
                             judge_exactness=judge_exactness)
        return executor.run(plan)
    from harness.reference.distributed import DaskDriver

    driver = DaskDriver(client, variant=variant)
    plan = ReferencePlan(setup, out_dir, spp=spp, K=K, target_rel_se=target_rel_se, max_seconds=max_seconds,
                         max_spp_per_seed=max_spp_per_seed, seed_base=seed_base, progress=progress,
                         slots=driver.slots, executor=driver.name, steps=steps, judge_exactness=judge_exactness)
    return driver.run([plan])[0]
