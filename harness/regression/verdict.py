"""Regression verdicts: did SSLPV change at all, and is it better or worse beyond noise?

SSLPV is deterministic; only the path-traced reference is noisy. A verdict compares
an *old* SSLPV image (the committed image of an accuracy case, or last night's
render) with a *new* one, in two steps.

**1. Changed?** (:func:`image_change`, no statistics). The images are *unchanged* when
they cover the same pixels and every covered pixel and channel agrees within

    |new - old| <= IMAGE_RTOL * |old| + IMAGE_ATOL * max|old| ,

the floating-point tolerance of one renderer on two OpenGL implementations
(llvmpipe, NVIDIA). No second implementation is available here, so
``benchmarks/image_tolerance.py`` emulates one on llvmpipe (32 of the 72 accuracy
cases: sphere_homogeneous, skin_torus, thin_ring, layered_dielectric): the same
render twice is bit-identical; the camera moved by 1e-6 (about 8 float32 ULP) moves
a pixel by at most 5.0e-6 of its value; every mesh vertex coordinate moved by one
ULP (another driver's vertex transform and rasteriser rounding) by at most 2.1e-6,
except on skin_torus, where 6 of its 8 cases change by up to 6.6e-2 in up to 285
pixels (a texel or a shading point that lies on an LPV cell face changes cell; not
traced further). The float32 pipeline is within 4e-7 of ``max|c00|`` of the float64
twin (``tests/test_gl_vs_twin.py``). ``IMAGE_RTOL = 1e-4`` is 20 times the largest
rounding difference; the smallest deliberate change, 16-bit grids (the paper's
storage), moves pixels by at least 3.8e-3, 38 times more. A pair beyond the tolerance
that is only a driver difference (the skin_torus ULP pairs) goes to step 2, which
judged all six of them *changed-within-noise*: a too tight tolerance costs a warning,
never a false alarm. The shading lookup (``lookup = cell``, ``texelFetch``) has no
filtering; hardware trilinear filtering (``lookup = trilinear``) uses 8-bit weights
and is then "changed" on NVIDIA by up to 1e-2.

**2. Better or worse?** (:func:`judge`). For each headline metric, ``Delta =
badness(new, ref) - badness(old, ref)`` with its standard error from the reference's
per-pixel standard error (:mod:`harness.metrics.uncertainty`: the delta method, or
resampling for FLIP; a resampled SE is not estimated where ``|Delta| <= tol``, since no SE can
make such a pair anything but changed-within-noise: its ``se`` is NaN and its method
``within-tolerance``). A pair is

* a **regression** when ``Delta > tol + t * SE``,
* an **improvement** when ``-Delta > tol + t * SE``,
* otherwise **changed-within-noise**,

``tol = max(abs, rel * badness(old))`` the stated tolerance (the smallest change that
matters) and ``t`` the two-sided critical value of Student's t with the SE's degrees
of freedom at ``ALPHA / (2 m)``: a **Bonferroni** correction over the ``m``
comparisons (metrics x images x cases) that the run can judge, valid under any
dependence between them (the metrics of one image are strongly dependent). That is
a one-sided test of ``|Delta| <= tol`` at level ``ALPHA / (2 m)`` in each direction,
so the family-wise probability that any comparison of the run is called a regression
or an improvement while its true change is within the tolerance is at most
:data:`ALPHA`. Which pairs reach step 2 depends only on the SSLPV images, never on
the reference's noise, so the correction stays valid for them.

Values are compared as *badness*, the distance from the metric's ideal value (0 for
errors, 1 for SSIM and the energy ratio), so that "larger is worse" holds for every
metric.
"""

import hashlib
import math
from dataclasses import asdict, dataclass
from typing import Optional

from pydantic import Field

from harness.validation import InputModel, NonNegative

import numpy as np

# The metrics a verdict is based on; the others are reported, never judged.
HEADLINE = ("relmse", "si_relmse", "energy_ratio", "flip")
IDEAL = {"ssim": 1.0, "energy_ratio": 1.0}
DEFAULT_TOLERANCE = {"rel": 0.05, "abs": 1e-4}
#: Family-wise probability of calling any comparison of one run a regression or an improvement
#: when its true change is within the tolerance.
ALPHA = 0.01
#: Floating-point tolerance of "unchanged" (see the module docstring): relative per pixel ...
IMAGE_RTOL = 1e-4
#: ... plus this fraction of the old image's largest value (for near-black pixels).
IMAGE_ATOL = 1e-6
#: A case's verdicts, worst first.
VERDICTS = ("regression", "improvement", "changed-within-noise", "unchanged")


