"""Render a ground-truth reference folder for one scene, with per-pixel noise estimates.

:func:`render_reference` renders the scene (``full``) and, when it can differ
from zero, the same scene with albedo 0 (``absorber``: surface reflection and
unscattered transmission only). ``subsurface = full - absorber``. Each image is
the mean of ``K`` independent renders (distinct ``seed``); the per-pixel
standard error is ``std(ddof=1) / sqrt(K)`` per channel, and
``se_subsurface = sqrt(se_full^2 + se_absorber^2)`` (disjoint seeds).

With an index-matched boundary (``null`` BSDF) or a smooth dielectric one, a black
background and only point lights, the absorber image is exactly zero (no surface
reflection is ever seen: a delta light reflected by a delta interface reaches the
pinhole with probability zero, camera rays that leave the object see black, and a delta
light is never hit), so its pass is skipped and ``subsurface = full``; ``reference.json``
says so (:func:`.mitsuba_scene.absorber_is_black`). The integrator is chosen by
:func:`.mitsuba_scene.integrator_dict` (``mneevolpath`` behind a smooth dielectric).

Choosing the sample count: unless ``spp`` is given, a pilot (4 seeds at
``PILOT_SPP``) measures the median relative standard error ``r_p`` of the
subsurface image over lit pixels at ``N_p`` samples per pixel, and the total is
``N = N_p (r_p / target)^2`` (SE ~ 1/sqrt(N); the low bias of a median of SEs
estimated from few seeds is corrected, :func:`se_median_factor`), split over
``K`` seeds and capped by ``max_spp_per_seed`` and by ``time_budget_s``. Heavy
tails (rough dielectric boundaries) make a short pilot optimistic, so after the
final render the noise is measured again and every seed is topped up with more
samples (new Mitsuba seeds) until the target is met, at most three times. The
figure written to ``reference.json`` is the one *measured* on the final render
(``target_met`` says whether it meets the target).

Noise figure: lit pixels are fully covered by the mesh (coverage >= 0.999) and,
per channel, brighter than 1 % of that channel's 99th percentile over covered
pixels; the figure is the median of ``se / mean`` over the lit (pixel, channel)
pairs.
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

from . import mitsuba_scene as ms

DEFAULT_K = 8
PILOT_K = 4
PILOT_SPP = 16
MAX_SPP_PER_SEED = 4096
MAX_LANES = 1 << 22          # samples in flight per mi.render call (memory bound)
LIT_FRACTION = 0.01          # lit: brighter than this fraction of the 99th percentile
SEED_STRIDE = 1 << 16        # separates the seed ranges of pilot/full/absorber passes
CHUNK_SEEDS = 4096           # Mitsuba seed = seed * CHUNK_SEEDS + chunk index (< 2**32)
REFERENCE_FILES = ("full.exr", "subsurface.exr", "half_a.exr", "half_b.exr", "mask.exr", "preview.png",
                   "reference.json")

RENDER_COUNT = 0             # how many times render_reference rendered (tests check the cache with it)


# --------------------------------------------------------------------------- statistics

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


# --------------------------------------------------------------------------- rendering

def se_median_factor(k):
    """Median of the estimated SE over its true value for ``k`` seeds: sqrt(median(chi2_{k-1}) / (k-1)).

    A median of per-pixel SE estimates from few seeds is biased low by this factor
    (0.89 for 4 seeds, 0.95 for 8); the pilot corrects for it when it predicts.
    """
    from scipy.stats import chi2

    return math.sqrt(chi2.median(k - 1) / (k - 1))


class _Pass:
    """One Mitsuba scene rendered with independent seeds; each seed's estimate can be topped up."""

    def __init__(self, mi, scene_dict, width, height):
        self.mi = mi
        self.scene = mi.load_dict(scene_dict)
        self.pixels = width * height
        self.seconds = 0.0
        self.sums, self.counts, self.chunks = {}, {}, {}

    def add(self, seed, spp):
        """Add ``spp`` samples per pixel to seed ``seed``'s estimate (in calls of <= MAX_LANES samples)."""
        chunk = max(1, MAX_LANES // self.pixels)
        done = 0
        t0 = time.perf_counter()
        while done < spp:
            n = min(chunk, spp - done)
            j = self.chunks.get(seed, 0)
            # Chunk j of seed s uses Mitsuba seed s * CHUNK_SEEDS + j: distinct across seeds and chunks.
            mseed = int(seed) * CHUNK_SEEDS + j
            if j >= CHUNK_SEEDS or not 0 <= mseed < 2 ** 32:
                raise InputError("render_reference", "seed_base", f"seed {seed} (chunk {j}) leaves Mitsuba's "
                                 "32-bit seed range", "use a smaller seed_base or fewer spp")
            img = np.asarray(self.mi.render(self.scene, seed=mseed, spp=n), dtype=np.float64)
            self.sums[seed] = self.sums.get(seed, 0.0) + img * n
            self.counts[seed] = self.counts.get(seed, 0) + n
            self.chunks[seed] = j + 1
            done += n
        self.seconds += time.perf_counter() - t0

    def stack(self, seeds):
        """Per-seed mean images, (len(seeds), H, W, 3)."""
        return np.stack([self.sums[s] / self.counts[s] for s in seeds])


class _Estimate:
    """The full and (optional) absorber passes over their seed sets, with the derived images."""

    def __init__(self, full, absorber, seeds_full, seeds_abs):
        self.full, self.absorber = full, absorber
        self.seeds_full, self.seeds_abs = seeds_full, seeds_abs
        self.spp = 0

    def add(self, spp):
        for s in self.seeds_full:
            self.full.add(s, spp)
        if self.absorber is not None:
            for s in self.seeds_abs:
                self.absorber.add(s, spp)
        self.spp += spp

    @property
    def seconds(self):
        return self.full.seconds + (self.absorber.seconds if self.absorber is not None else 0.0)

    def stacks(self):
        f = self.full.stack(self.seeds_full)
        a = self.absorber.stack(self.seeds_abs) if self.absorber is not None else None
        return f, a

    def images(self):
        """(full mean, full se, absorber mean|None, absorber se|None, subsurface mean, subsurface se)."""
        f, a = self.stacks()
        fm, fse = seed_stats(f)
        if a is None:
            return fm, fse, None, None, fm, fse
        am, ase = seed_stats(a)
        return fm, fse, am, ase, fm - am, np.sqrt(fse ** 2 + ase ** 2)


def render_reference(scene, out_dir, spp=None, K=None, target_rel_se=0.05, variant=None, time_budget_s=None,
                     max_spp_per_seed=MAX_SPP_PER_SEED, seed_base=0, extra_emitters=None):
    """Render the reference folder of ``scene`` into ``out_dir`` (atomically) and return its metadata.

    Parameters
    ----------
    scene : harness.scene.Scene
    out_dir : path; replaced as a whole on success.
    spp : samples per pixel per seed; ``None`` chooses it from a pilot to meet ``target_rel_se``.
    K : number of independent seeds (default 8; at least 2).
    target_rel_se : median relative SE of the subsurface image over lit pixels to aim for.
    variant : ``llvm_ad_rgb`` (default) or ``cuda_ad_rgb``.
    time_budget_s : cap on the (predicted) time of the final render after the pilot, or ``None``.
    max_spp_per_seed : cap on the chosen ``spp``.
    seed_base : first seed; the final render uses ``seed_base + i``, i < K.
    extra_emitters : emitters added to the scene (validation scenes); forces the absorber pass.

    Returns the dict written to ``reference.json``.
    """
    global RENDER_COUNT
    K = DEFAULT_K if K is None else int(K)
    if K < 2:
        raise InputError("render_reference", "K", f"must be at least 2 to estimate noise, got {K}", "use K >= 2")
    if spp is not None and int(spp) < 1:
        raise InputError("render_reference", "spp", f"must be a positive integer, got {spp}", "use spp >= 1")
    if not (target_rel_se and target_rel_se > 0):
        raise InputError("render_reference", "target_rel_se", f"must be > 0, got {target_rel_se}", "use e.g. 0.05")
    t_start = time.perf_counter()
    mi = ms.use_variant(variant)
    RENDER_COUNT += 1
    cam = scene.camera
    full = _Pass(mi, ms.build_scene_dict(scene, extra_emitters=extra_emitters), cam.width, cam.height)
    black_absorber = None if extra_emitters else ms.absorber_is_black(scene)
    absorber_needed = black_absorber is None
    absorber = (_Pass(mi, ms.build_scene_dict(scene, albedo_override=0.0, extra_emitters=extra_emitters),
                      cam.width, cam.height) if absorber_needed else None)
    coverage = ms.coverage_mask(scene)

    seeds_full = [seed_base + i for i in range(K)]
    seeds_abs = [seed_base + 2 * SEED_STRIDE + i for i in range(K)] if absorber else []

    def noise(est):
        *_, sm, sse = est.images()
        return median_rel_se(sm, sse, lit_mask(sm, coverage))

    def spp_for(r_now, n_now, k_now, seconds_now, spent):
        """spp per final seed predicted to reach the target (SE ~ 1/sqrt(N); median-of-SE bias corrected)."""
        n_total = n_now * (r_now * se_median_factor(K) / (se_median_factor(k_now) * target_rel_se)) ** 2
        want = max(1, math.ceil(n_total / K))
        cap, why = max_spp_per_seed, "max_spp_per_seed"
        if time_budget_s is not None:
            per_spp = seconds_now / n_now          # seconds per spp of one seed image (all passes)
            budget_spp = int((time_budget_s - spent) / (per_spp * K)) + final.spp
            if budget_spp < cap:
                cap, why = max(budget_spp, final.spp, 1), "time_budget_s"
        return (want, None) if want <= cap else (cap, why)

    # ---- pilot: a first guess of spp per seed from measured noise
    pilot, capped_by = None, None
    final = _Estimate(full, absorber, seeds_full, seeds_abs)
    rounds = []
    if spp is None:
        pilot_est = _Estimate(full, absorber, [seed_base + SEED_STRIDE + i for i in range(PILOT_K)],
                              [seed_base + 3 * SEED_STRIDE + i for i in range(PILOT_K)])
        pilot_est.add(PILOT_SPP)
        r_pilot = noise(pilot_est)
        n_pilot = PILOT_K * PILOT_SPP
        pilot_seconds = pilot_est.seconds
        if np.isfinite(r_pilot) and r_pilot > 0:
            spp, capped_by = spp_for(r_pilot, n_pilot, PILOT_K, pilot_seconds, 0.0)
        else:
            spp = PILOT_SPP
        pilot = {"K": PILOT_K, "spp": PILOT_SPP, "median_rel_se_subsurface": r_pilot,
                 "seconds": pilot_seconds, "first_spp_per_seed": spp}
        full.seconds = 0.0
        if absorber:
            absorber.seconds = 0.0

    # ---- final render; top up (at most 3 times) while the measured noise misses the target
    final.add(int(spp))
    r_sub = noise(final)
    rounds.append({"spp_per_seed": final.spp, "median_rel_se_subsurface": r_sub, "seconds": final.seconds})
    if pilot is not None:
        for _ in range(3):
            if not (np.isfinite(r_sub) and r_sub > target_rel_se) or capped_by:
                break
            want, capped_by = spp_for(r_sub, final.spp * K, K, final.seconds, final.seconds)
            if not capped_by:  # aim 10 % past the prediction so that one top-up usually suffices
                want = min(math.ceil(1.1 * want), max_spp_per_seed)
            if want <= final.spp:
                break
            final.add(want - final.spp)
            r_sub = noise(final)
            rounds.append({"spp_per_seed": final.spp, "median_rel_se_subsurface": r_sub, "seconds": final.seconds})
    spp = final.spp
    f, a = final.stacks()
    fm, fse, am, ase, sm, sse = final.images()
    half = K // 2
    half_a = f[:half].mean(0) - (a[:half].mean(0) if a is not None else 0.0)
    half_b = f[half:].mean(0) - (a[half:].mean(0) if a is not None else 0.0)
    render_seconds = final.seconds
    r_full = median_rel_se(fm, fse, lit_mask(fm, coverage))

    import mitsuba

    meta = {
        "scene": scene.name,
        "content_hash": scene.content_hash,
        "width": int(cam.width),
        "height": int(cam.height),
        "mitsuba_version": mitsuba.__version__,
        "variant": mi.variant(),
        "K": K,
        "spp_per_seed": spp,
        "spp_total": spp * K,
        "seeds": seeds_full,
        "seeds_absorber": seeds_abs,
        "seed_note": (f"mi.render seed = seed * {CHUNK_SEEDS} + chunk index (chunks of <= {MAX_LANES} samples in flight); "
                      "pilot seeds start at seed_base + %d, absorber seeds at seed_base + %d" % (SEED_STRIDE, 2 * SEED_STRIDE)),
        "absorber_pass": "rendered" if absorber else f"skipped: exactly zero ({black_absorber})",
        "target_rel_se": float(target_rel_se),
        "median_rel_se_full": r_full,
        "median_rel_se_subsurface": r_sub,
        "noise_note": ("measured on the final render: median of se/mean over lit (pixel, channel) pairs; lit = "
                       f"coverage >= {FULL_COVERAGE} and value > {LIT_FRACTION} x the channel's 99th percentile"),
        "lit_pixels": int(lit_mask(sm, coverage).any(axis=2).sum()),
        "covered_pixels": int((coverage >= FULL_COVERAGE).sum()),
        "render_seconds": render_seconds,
        "wall_seconds": None,
        "pilot": pilot,
        "rounds": rounds,
        "capped_by": capped_by,
        "target_met": bool(np.isfinite(r_sub) and r_sub <= target_rel_se),
        "files": list(REFERENCE_FILES) + (["absorber.exr"] if absorber else []),
        **ms.scene_notes(scene),
    }

    out_dir = Path(out_dir)
    with atomic_dir(out_dir) as tmp:
        write_exr(tmp / "full.exr", fm, fse)
        write_exr(tmp / "subsurface.exr", sm, sse)
        if absorber:
            write_exr(tmp / "absorber.exr", am, ase)
        write_exr(tmp / "half_a.exr", half_a)
        write_exr(tmp / "half_b.exr", half_b)
        write_exr(tmp / "mask.exr", np.repeat(coverage[..., None], 3, axis=2))
        write_png(tmp / "preview.png", fm, auto_exposure(fm))
        meta["wall_seconds"] = time.perf_counter() - t_start
        meta = _jsonable(meta)
        (tmp / "reference.json").write_text(json.dumps(meta, indent=2, allow_nan=False))
    return meta


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
