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
Heavy tails (rough dielectric boundaries) make a short pilot optimistic, so when
all planned samples are in and the target is still missed, every seed is topped up
(new Mitsuba seeds) from a new prediction, at most three times. The figure written
to ``reference.json`` is the one *measured* on the final render (``target_met``
says whether it meets the target; ``capped_by`` names a cap that stopped it).

Scheduling. The work is a set of independent *jobs*, one ``mi.render`` call
each: a pass, a seed, the seed's chunk index and a sample count
(:class:`Job`). :func:`render_job` is the unit a worker runs (it builds each
pass's Mitsuba scene once per process and keeps it); :class:`ReferencePlan`
decides the jobs round by round (pilot, the steps of the final render, top-ups)
and merges what comes back; an executor runs the rounds: :class:`SerialExecutor`
in this process, or :class:`harness.reference.distributed.DaskDriver` on a Dask
cluster. A job's result is its image times its sample count (float64); per (pass,
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

import collections
import dataclasses
import hashlib
import json
import math
import os
import time
from pathlib import Path

import numpy as np

from harness.io.atomic import atomic_dir
from harness.errors import InputError
from harness.io.images import auto_exposure, write_exr, write_png
from harness.metrics.coverage import FULL_COVERAGE
from harness.progress import Progress, format_duration

from . import mitsuba_scene as ms

DEFAULT_K = 8
PILOT_K = 4
PILOT_SPP = 16
PILOT_EARLY_SPP = 4          # the pilot's first round: its prediction corrects the cost model's early
STEPS = 4                    # the final render is rendered (and its noise measured) in at most this many steps,
STEP_MIN_SPP = 32            # ... one per this many samples per seed (sample counts only: see the docstring)
MAX_TOPUPS = 3
MAX_SPP_PER_SEED = 4096
MAX_LANES = 1 << 22          # samples in flight per mi.render call (memory bound)
LIT_FRACTION = 0.01          # lit: brighter than this fraction of the 99th percentile
SEED_STRIDE = 1 << 16        # separates the seed ranges of pilot/full/absorber passes
CHUNK_SEEDS = 4096           # Mitsuba seed = seed * CHUNK_SEEDS + chunk index (< 2**32)
REFERENCE_FILES = ("full.exr", "subsurface.exr", "half_a.exr", "half_b.exr", "mask.exr", "preview.png",
                   "reference.json")

RENDER_COUNT = 0             # how many times a reference was rendered (tests check the cache with it)


# --------------------------------------------------------------------------- statistics

def unit_cost(jobs, overhead=0.0):
    """Seconds per sample of one (pass, seed) unit from a round's ``jobs`` ``[(pass, spp, seconds)]``.

    Per pass, the lower quartile of its jobs' seconds (scaled to the round's median sample count):
    a job that compiled a kernel is a slow outlier. The passes' figures are averaged (a grey pass per
    colour channel costs what its channel's sigma_t makes it cost), and ``overhead`` seconds per job
    (at most half a job's time) are not counted as samples.
    """
    spp = float(np.median([n for _, n, _ in jobs]))
    t = float(np.mean([np.percentile([sec / n * spp for q, n, sec in jobs if q == p], 25)
                       for p in sorted({q for q, _, _ in jobs})]))
    return (t - min(overhead, 0.5 * t)) / spp


def seed_stats(stack):
    """Mean and standard error over the first axis (independent seeds): ``std(ddof=1)/sqrt(K)``."""
    stack = np.asarray(stack, dtype=np.float64)
    k = stack.shape[0]
    mean = stack.mean(axis=0)
    se = stack.std(axis=0, ddof=1) / math.sqrt(k) if k > 1 else np.full_like(mean, np.inf)
    return mean, se


def lit_mask(mean, coverage):
    """(H, W, 3) bool: fully covered pixels whose channel exceeds 1 % of its 99th percentile."""
    covered = coverage >= FULL_COVERAGE
    out = np.zeros(mean.shape, dtype=bool)
    if not covered.any():
        return out
    for c in range(mean.shape[2]):
        vals = mean[..., c][covered]
        thr = LIT_FRACTION * np.percentile(vals, 99.0)
        out[..., c] = covered & (mean[..., c] > max(thr, 0.0))
    return out


def median_rel_se(mean, se, lit):
    """Median of se/mean over the lit (pixel, channel) pairs (NaN when nothing is lit)."""
    if not lit.any():
        return float("nan")
    return float(np.median(se[lit] / mean[lit]))


def se_median_factor(k):
    """Median of the estimated SE over its true value for ``k`` seeds: sqrt(median(chi2_{k-1}) / (k-1)).

    A median of per-pixel SE estimates from few seeds is biased low by this factor
    (0.89 for 4 seeds, 0.95 for 8); the pilot corrects for it when it predicts.
    """
    from scipy.stats import chi2

    return math.sqrt(chi2.median(k - 1) / (k - 1))


# --------------------------------------------------------------------------- the unit of work

@dataclasses.dataclass(frozen=True)
class PassSpec:
    """One Mitsuba scene of a reference: ``full`` or ``absorber`` (albedo 0), RGB or one grey channel."""

    kind: str                  # "full" | "absorber"
    channel: int = None        # None: one RGB pass; c: the grey pass of channel c

    @property
    def name(self):
        return self.kind if self.channel is None else f"{self.kind}_{'rgb'[self.channel]}"


@dataclasses.dataclass
class RenderSetup:
    """What a worker needs to build a reference's Mitsuba scenes (shipped once per worker)."""

    scene: object              # harness.scene.Scene
    variant: str = None
    threads: int = None        # Dr.Jit threads per render (None: Dr.Jit's default, one per core)
    extra_emitters: dict = None

    def __post_init__(self):
        extra = json.dumps(self.extra_emitters, sort_keys=True, default=repr) if self.extra_emitters else ""
        digest = hashlib.sha256(extra.encode()).hexdigest()[:8]
        self.key = f"{self.scene.content_hash[:16]}-{self.variant}-{self.threads}-{digest}"

    def passes(self):
        kinds = ["full"]
        if self.extra_emitters or ms.absorber_is_black(self.scene) is None:
            kinds.append("absorber")
        return [PassSpec(k, c) for k in kinds for c in ms.channel_passes(self.scene.medium)]


@dataclasses.dataclass(frozen=True)
class Job:
    """One ``mi.render`` call: ``spp`` samples of seed ``seed``'s chunk ``chunk`` in one pass."""

    pass_name: str
    seed: int
    chunk: int
    spp: int

    @property
    def mitsuba_seed(self):
        # Chunk j of seed s uses Mitsuba seed s * CHUNK_SEEDS + j: distinct across seeds and chunks.
        return int(self.seed) * CHUNK_SEEDS + int(self.chunk)


_LOADED = collections.OrderedDict()      # (setup key, pass name) -> mi.Scene, in this process
_LOADED_MAX = 8


def _mitsuba_scene(mi, setup, spec):
    key = (setup.key, spec.name)
    if key not in _LOADED:
        albedo = 0.0 if spec.kind == "absorber" else None
        d = ms.build_scene_dict(setup.scene, albedo_override=albedo, extra_emitters=setup.extra_emitters,
                                channel=spec.channel)
        _LOADED[key] = mi.load_dict(d)
        while len(_LOADED) > _LOADED_MAX:
            _LOADED.popitem(last=False)
    _LOADED.move_to_end(key)
    return _LOADED[key]


def render_job(setup, job):
    """Render one :class:`Job` of ``setup`` here; returns ``{"sum": image * spp (float64), "spp", "seconds", "worker"}``.

    The per-seed unit that both the serial renderer and a Dask worker run. Each pass's
    Mitsuba scene is built on first use in this process and kept.
    """
    mi = ms.use_variant(setup.variant)
    threads = _use_threads(setup.threads)
    spec = {p.name: p for p in setup.passes()}[job.pass_name]
    scene = _mitsuba_scene(mi, setup, spec)
    _fault_injection(job)
    t0, c0 = time.perf_counter(), time.process_time()
    img = np.asarray(mi.render(scene, seed=job.mitsuba_seed, spp=int(job.spp)), dtype=np.float64)
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    return {"sum": img * job.spp, "spp": int(job.spp), "seconds": seconds, "cpu_seconds": cpu, "threads": threads,
            "worker": f"{os.uname().nodename}:{os.getpid()}"}


_DEFAULT_THREADS = None


def _use_threads(threads):
    """Set Dr.Jit's thread count for this render (``None``: its default, as found at the first call here)."""
    global _DEFAULT_THREADS
    import drjit as dr

    if _DEFAULT_THREADS is None:
        _DEFAULT_THREADS = dr.thread_count()
    want = int(threads) if threads else _DEFAULT_THREADS
    if dr.thread_count() != want:
        dr.set_thread_count(want)
    return want


def _fault_injection(job):
    """Test hook: ``SSLPV_REFERENCE_DIE_ONCE=PASS:SEED:CHUNK:MARKER`` kills the Dask worker
    process that first runs that job (``MARKER`` is a file made on the way out), as a crash would.
    Nothing happens outside a Dask worker."""
    spec = os.environ.get("SSLPV_REFERENCE_DIE_ONCE")
    if not spec:
        return
    p, s, c, marker = spec.split(":", 3)
    if (p, int(s), int(c)) != (job.pass_name, job.seed, job.chunk) or os.path.exists(marker):
        return
    try:
        from distributed import get_worker

        get_worker()
    except (ImportError, ValueError):
        return
    Path(marker).write_text(str(os.getpid()))
    os._exit(1)


# --------------------------------------------------------------------------- accumulation

class _Estimate:
    """Per-(pass, seed) sums and counts over one seed set; results are added in chunk order."""

    def __init__(self, passes, seeds):
        self.passes, self.seeds = list(passes), list(seeds)
        self.sums = {(p.name, self.seed_of(p, s)): 0.0 for p in self.passes for s in self.seeds}
        self.counts = {k: 0 for k in self.sums}
        self.next_chunk = {k: 0 for k in self.sums}     # next chunk to merge
        self.planned = {k: 0 for k in self.sums}        # next chunk index to hand out
        self.pending = {}                                # (pass, seed, chunk) -> result, out of order
        self.spp = 0                                     # spp per seed once the current round is in

    @staticmethod
    def seed_of(spec, seed):
        """The seed a pass renders for logical seed ``seed``: absorber passes use disjoint seeds, so
        that the full and absorber images are independent and their standard errors add in quadrature."""
        return seed + (2 * SEED_STRIDE if spec.kind == "absorber" else 0)

    def jobs(self, spp, chunk_spp):
        """Jobs that add ``spp`` samples to every (pass, seed), in chunks of <= ``chunk_spp``."""
        out = []
        for s0 in self.seeds:
            for p in self.passes:
                s = self.seed_of(p, s0)
                done = 0
                while done < spp:
                    n = min(chunk_spp, spp - done)
                    k = (p.name, s)
                    j = self.planned[k]
                    if j >= CHUNK_SEEDS or not 0 <= s * CHUNK_SEEDS + j < 2 ** 32:
                        raise InputError("render_reference", "seed_base", f"seed {s} (chunk {j}) leaves Mitsuba's "
                                         "32-bit seed range", "use a smaller seed_base or fewer spp")
                    self.planned[k] = j + 1
                    out.append(Job(p.name, s, j, n))
                    done += n
        return out

    def merge(self, job, result):
        """Add a job's result; results of one (pass, seed) are added in chunk order, each exactly once."""
        k = (job.pass_name, job.seed)
        if job.chunk < self.next_chunk[k] or (job.pass_name, job.seed, job.chunk) in self.pending:
            return False                                 # already merged: a re-run of a lost job
        self.pending[(job.pass_name, job.seed, job.chunk)] = result
        while (job.pass_name, job.seed, self.next_chunk[k]) in self.pending:
            r = self.pending.pop((job.pass_name, job.seed, self.next_chunk[k]))
            self.sums[k] = self.sums[k] + r["sum"]
            self.counts[k] += r["spp"]
            self.next_chunk[k] += 1
        return True

    def snapshot(self):
        return (dict(self.sums), dict(self.counts), dict(self.next_chunk), dict(self.planned), self.spp)

    def restore(self, snap):
        self.sums, self.counts, self.next_chunk, self.planned, self.spp = (dict(snap[0]), dict(snap[1]),
                                                                           dict(snap[2]), dict(snap[3]), snap[4])
        self.pending = {}

    def samples_done(self):
        """Samples per pixel merged so far, summed over seeds (mean over passes)."""
        return sum(self.counts.values()) / max(len(self.passes), 1)

    def stack(self, kind):
        """Per-seed mean images of ``kind`` (``full`` or ``absorber``), (K, H, W, 3); None without that pass."""
        specs = [p for p in self.passes if p.kind == kind]
        if not specs:
            return None
        out = []
        for s0 in self.seeds:
            s = self.seed_of(specs[0], s0)
            if specs[0].channel is None:
                out.append(self.sums[(specs[0].name, s)] / self.counts[(specs[0].name, s)])
            else:
                chans = [self.sums[(p.name, s)][..., p.channel] / self.counts[(p.name, s)] for p in specs]
                out.append(np.stack(chans, axis=-1))
        return np.stack(out)

    def images(self):
        """(full mean, full se, absorber mean|None, absorber se|None, subsurface mean, subsurface se)."""
        f, a = self.stack("full"), self.stack("absorber")
        fm, fse = seed_stats(f)
        if a is None:
            return fm, fse, None, None, fm, fse
        am, ase = seed_stats(a)
        return fm, fse, am, ase, fm - am, np.sqrt(fse ** 2 + ase ** 2)


# --------------------------------------------------------------------------- the plan

class ReferencePlan:
    """The rounds of one reference render and the merge of their results (executor-agnostic).

    ``start()`` returns the first round's jobs; each job's result goes to ``merge(job, result)``;
    when a round is complete (``round_complete()``), ``next_jobs()`` returns the next round or
    ``None``; ``finish()`` writes the folder and returns its metadata. ``abort_round()`` rolls a
    round back at the time cap. ``slots`` is how many jobs the executor runs at once (its
    prediction of wall time uses it).
    """

    def __init__(self, setup, out_dir, spp=None, K=None, target_rel_se=0.05, max_seconds=None,
                 max_spp_per_seed=MAX_SPP_PER_SEED, seed_base=0, progress=True, slots=1, executor="serial",
                 steps=None):
        K = DEFAULT_K if K is None else int(K)
        if K < 2:
            raise InputError("render_reference", "K", f"must be at least 2 to estimate noise, got {K}", "use K >= 2")
        if spp is not None and int(spp) < 1:
            raise InputError("render_reference", "spp", f"must be a positive integer, got {spp}", "use spp >= 1")
        if not (target_rel_se and target_rel_se > 0):
            raise InputError("render_reference", "target_rel_se", f"must be > 0, got {target_rel_se}", "use e.g. 0.05")
        check_max_seconds(max_seconds, "render_reference", "max_seconds")
        self.setup, self.out_dir = setup, Path(out_dir)
        self.scene = setup.scene
        self.K, self.spp_fixed, self.target = K, (None if spp is None else int(spp)), float(target_rel_se)
        self.max_seconds, self.max_spp_per_seed = max_seconds, int(max_spp_per_seed)
        self.seed_base, self.slots, self.executor = int(seed_base), max(1, int(slots)), executor
        self.steps = None if steps is None else max(1, int(steps))
        self.passes = setup.passes()
        cam = self.scene.camera
        self.chunk_spp = max(1, MAX_LANES // (cam.width * cam.height))
        self.final = _Estimate(self.passes, [self.seed_base + i for i in range(K)])
        self.pilot_est = None
        self.progress_enabled = progress
        self.progress = None
        self._outstanding = 0
        self._snapshot = None
        self._abortable = False
        self.aborted = False
        self.capped_by = None
        self.rounds, self.pilot = [], None
        self.cost = None                   # seconds per spp of one (pass, seed) unit, measured
        self.job_overhead = 0.0            # seconds per job (mi.render call) besides its samples (cost model)
        self.job_seconds, self.jobs_run, self.reruns, self.jobs_rolled_back = 0.0, 0, 0, 0
        self.job_cpu_seconds = 0.0
        self.workers = set()
        self.threads_seen = set()
        self._t_final = None               # when the final render started (progress rate)
        self._gen = None

    # ----------------------------------------------------------------- executor interface

    def start(self):
        global RENDER_COUNT
        RENDER_COUNT += 1
        self.t_start = time.perf_counter()
        self.deadline = None if self.max_seconds is None else self.t_start + float(self.max_seconds)
        ms.use_variant(self.setup.variant)
        self.coverage = ms.coverage_mask(self.scene)
        self.progress = Progress(f"reference {self.scene.name}", total=None, unit="spp (all seeds)",
                                 enabled=bool(self.progress_enabled), every_s=10.0)
        self.progress.__enter__()
        self._gen = self._rounds()
        return self.next_jobs()

    def next_jobs(self):
        """The next round's jobs (the previous one complete), or None when the render is done."""
        try:
            est, jobs = next(self._gen)
        except StopIteration:
            return None
        self._round_est = est
        self._snapshot = est.snapshot()
        self._outstanding = len(jobs)
        self._round_spp = {}
        return jobs

    def merge(self, job, result):
        if not self._round_est.merge(job, result):
            self.reruns += 1
            return
        self._outstanding -= 1
        self.job_seconds += result["seconds"]
        self.job_cpu_seconds += result.get("cpu_seconds", 0.0)
        self.jobs_run += 1
        self.workers.add(result.get("worker"))
        self.threads_seen.add(result.get("threads"))
        self._round_spp.setdefault("spp", 0)
        self._round_spp["spp"] += result["spp"]
        self._round_spp["seconds"] = self._round_spp.get("seconds", 0.0) + result["seconds"]
        self._round_spp["jobs"] = self._round_spp.get("jobs", 0) + 1
        self._round_spp.setdefault("each", []).append((job.pass_name, result["spp"], result["seconds"]))
        if self._round_est is self.final:
            self._show()

    def round_complete(self):
        return self._outstanding == 0

    def abortable(self):
        """Whether the running round may be abandoned at the time cap (not the pilot, not the first step)."""
        return self._abortable

    def past_deadline(self):
        return self.deadline is not None and time.perf_counter() >= self.deadline

    def seconds_left(self):
        return None if self.deadline is None else self.deadline - time.perf_counter()

    def abort_round(self):
        """Roll the running round back (time cap): every seed keeps its previous sample count."""
        self._round_est.restore(self._snapshot)
        self._outstanding = 0
        self.jobs_rolled_back += self._round_spp.get("jobs", 0)
        self.aborted = True
        self.capped_by = "max_seconds"
        self.progress.log(f"time cap of {format_duration(self.max_seconds)} reached: the running step was "
                          "abandoned; writing what the completed steps reached")

    # ----------------------------------------------------------------- the rounds

    def _noise(self, est):
        *_, sm, sse = est.images()
        return median_rel_se(sm, sse, lit_mask(sm, self.coverage))

    def _measure_cost(self):
        """Seconds per sample from the round just rendered: a job's time is ``overhead + spp x cost``.

        The overhead per job (kernel launch, readback) is the cost model's ``c_job``: two pilot
        rounds at 4 and 12 samples per job time it too noisily on a small image (jobs of 10 to
        30 ms). Jobs that compiled a kernel (the first of a process at each new sample count)
        are slow outliers, so each pass counts the lower quartile of its jobs' times; the passes
        (one per colour channel where sigma_t differs between channels) cost differently, and a
        unit's cost is their mean.
        """
        each = self._round_spp.get("each")
        if each:
            self.cost = unit_cost(each, self.job_overhead)

    def _round_wall(self, spp):
        """Predicted wall seconds to add ``spp`` samples to every (pass, seed) of the final estimate."""
        if self.cost is None or spp <= 0:
            return 0.0
        units = len(self.passes) * self.K
        chunks = math.ceil(spp / self.chunk_spp)
        overhead = min(self.job_overhead, spp / chunks * self.cost)
        return math.ceil(units * chunks / self.slots) * (overhead + spp / chunks * self.cost)

    def _spp_for(self, r_now, n_now, k_now):
        """spp per final seed predicted to reach the target (SE ~ 1/sqrt(N); median-of-SE bias corrected)."""
        n_total = n_now * (r_now * se_median_factor(self.K) / (se_median_factor(k_now) * self.target)) ** 2
        want = max(1, math.ceil(n_total / self.K))
        if want > self.max_spp_per_seed:
            return self.max_spp_per_seed, "max_spp_per_seed"
        return want, None

    def _fit_deadline(self, step):
        """``step`` shrunk so that its predicted wall time ends before the cap (None: no time left)."""
        left = self.seconds_left()
        if left is None or self._round_wall(step) <= left:
            return step
        per = self._round_wall(1)
        fit = int(left / per) if per > 0 else step
        # Chunks make the wall time a step function of spp: step down until it fits.
        while fit > 0 and self._round_wall(fit) > left:
            fit -= 1
        self.capped_by = "max_seconds"
        return fit if fit >= 1 else None

    def _rounds(self):
        final, K = self.final, self.K
        want, capped = self.spp_fixed, None
        if want is None:
            pilot = _Estimate(self.passes, [self.seed_base + SEED_STRIDE + i for i in range(PILOT_K)])
            self.pilot_est = pilot
            model = self._cost_model_seconds()
            self.progress.log((f"the cost model predicts {format_duration(model)} for the final render, before "
                               "rendering" if model else "the cost model cannot predict this scene") +
                              "; the pilot corrects it after its first round")
            self.progress.log(f"pilot: {PILOT_K} seeds x {PILOT_SPP} spp in two rounds ({PILOT_EARLY_SPP}, then "
                              f"{PILOT_SPP - PILOT_EARLY_SPP}; {len(self.passes)} pass"
                              f"{'es' if len(self.passes) > 1 else ''}, {self.executor})")
            self.pilot = {"K": PILOT_K, "spp": PILOT_SPP, "cost_model_seconds": model}
            self.job_overhead = self._cost_model_job_seconds()
            yield pilot, pilot.jobs(PILOT_EARLY_SPP, self.chunk_spp)
            self._measure_cost()
            r_e, want_e, capped_e = self._pilot_predict(pilot, PILOT_EARLY_SPP)
            seconds = self._round_spp.get("seconds", 0.0)
            self.pilot["early"] = {"spp": PILOT_EARLY_SPP, "median_rel_se_subsurface": r_e,
                                   "first_spp_per_seed": want_e, "predicted_wall_seconds": self._round_wall(want_e),
                                   "elapsed_seconds": time.perf_counter() - self.t_start}
            self.progress.log(self._prediction_line(r_e, want_e, capped_e, early=True))
            yield pilot, pilot.jobs(PILOT_SPP - PILOT_EARLY_SPP, self.chunk_spp)
            self._measure_cost()
            r_p, want, capped = self._pilot_predict(pilot, PILOT_SPP)
            self.pilot.update({"median_rel_se_subsurface": r_p,
                               "seconds": seconds + self._round_spp.get("seconds", 0.0), "first_spp_per_seed": want,
                               "predicted_wall_seconds": self._round_wall(want),
                               "job_overhead_seconds": self.job_overhead, "seconds_per_spp": self.cost,
                               "elapsed_seconds": time.perf_counter() - self.t_start})
            self.progress.log(self._prediction_line(r_p, want, capped))
        n_steps = self.steps or (1 if self.spp_fixed is not None else min(STEPS, max(1, want // STEP_MIN_SPP)))
        step_size = max(1, math.ceil(want / n_steps))
        topups, r = 0, float("nan")
        self.progress.update(done=0, total=K * want)
        self._t_final = time.perf_counter()
        while True:
            step = min(step_size, want - final.spp)
            if self.deadline is not None:
                fit = self._fit_deadline(step)
                if fit is None and final.spp > 0:
                    break
                step = fit or 1             # the first step always renders (at least 1 spp per seed)
            self._abortable = final.spp > 0
            jobs = final.jobs(step, self.chunk_spp)
            yield final, jobs
            if self.aborted:
                break
            final.spp += step
            self._measure_cost()
            r = self._noise(final)
            self.rounds.append({"spp_per_seed": final.spp, "median_rel_se_subsurface": r,
                                "seconds": time.perf_counter() - self.t_start})
            self._show(r)
            if self.spp_fixed is not None:
                if final.spp >= want:
                    break
                continue
            if np.isfinite(r) and r <= self.target:
                break
            if self.capped_by == "max_seconds" and self._fit_deadline(1) is None:
                break
            if final.spp >= want:
                if capped or topups >= MAX_TOPUPS or not np.isfinite(r):
                    break
                new, capped = self._spp_for(r, final.spp * K, K)
                if not capped:  # aim 10 % past the prediction so that one top-up usually suffices
                    new = min(math.ceil(1.1 * new), self.max_spp_per_seed)
                if new <= final.spp:
                    break
                topups += 1
                self.progress.log(f"measured {r:.2%} at {final.spp} spp per seed, target {self.target:.2%}: "
                                  f"top-up {topups} to {new} spp per seed")
                want = new
                self.progress.update(total=K * want)
        self.capped_by = self.capped_by or capped

    @staticmethod
    def _cost_model_job_seconds():
        """The cost model's seconds per job besides its samples (0 where it has none)."""
        from harness.reference.cost import load_model

        try:
            return float(load_model()["time"]["c_job"])
        except (OSError, KeyError, ValueError, TypeError, InputError):
            return 0.0

    def _cost_model_seconds(self):
        """What the cost model (``reference --estimate``, :func:`harness.reference.cost.estimate_reference`)
        predicts, before any rendering, for the final render's samples on the cores at hand; None where it
        cannot predict (the pilot's prediction is compared with it in the log)."""
        from harness.reference.cost import estimate_reference

        try:
            est = estimate_reference(self.scene, self.target, workers=None if self.executor == "serial" else
                                     self.slots, coverage=self.coverage)
        except (ValueError, KeyError, OSError, InputError):
            return None
        return float(est["predicted_spp_total"] * est["seconds_per_spp"])

    def _pilot_predict(self, pilot, spp):
        """``(noise, spp per final seed, cap)`` predicted from the pilot's ``spp`` samples per seed so far."""
        r = self._noise(pilot)
        if np.isfinite(r) and r > 0:
            return (r, *self._spp_for(r, PILOT_K * spp, PILOT_K))
        return r, PILOT_SPP, None

    def _prediction_line(self, r_p, want, capped, early=False):
        where = ("in this process" if self.executor == "serial" else
                 f"on {self.executor} ({self.slots} job{'s' if self.slots > 1 else ''} at a time)")
        wall = self._round_wall(want)
        head = (f"pilot, first round ({PILOT_EARLY_SPP} of {PILOT_SPP} spp per seed, "
                f"{format_duration(time.perf_counter() - self.t_start)} after the start)" if early else "pilot")
        line = (f"{head} measured {r_p:.2%} median relative SE; predicted {self.K} seeds x {want} spp "
                f"({self.K * want} in all) to reach {self.target:.2%}, about {format_duration(wall)} {where}")
        model = (self.pilot or {}).get("cost_model_seconds")
        if model:
            # The cost model never saw this scene's render; the pilot has. Its prediction replaces the model's.
            line += (f"; the cost model predicted {format_duration(model)} before rendering: the pilot's "
                     f"prediction replaces it (x{wall / model:.2f})")
        if capped:
            line += f" (capped by {capped})"
        if self.deadline is not None and wall > self.seconds_left():
            line += f"; the time cap ({format_duration(self.max_seconds)}) will stop it first"
        return line

    def _show(self, r=None):
        """Progress toward the target: samples merged, the last measured noise, and the ETA.

        The samples still to render come from the noise (the pilot's prediction, or a top-up's);
        their time from the wall-clock rate of the final render so far (before its first job,
        from the pilot's seconds per sample and the parallel slots)."""
        if self.progress is None:
            return
        done = self.final.samples_done()
        total = self.progress.total or done
        left = max(total - done, 0)
        if self._t_final is None:
            self._t_final = time.perf_counter()
        if done > 0:
            eta = (time.perf_counter() - self._t_final) / done * left
        else:
            eta = self._round_wall(math.ceil(left / self.K)) if self.cost is not None else None
        if r is None:
            r = self.rounds[-1]["median_rel_se_subsurface"] if self.rounds else None
        detail = (f"median rel. SE {r:.2%} (target {self.target:.2%})" if r is not None and np.isfinite(r)
                  else f"target {self.target:.2%}")
        self.progress.update(done=int(done), detail=detail, eta_s=eta)

    # ----------------------------------------------------------------- result

    def finish(self):
        """Write the reference folder (atomically) and return its metadata."""
        final, K = self.final, self.K
        f, a = final.stack("full"), final.stack("absorber")
        fm, fse, am, ase, sm, sse = final.images()
        half = K // 2
        half_a = f[:half].mean(0) - (a[:half].mean(0) if a is not None else 0.0)
        half_b = f[half:].mean(0) - (a[half:].mean(0) if a is not None else 0.0)
        r_sub = median_rel_se(sm, sse, lit_mask(sm, self.coverage))
        r_full = median_rel_se(fm, fse, lit_mask(fm, self.coverage))
        absorber = a is not None
        import mitsuba

        meta = {
            "scene": self.scene.name,
            "content_hash": self.scene.content_hash,
            "width": int(self.scene.camera.width),
            "height": int(self.scene.camera.height),
            "mitsuba_version": mitsuba.__version__,
            "variant": ms.use_variant(self.setup.variant).variant(),
            "threads": self.setup.threads,
            "drjit_threads": sorted(t for t in self.threads_seen if t),
            "K": K,
            "spp_per_seed": final.spp,
            "spp_total": final.spp * K,
            "seeds": final.seeds,
            "seeds_absorber": [s + 2 * SEED_STRIDE for s in final.seeds] if absorber else [],
            "passes": [p.name for p in self.passes],
            "seed_note": (f"mi.render seed = seed * {CHUNK_SEEDS} + chunk index (chunks of <= {MAX_LANES} samples "
                          f"in flight); pilot seeds start at seed_base + {SEED_STRIDE}, absorber seeds at "
                          f"seed_base + {2 * SEED_STRIDE}; a grey pass per channel uses its kind's seeds"),
            "absorber_pass": ("rendered" if absorber else
                              f"skipped: exactly zero ({ms.absorber_is_black(self.scene)})"),
            "target_rel_se": self.target,
            "median_rel_se_full": r_full,
            "median_rel_se_subsurface": r_sub,
            "noise_note": ("measured on the final render: median of se/mean over lit (pixel, channel) pairs; lit = "
                           f"coverage >= {FULL_COVERAGE} and value > {LIT_FRACTION} x the channel's 99th percentile"),
            "lit_pixels": int(lit_mask(sm, self.coverage).any(axis=2).sum()),
            "covered_pixels": int((self.coverage >= FULL_COVERAGE).sum()),
            "render_seconds": self.job_seconds,       # the jobs' own render time, summed (all workers)
            "render_cpu_seconds": self.job_cpu_seconds,   # the CPU time of their processes, summed
            "wall_seconds": None,
            "executor": self.executor,
            "slots": self.slots,
            "jobs": self.jobs_run,
            "jobs_rolled_back": self.jobs_rolled_back,
            "jobs_rerun_ignored": self.reruns,
            "workers": sorted(w for w in self.workers if w),
            "pilot": self.pilot,
            "rounds": self.rounds,
            "max_seconds": self.max_seconds,
            "capped_by": self.capped_by,
            "target_met": bool(np.isfinite(r_sub) and r_sub <= self.target),
            "files": list(REFERENCE_FILES) + (["absorber.exr"] if absorber else []),
            **ms.scene_notes(self.scene),
        }
        if ms.smooth_dielectric(self.scene.boundary) and not self.setup.extra_emitters:
            # What the manifold connections leave out, measured (harness.reference.losses); a reference
            # whose lost light exceeds its share of the noise target says so and is not judged against.
            from harness.reference import losses

            found = losses.measure(self.scene, self.setup.variant)
            exact, note = losses.verdict(found, self.target)
            meta.update(mnee_losses=found, exact=exact, exact_note=note)
        with atomic_dir(self.out_dir) as tmp:
            write_exr(tmp / "full.exr", fm, fse)
            write_exr(tmp / "subsurface.exr", sm, sse)
            if absorber:
                write_exr(tmp / "absorber.exr", am, ase)
            write_exr(tmp / "half_a.exr", half_a)
            write_exr(tmp / "half_b.exr", half_b)
            write_exr(tmp / "mask.exr", np.repeat(self.coverage[..., None], 3, axis=2))
            write_png(tmp / "preview.png", fm, auto_exposure(fm))
            meta["wall_seconds"] = time.perf_counter() - self.t_start
            meta = _jsonable(meta)
            (tmp / "reference.json").write_text(json.dumps(meta, indent=2, allow_nan=False))
        self.close_progress(f"done: median rel. SE {r_sub:.2%} (target {self.target:.2%}"
                            f"{', met' if meta['target_met'] else ', NOT met'}), {final.spp * K} spp in all, "
                            f"{format_duration(meta['wall_seconds'])}"
                            + (f"; stopped by {self.capped_by}" if self.capped_by else "")
                            + (f"; {meta['exact_note']}" if meta.get("exact") is False else ""))
        return meta

    def close_progress(self, message=None):
        """End the progress display (its last state first), then print ``message`` as a last line."""
        if self.progress is not None:
            self.progress.__exit__(None, None, None)
            if message:
                self.progress.log(message)
            self.progress = None


def check_max_seconds(value, where, field):
    """``None`` or a finite number of seconds > 0; anything else is one line of bad input."""
    if value is None:
        return None
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = float("nan")
    if not (math.isfinite(v) and v > 0):
        raise InputError(where, field, f"must be a finite time > 0, got {value!r}",
                         "give a positive number of minutes, or leave the cap out")
    return v


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
                     client=None, progress=False, steps=None):
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

    Returns the dict written to ``reference.json``.
    """
    setup = RenderSetup(scene, variant=variant, threads=threads, extra_emitters=extra_emitters)
    if client is None:
        executor = SerialExecutor()
        plan = ReferencePlan(setup, out_dir, spp=spp, K=K, target_rel_se=target_rel_se, max_seconds=max_seconds,
                             max_spp_per_seed=max_spp_per_seed, seed_base=seed_base, progress=progress, steps=steps)
        return executor.run(plan)
    from harness.reference.distributed import DaskDriver

    driver = DaskDriver(client, variant=variant)
    plan = ReferencePlan(setup, out_dir, spp=spp, K=K, target_rel_se=target_rel_se, max_seconds=max_seconds,
                         max_spp_per_seed=max_spp_per_seed, seed_base=seed_base, progress=progress,
                         slots=driver.slots, executor=driver.name, steps=steps)
    return driver.run([plan])[0]


def _jsonable(x):
    """numpy scalars -> Python; NaN/Inf -> None (strict JSON)."""
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, np.integer)):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x
