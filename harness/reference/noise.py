"""The noise figure of a reference: per-seed statistics and the lit pixels it is measured over.

Each image is the mean of ``K`` independent renders (distinct seeds); the per-pixel
standard error is ``std(ddof=1) / sqrt(K)`` per channel (:func:`seed_stats`). Lit pixels
are fully covered by the mesh (coverage >= ``FULL_COVERAGE``) and, per channel, brighter
than ``LIT_FRACTION`` of that channel's 99th percentile over covered pixels
(:func:`lit_mask`); the figure is the median of ``se / mean`` over the lit (pixel,
channel) pairs (:func:`median_rel_se`). A median of SEs estimated from few seeds is
biased low, by :func:`se_median_factor`. The time a round's samples took per (pass, seed)
unit is :func:`unit_cost`.
"""

import math

import numpy as np

from harness.metrics.coverage import FULL_COVERAGE

LIT_FRACTION = 0.01          # lit: brighter than this fraction of the 99th percentile


def unit_cost(jobs, overhead=0.0, weights=None):
    """Seconds per sample of one (pass, seed) unit from a round's ``jobs`` ``[(pass, spp, seconds[, kernels])]``.

    Where every job has its kernels' execution seconds (Dr.Jit's kernel history, compilation apart),
    a pass costs the mean of its jobs' kernel seconds per sample: a sample's cost varies with its
    path's length, and a few long paths weigh in the mean that large jobs will pay. Otherwise, per
    pass, the lower quartile of its jobs' seconds (scaled to the round's median sample count; a job
    that compiled a kernel is a slow outlier), less ``overhead`` seconds per job (at most half a
    job's time). The passes' figures are averaged (a grey pass per colour channel costs what its
    channel's sigma_t makes it cost). ``weights`` (pass name -> samples per sample of the unit, 1 where
    absent) weighs a pass that renders fewer samples than the others: the sampled solutions' part of a
    split reference (:class:`.jobs.PassSpec`).
    """
    jobs = [tuple(j) + (None,) * (4 - len(j)) for j in jobs]
    passes = sorted({q for q, *_ in jobs})
    w = {p: (weights or {}).get(p, 1.0) for p in passes}
    if all(k is not None for *_, k in jobs):
        return float(np.mean([w[p] * np.mean([k / n for q, n, _, k in jobs if q == p]) for p in passes]))
    spp = float(np.median([n for _, n, _, _ in jobs]))
    t = float(np.mean([w[p] * np.percentile([sec / n * spp for q, n, sec, _ in jobs if q == p], 25)
                       for p in passes]))
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


def stack_agreement(a, b, lit, z_max=4.0):
    """How two independent seed stacks ``a`` and ``b`` (K, H, W, 3) of the same image agree, per lit channel.

    ``lit`` is the (H, W, 3) mask of :func:`lit_mask` (usually of ``b``'s mean). Per channel of a pixel,
    ``z = (mean_a - mean_b) / sqrt(se_a^2 + se_b^2)`` with each SE from its own seeds (:func:`seed_stats`); a channel
    whose combined SE is 0 (no seed saw light, or every seed the same: a shadow ray's 0-or-1 transmittance) has no
    z and counts as agreeing. A pixel is *within* when each of its lit channels has ``|z| <= z_max``.

    Returns a dict: ``within`` (the fraction of pixels with a lit channel that are within; NaN when none is lit),
    ``pixels`` (how many have a lit channel), ``z`` ((H, W, 3), NaN where unlit or without an SE), ``ratio`` and
    ``diff`` (per channel, image mean of ``a`` over that of ``b``, and their difference) and ``diff_se`` (the
    difference's standard error, from the per-seed image means).
    """
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    (ma, sa), (mb, sb) = seed_stats(a), seed_stats(b)
    se = np.hypot(sa, sb)
    z = np.where(lit & (se > 0), (ma - mb) / np.where(se > 0, se, 1.0), np.nan)
    rows = lit.any(axis=-1)
    within = np.all(~(np.abs(z) > z_max), axis=-1)[rows]
    pa, pb = a.mean(axis=(1, 2)), b.mean(axis=(1, 2))
    diff_se = np.hypot(pa.std(axis=0, ddof=1) / math.sqrt(len(pa)), pb.std(axis=0, ddof=1) / math.sqrt(len(pb)))
    return {"within": float(within.mean()) if within.size else float("nan"), "pixels": int(rows.sum()), "z": z,
            "ratio": pa.mean(axis=0) / pb.mean(axis=0), "diff": pa.mean(axis=0) - pb.mean(axis=0), "diff_se": diff_se}