def badness(metric, value):
    """Distance of a metric value from its ideal."""
    return abs(float(value) - IDEAL.get(metric, 0.0))


# --------------------------------------------------------------------------- step 1: changed?

@dataclass(frozen=True)
class ImageChange:
    """What :func:`image_change` found between two SSLPV images."""

    changed: bool
    compared: int            # pixels covered in both images
    mask_flips: int          # pixels covered in one image only
    beyond: int              # covered pixels with a channel beyond the tolerance
    worst: float             # largest |new - old| / (rtol |old| + atol max|old|) (<= 1 is within)
    max_rel: float           # largest |new - old| / max|old| over covered pixels
    rtol: float
    atol: float

    def line(self):
        if not self.changed:
            return (f"unchanged: {self.compared} pixels within {self.rtol:g} x |old| + {self.atol:g} x max|old| "
                    f"(worst at {self.worst:.2g} of it)")
        return (f"changed: {self.beyond} of {self.compared} pixels beyond {self.rtol:g} x |old| + "
                f"{self.atol:g} x max|old|, {self.mask_flips} pixels covered in one image only; largest "
                f"difference {self.max_rel:.3g} x max|old|")

    def as_dict(self):
        return asdict(self)


def image_change(new, old, new_mask=None, old_mask=None, rtol=IMAGE_RTOL, atol=IMAGE_ATOL):
    """Step 1 of a verdict: are two SSLPV images equal within the floating-point tolerance?

    ``new`` and ``old`` are ``(H, W, 3)``; the masks are the renderer's coverage
    (``None``: every pixel). Any pixel covered in one image only is a change.
    """
    x = np.asarray(new, dtype=np.float64)
    y = np.asarray(old, dtype=np.float64)
    if x.shape != y.shape:
        raise ValueError(f"image_change: shapes differ: new {x.shape}, old {y.shape}")
    mn = np.ones(x.shape[:2], bool) if new_mask is None else np.asarray(new_mask, bool)
    mo = np.ones(x.shape[:2], bool) if old_mask is None else np.asarray(old_mask, bool)
    both = mn & mo
    flips = int(np.count_nonzero(mn != mo))
    xs, ys = x[both], y[both]
    peak = float(np.abs(ys).max()) if ys.size else 0.0
    d = np.abs(xs - ys)
    allowed = rtol * np.abs(ys) + atol * peak
    ratio = np.divide(d, allowed, out=np.where(d > 0, np.inf, 0.0), where=allowed > 0)
    beyond = int(np.count_nonzero((ratio > 1.0).any(axis=-1))) if ratio.size else 0
    worst = float(ratio.max()) if ratio.size else 0.0
    max_rel = float(d.max() / peak) if ys.size and peak > 0 else (0.0 if not d.size or d.max() == 0 else math.inf)
    return ImageChange(bool(flips or beyond), int(both.sum()), flips, beyond, worst, max_rel, float(rtol), float(atol))


# --------------------------------------------------------------------------- step 2: better or worse?

def critical_value(family, alpha=ALPHA, dof=math.inf):
    """Two-sided Bonferroni critical value: Student's t (``dof``) at ``1 - alpha / (2 family)``."""
    from scipy import stats

    q = 1.0 - alpha / (2.0 * max(int(family), 1))
    return float(stats.norm.ppf(q) if not np.isfinite(dof) else stats.t.ppf(q, max(float(dof), 1.0)))


@dataclass(frozen=True)
class Change:
    """The verdict on one headline metric of one image pair."""

    scene: str
    config: str
    image: str
    metric: str
    old: float               # metric(old image, ref)
    new: float               # metric(new image, ref)
    delta: float             # badness(new) - badness(old); positive is worse
    se: float                # standard error of delta (from the reference's noise)
    z: float                 # delta / se
    dof: float               # degrees of freedom of se
    critical: float          # t: Bonferroni-corrected two-sided critical value
    family: int              # m: comparisons the run can judge
    tolerance: float         # tol = max(abs, rel * badness(old))
    threshold: float         # tol + t * se: |delta| beyond it is a regression or an improvement
    verdict: str             # regression | improvement | changed-within-noise
    against: str             # previous-night | baseline
    method: str              # delta | resampling

    def as_dict(self):
        d = asdict(self)
        for k in ("se", "z", "dof", "critical"):  # JSON has no infinity or NaN (no SE: within the tolerance)
            if not np.isfinite(d[k]):
                d[k] = None if np.isnan(d[k]) else (1e308 if d[k] > 0 else -1e308)
        return d

    def line(self):
        if self.method == "within-tolerance":
            return (f"{self.metric:<13} old {self.old:.6g} new {self.new:.6g}  Delta {self.delta:+.4g}  within the "
                    f"tolerance {self.tolerance:.3g} (no SE needed)  {self.verdict.upper()}")
        z = f"{self.z:+.3g}" if np.isfinite(self.z) else ("+inf" if self.z > 0 else "-inf")
        return (f"{self.metric:<13} old {self.old:.6g} new {self.new:.6g}  Delta {self.delta:+.4g}  "
                f"SE {self.se:.3g}  z {z}  threshold {self.threshold:.4g} (tol {self.tolerance:.3g} + "
                f"t {self.critical:.3g} x SE; Bonferroni over {self.family})  {self.verdict.upper()}")


