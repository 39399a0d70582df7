"""The plan of one reference render: its rounds (pilot, steps, top-ups), their merge, and the folder it writes.

:class:`ReferencePlan` is executor-agnostic: it hands out the jobs of each round
(:mod:`harness.reference.jobs`) and merges what comes back. A pilot (``PILOT_K`` seeds at
``PILOT_SPP``, in two rounds: ``PILOT_EARLY_SPP``, then the rest) measures the median
relative standard error ``r_p`` of the subsurface image over lit pixels at ``N_p`` samples
per pixel (:mod:`harness.reference.noise`), and the total is ``N = N_p (r_p / target)^2``
(SE ~ 1/sqrt(N), corrected by :func:`.noise.se_median_factor`), split over ``K`` seeds and
capped by ``max_spp_per_seed`` and ``max_seconds``. The final render runs in up to ``STEPS``
steps (one per ``STEP_MIN_SPP`` samples per seed: sample counts only, never measured times,
so every executor renders the same image), and at most ``MAX_TOPUPS`` top-ups when the
target is still missed. ``MAX_LANES`` bounds the samples in flight per job. At the time
cap a running step is rolled back. The full account is :mod:`harness.reference.render`'s
docstring.
"""

import json
import math
import time
from pathlib import Path

import numpy as np

from harness.io.atomic import atomic_dir
from harness.errors import InputError
from harness.io.images import auto_exposure, write_exr, write_png
from harness.metrics.coverage import FULL_COVERAGE
from harness.progress import Progress, format_duration

from . import mitsuba_scene as ms
from .cost import tail_factor
from .jobs import CHUNK_SEEDS, DEFAULT_K, PILOT_EARLY_SPP, PILOT_K, PILOT_SPP, SEED_STRIDE, _Estimate
from .noise import LIT_FRACTION, lit_mask, median_rel_se, se_median_factor, unit_cost

STEPS = 4                    # the final render is rendered (and its noise measured) in at most this many steps,
STEP_MIN_SPP = 32            # ... one per this many samples per seed (sample counts only: see the docstring)
MAX_TOPUPS = 3
MAX_SPP_PER_SEED = 4096
MAX_LANES = 1 << 22          # samples in flight per mi.render call (memory bound)
REFERENCE_FILES = ("full.exr", "subsurface.exr", "half_a.exr", "half_b.exr", "mask.exr", "preview.png",
                   "reference.json")

RENDER_COUNT = 0             # how many times a reference was rendered (tests check the cache with it)


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
                 steps=None, judge_exactness=True):
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
        self.judge_exactness = bool(judge_exactness)
        self.passes = setup.passes()
        cam = self.scene.camera
        self.chunk_spp = max(1, MAX_LANES // (cam.width * cam.height))
        self.final = _Estimate(self.passes, [self.seed_base + i for i in range(K)], setup.split)
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
        self._round_spp.setdefault("each", []).append((job.pass_name, result["spp"], result["seconds"],
                                                       result.get("kernel_seconds")))
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
        unit's cost is their mean (:func:`.noise.unit_cost`).
        """
        each = self._round_spp.get("each")
        if each:
            weights = {p.name: 1.0 / self.setup.split for p in self.passes if p.part == "sampled"}
            self.cost = unit_cost(each, self.job_overhead, weights)

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
            pilot = _Estimate(self.passes, [self.seed_base + SEED_STRIDE + i for i in range(PILOT_K)], self.setup.split)
            self.pilot_est = pilot
            model, outside = self._cost_model_seconds()
            self.progress.log((f"the cost model predicts {format_duration(model)} for the final render, before "
                               "rendering" if model else "the cost model cannot predict this scene") +
                              "".join(f" ({o})" for o in outside) + "; the pilot corrects it after its first round")
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
            tail = tail_factor(r_e, r_p, self._cost_model_value("pilot_tail", "exponent"))
            self.pilot.update({"spp_per_seed_from_noise": want, "tail_factor": tail})
            if tail > 1.0 and not capped:
                self.progress.log(f"pilot: the noise fell by x{r_e / r_p:.2f} from {PILOT_EARLY_SPP} to {PILOT_SPP} spp "
                                  f"per seed, x{math.sqrt(PILOT_SPP / PILOT_EARLY_SPP):.0f} expected: heavy tails; "
                                  f"the prediction is raised x{tail:.2f}")
                want = min(math.ceil(want * tail), self.max_spp_per_seed)
                capped = "max_spp_per_seed" if want >= self.max_spp_per_seed else None
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
    def _cost_model_value(*keys):
        """A number of the cost model (``cost_model.json``), 0 where it has none."""
        from harness.reference.cost import load_model

        try:
            v = load_model()
            for k in keys:
                v = v[k]
            return float(v)
        except (OSError, KeyError, ValueError, TypeError, InputError):
            return 0.0

    @classmethod
    def _cost_model_job_seconds(cls):
        """The cost model's seconds per job besides its samples (0 where it has none)."""
        return cls._cost_model_value("time", "c_job")

    def _cost_model_seconds(self):
        """What the cost model (``reference --estimate``, :func:`harness.reference.cost.estimate_reference`)
        predicts, before any rendering, for the final render's samples on the cores at hand (None where it
        cannot predict; the pilot's prediction is compared with it in the log), and what of the render lies
        outside the model's measurements (:func:`harness.reference.cost.outside_the_fit`; with another
        Mitsuba variant than the measured ``llvm_ad_rgb``, that too)."""
        from harness.reference.cost import estimate_reference

        try:
            est = estimate_reference(self.scene, self.target, workers=None if self.executor == "serial" else
                                     self.slots, coverage=self.coverage)
        except (ValueError, KeyError, OSError, InputError):
            return None, []
        variant = self.setup.variant
        outside = list(est.get("outside_the_fit", []))
        if variant and variant != "llvm_ad_rgb":
            outside.append(f"measured with llvm_ad_rgb on CPU cores, rendered with {variant}")
        return float(est["predicted_spp_total"] * est["seconds_per_spp"]), outside

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
            "sms_split": self.setup.split,
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
            if not self.judge_exactness:
                # A caller that only times renders (benchmarks) skips the verdict; the reference then says it
                # is not known to be exact, so no accuracy verdict is drawn against it.
                meta.update(exact=False, exact_note=("not judged: the exactness verdict was skipped "
                                                     "(render_reference(judge_exactness=False))"))
            else:
                # What the manifold connections leave out, measured (harness.reference.losses); a reference
                # whose lost light exceeds its share of the noise target says so and is not judged against.
                from harness.reference import losses

                found = losses.measure(self.scene, self.setup.variant,
                                       limit=losses.LOSS_FRACTION_OF_TARGET * float(self.target))
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
