"""The unit of work of a reference render: a reference's passes, its jobs, and their per-seed sums.

A job (:class:`Job`) is one ``mi.render`` call: a pass (``full`` or ``absorber``, RGB or
one grey channel, :class:`PassSpec`), a seed, the seed's chunk index and a sample count.
:func:`render_job` is the unit a worker runs, serial or on Dask (it builds each pass's
Mitsuba scene once per process and keeps it). Chunk ``j`` of seed ``s`` is Mitsuba seed
``s * CHUNK_SEEDS + j``; absorber passes use seeds ``2 * SEED_STRIDE`` above the full
pass's, so the two images are independent. :class:`_Estimate` holds a seed set's sums:
a job's result is its image times its sample count (float64), added per (pass, seed) in
chunk order and exactly once, whoever rendered it and in whatever order it arrived.
"""

import collections
import dataclasses
import hashlib
import json
import os
import time
from pathlib import Path

import numpy as np

from harness.errors import InputError

from . import mitsuba_scene as ms
from .noise import seed_stats

DEFAULT_K = 8
PILOT_K = 4                  # the pilot's seeds ...
PILOT_SPP = 16               # ... and samples per seed, rendered in two rounds:
PILOT_EARLY_SPP = 4          # the first, whose prediction corrects the cost model's early, then the rest
SEED_STRIDE = 1 << 16        # separates the seed ranges of pilot/full/absorber passes
MAX_SMS_SPLIT = 64           # the most samples of the rest per sample of the sampled solutions' pass
DEFAULT_SMS_SPLIT = 8        # ... and the split where none is given and the scene samples (bench_sms_split)
CHUNK_SEEDS = 4096           # Mitsuba seed = seed * CHUNK_SEEDS + chunk index (< 2**32)


# --------------------------------------------------------------------------- the unit of work

@dataclasses.dataclass(frozen=True)
class PassSpec:
    """One Mitsuba scene of a reference: ``full`` or ``absorber`` (albedo 0), RGB or one grey channel, and with
    a split specular manifold sampling (:attr:`RenderSetup.sms_split`) one of the full image's two parts:
    ``rest`` (sampling off) or ``sampled`` (only the sampled solutions' light), whose images add."""

    kind: str                  # "full" | "absorber"
    channel: int = None        # None: one RGB pass; c: the grey pass of channel c
    part: str = None           # None: the whole image; "rest" | "sampled": a part of it

    @property
    def name(self):
        base = self.kind if self.channel is None else f"{self.kind}_{'rgb'[self.channel]}"
        return base if self.part is None else f"{base}_{self.part}"