def tolerance_of(metric, old_value, tolerance=None):
    tol = dict(DEFAULT_TOLERANCE, **(tolerance or {}))
    return max(float(tol["abs"]), float(tol["rel"]) * badness(metric, old_value))


def judge(scene, config, image, diff, tolerance=None, family=1, against="baseline", alpha=ALPHA):
    """One :class:`Change` from a :class:`harness.metrics.uncertainty.PairedDifference`."""
    tol = tolerance_of(diff.metric, diff.old, tolerance)
    delta = diff.delta
    if diff.method == "within-tolerance":
        # |delta| <= tol <= tol + t SE for any SE: within noise, and no SE was estimated.
        if abs(delta) > tol:
            raise ValueError(f"{diff.metric}: a difference without a standard error is beyond the tolerance")
        return Change(scene, config, image, diff.metric, diff.old, diff.new, float(delta), math.nan, math.nan,
                      math.nan, math.nan, int(family), tol, tol, "changed-within-noise", against, diff.method)
    t = critical_value(family, alpha, diff.dof)
    threshold = tol + t * diff.se
    verdict = ("regression" if delta > threshold else "improvement" if -delta > threshold
               else "changed-within-noise")
    z = delta / diff.se if diff.se > 0 else (math.copysign(math.inf, delta) if delta else 0.0)
    return Change(scene, config, image, diff.metric, diff.old, diff.new, float(delta), float(diff.se), float(z),
                  float(diff.dof), t, int(family), tol, float(threshold), verdict, against, diff.method)


def resample_seed(*parts):
    """A stable seed for the resamples of one comparison (verdicts are reproducible)."""
    return int.from_bytes(hashlib.sha256("|".join(map(str, parts)).encode()).digest()[:4], "little")


def judge_images(scene, config, image, new, old, ref, se, mask, tolerance=None, family=1, against="baseline",
                 k=None, metrics=HEADLINE, alpha=ALPHA, draws=None):
    """Step 2 for one changed image pair: a :class:`Change` per metric in ``metrics``.

    ``ref``/``se`` are the reference image and its per-pixel standard error, ``mask``
    the comparison mask (:func:`harness.metrics.coverage.comparison_mask`), ``k`` the
    reference's seed count.
    """
    from harness.metrics.uncertainty import DEFAULT_DRAWS, paired_difference

    out = []
    for metric in metrics:
        # A resampled SE (FLIP: 2 x draws evaluations) only where it can change the verdict.
        diff = paired_difference(metric, new, old, ref, se, mask, k=k, draws=draws or DEFAULT_DRAWS,
                                 seed=resample_seed(scene, config, image, metric, against),
                                 decided_within=lambda old_value, m=metric: tolerance_of(m, old_value, tolerance))
        out.append(judge(scene, config, image, diff, tolerance, family, against, alpha))
    return out


def overall(changes, image_changed=False):
    """The worst verdict: ``regression``, ``improvement``, ``changed-within-noise`` (also when
    ``image_changed`` but nothing was judged) or ``unchanged``."""
    verdicts = {c.verdict for c in changes}
    for v in VERDICTS[:3]:
        if v in verdicts:
            return v
    return "changed-within-noise" if image_changed else "unchanged"


# ----------------------------------------------------------------- the tolerance tables of the matrices

class ToleranceSpec(InputModel):
    """A ``[tolerance]`` table of a matrix file; a key left out keeps the default's value."""

    rel: Optional[NonNegative] = Field(None, description="fraction of the old badness", examples=[0.05])
    abs: Optional[NonNegative] = Field(None, description="absolute, in the metric's units", examples=[1e-4])

    def over(self, defaults):
        """This table on top of ``defaults`` (a dict with ``rel`` and ``abs``)."""
        return dict(defaults, **self.model_dump(exclude_none=True))
