"""Regression verdicts: is a change in a metric beyond noise and tolerance?

A path-traced reference is an estimate, so every metric value carries a noise
floor: the same metric between two independent halves of the reference
(:func:`harness.metrics.noise_floor`). Values are compared as *badness*, the
distance from the metric's ideal value (0 for errors, 1 for SSIM and the
energy ratio), so that "larger is worse" holds for every metric.

A change from ``old`` to ``new`` is

* a **regression** when ``bad(new) - bad(old) > floor(old) + floor(new) + tol``,
* an **improvement** when ``bad(old) - bad(new) > floor(old) + floor(new) + tol``,
* otherwise **unchanged**,

with ``tol = max(abs_tol, rel_tol * bad(old))``. False alarms cost users as much
as missed regressions, so both the floors and the tolerance are always added.
"""

from dataclasses import asdict, dataclass
from typing import Optional

from pydantic import Field

from harness.validation import InputModel, NonNegative

# The metrics a verdict is based on; the others are reported, never judged.
HEADLINE = ("relmse", "si_relmse", "energy_ratio", "flip")
IDEAL = {"ssim": 1.0, "energy_ratio": 1.0}
DEFAULT_TOLERANCE = {"rel": 0.05, "abs": 1e-4}


def badness(metric, value):
    """Distance of a metric value from its ideal."""
    return abs(float(value) - IDEAL.get(metric, 0.0))


@dataclass(frozen=True)
class Change:
    scene: str
    config: str
    image: str
    metric: str
    old: float
    new: float
    old_floor: float
    new_floor: float
    threshold: float
    delta: float          # bad(new) - bad(old); positive is worse
    verdict: str          # regression | improvement | unchanged
    against: str          # previous-night | baseline

    def as_dict(self):
        return asdict(self)


def judge(scene, config, image, metric, old, old_floor, new, new_floor, tolerance=None, against="baseline"):
    """One :class:`Change` for one metric of one configuration."""
    tol = dict(DEFAULT_TOLERANCE, **(tolerance or {}))
    b_old, b_new = badness(metric, old), badness(metric, new)
    f_old, f_new = badness(metric, old_floor), badness(metric, new_floor)
    threshold = f_old + f_new + max(tol["abs"], tol["rel"] * b_old)
    delta = b_new - b_old
    verdict = "regression" if delta > threshold else "improvement" if -delta > threshold else "unchanged"
    return Change(scene, config, image, metric, float(old), float(new), float(old_floor), float(new_floor),
                  float(threshold), float(delta), verdict, against)


def compare_rows(old_rows, new_rows, tolerance=None, against="baseline", metrics=HEADLINE):
    """Judge every headline metric present in both row sets.

    Rows are dicts with ``scene, config, image, metric, value, noise_floor``; they
    are matched on ``(scene, config, image, metric)``. Rows present on one side only
    are ignored here (the caller reports them as new or missing).
    """
    old = {(r["scene"], r["config"], r["image"], r["metric"]): r for r in old_rows}
    out = []
    for r in new_rows:
        key = (r["scene"], r["config"], r["image"], r["metric"])
        if r["metric"] not in metrics or key not in old:
            continue
        o = old[key]
        tol = tolerance(r["scene"]) if callable(tolerance) else tolerance
        out.append(judge(*key, o["value"], o["noise_floor"], r["value"], r["noise_floor"], tol, against))
    return out


def overall(changes):
    """``regression`` if any change regressed, else ``improvement`` if any improved, else ``unchanged``."""
    verdicts = {c.verdict for c in changes}
    for v in ("regression", "improvement"):
        if v in verdicts:
            return v
    return "unchanged"


# ----------------------------------------------------------------- the tolerance tables of the matrices

class ToleranceSpec(InputModel):
    """A ``[tolerance]`` table of a matrix file; a key left out keeps the default's value."""

    rel: Optional[NonNegative] = Field(None, description="fraction of the old badness", examples=[0.05])
    abs: Optional[NonNegative] = Field(None, description="absolute, in the metric's units", examples=[1e-4])

    def over(self, defaults):
        """This table on top of ``defaults`` (a dict with ``rel`` and ``abs``)."""
        return dict(defaults, **self.model_dump(exclude_none=True))