@dataclasses.dataclass
class RenderSetup:
    """What a worker needs to build a reference's Mitsuba scenes (shipped once per worker)."""

    scene: object              # harness.scene.Scene
    variant: str = None
    threads: int = None        # Dr.Jit threads per render (None: Dr.Jit's default, one per core)
    extra_emitters: dict = None
    #: With specular manifold sampling (``[boundary] sms_trials``): render the sampled solutions' light as a
    #: pass of its own with one sample for every ``sms_split`` of the rest (1: one pass, no split; None:
    #: :data:`DEFAULT_SMS_SPLIT` where the scene samples). Their light is a few per cent of the image and much
    #: of its cost (``docs/benchmarks/bench_sms_split.md``).
    sms_split: int = None

    def __post_init__(self):
        if self.sms_split is not None:
            if not 1 <= int(self.sms_split) <= MAX_SMS_SPLIT:
                raise InputError("render_reference", "sms_split", f"{self.sms_split} is outside "
                                 f"[1, {MAX_SMS_SPLIT}]", "give the rest's samples per sampled one, or none")
            if int(self.sms_split) > 1 and not self.samples_manifolds:
                raise InputError("render_reference", "sms_split", "the scene samples no specular manifolds "
                                 "([boundary] sms_trials is 0 or the boundary is not a smooth dielectric)",
                                 "leave sms_split unset")
        extra = json.dumps(self.extra_emitters, sort_keys=True, default=repr) if self.extra_emitters else ""
        digest = hashlib.sha256(extra.encode()).hexdigest()[:8]
        self.key = f"{self.scene.content_hash[:16]}-{self.variant}-{self.threads}-{digest}"

    @property
    def samples_manifolds(self):
        """Whether the scene's reference samples specular manifolds (a smooth dielectric with ``sms_trials``)."""
        b = self.scene.boundary
        return bool(ms.smooth_dielectric(b) and b.sms_trials)

    @property
    def split(self):
        """The rest's samples per sampled one, or 1 (the full image is one pass)."""
        if self.sms_split is not None:
            return int(self.sms_split)
        return DEFAULT_SMS_SPLIT if self.samples_manifolds else 1

    def passes(self):
        kinds = ["full"]
        if self.extra_emitters or ms.absorber_is_black(self.scene) is None:
            kinds.append("absorber")
        # The absorber (albedo 0) has no medium vertex to sample from: it is never split.
        parts = {"full": ("rest", "sampled") if self.split > 1 else (None,), "absorber": (None,)}
        return [PassSpec(k, c, part) for k in kinds for c in ms.channel_passes(self.scene.medium) for part in parts[k]]


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
                                channel=spec.channel, part=spec.part)
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
    import drjit as dr

    # Dr.Jit's kernel history times each kernel's execution apart from its compilation (a new sample
    # count compiles the render's kernels again): the samples' own cost, which the pilot extrapolates.
    # The flag is set back afterwards, so that the history does not grow through later work in this process.
    history = dr.flag(dr.JitFlag.KernelHistory)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    dr.kernel_history()                                   # reading it empties it
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        img = np.asarray(mi.render(scene, seed=job.mitsuba_seed, spp=int(job.spp)), dtype=np.float64)
        seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
        kernels = sum(float(k.get("execution_time", 0.0)) for k in dr.kernel_history()) / 1000.0   # ms -> s
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, history)
    return {"sum": img * job.spp, "spp": int(job.spp), "seconds": seconds, "cpu_seconds": cpu, "threads": threads,
            "kernel_seconds": kernels if 0.0 < kernels <= seconds * 1.05 else None,
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

    def __init__(self, passes, seeds, split=1):
        self.passes, self.seeds, self.split = list(passes), list(seeds), int(split)
        self.sums = {(p.name, self.seed_of(p, s)): 0.0 for p in self.passes for s in self.seeds}
        self.counts = {k: 0 for k in self.sums}
        self.next_chunk = {k: 0 for k in self.sums}     # next chunk to merge
        self.planned = {k: 0 for k in self.sums}        # next chunk index to hand out
        self.handed_out = 0                              # samples per seed handed out (the rest's)
        self.pending = {}                                # (pass, seed, chunk) -> result, out of order
        self.spp = 0                                     # spp per seed once the current round is in

    @staticmethod
    def seed_of(spec, seed):
        """The seed a pass renders for logical seed ``seed``: absorber passes use disjoint seeds, so
        that the full and absorber images are independent and their standard errors add in quadrature."""
        return seed + (2 * SEED_STRIDE if spec.kind == "absorber" else 0)

    def jobs(self, spp, chunk_spp):
        """Jobs that add ``spp`` samples to every (pass, seed), in chunks of <= ``chunk_spp``; a ``sampled``
        part's pass gets ``ceil(n / split)`` samples once ``n`` have been handed out to the seed (at least one,
        so its ratio to the rest is ``split`` up to the rounding, whatever the rounds)."""
        before, self.handed_out = self.handed_out, self.handed_out + spp
        sampled = -(-self.handed_out // self.split) - -(-before // self.split)
        out = []
        for s0 in self.seeds:
            for p in self.passes:
                s = self.seed_of(p, s0)
                k = (p.name, s)
                want = sampled if p.part == "sampled" else spp
                done = 0
                while done < want:
                    n = min(chunk_spp, want - done)
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
        return (dict(self.sums), dict(self.counts), dict(self.next_chunk), dict(self.planned), self.spp,
                self.handed_out)

    def restore(self, snap):
        self.sums, self.counts, self.next_chunk, self.planned, self.spp, self.handed_out = (
            dict(snap[0]), dict(snap[1]), dict(snap[2]), dict(snap[3]), snap[4], snap[5])
        self.pending = {}

    def samples_done(self):
        """Samples per pixel merged so far, summed over seeds (mean over the passes; a split's ``sampled``
        part, which renders fewer, is not counted)."""
        counted = [p.name for p in self.passes if p.part != "sampled"]
        return sum(v for (name, _), v in self.counts.items() if name in counted) / max(len(counted), 1)

    def stack(self, kind):
        """Per-seed mean images of ``kind`` (``full`` or ``absorber``), (K, H, W, 3); None without that pass.
        A grey pass gives its channel; the parts of a split pass (``rest``, ``sampled``) add."""
        specs = [p for p in self.passes if p.kind == kind]
        if not specs:
            return None
        out = []
        for s0 in self.seeds:
            s = self.seed_of(specs[0], s0)
            img = 0.0
            for p in specs:
                mean = self.sums[(p.name, s)] / self.counts[(p.name, s)]
                if p.channel is not None:
                    mean = np.where(np.arange(3) == p.channel, mean, 0.0)
                img = img + mean
            out.append(np.asarray(img, np.float64))
        return np.stack(out)

    def images(self):
        """(full mean, full se, absorber mean|None, absorber se|None, subsurface mean, subsurface se)."""
        f, a = self.stack("full"), self.stack("absorber")
        fm, fse = seed_stats(f)
        if a is None:
            return fm, fse, None, None, fm, fse
        am, ase = seed_stats(a)
        return fm, fse, am, ase, fm - am, np.sqrt(fse ** 2 + ase ** 2)
