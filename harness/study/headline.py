"""The headline table: per scene and real-time budget, the best setting of each family, judged.

A *family* is an SSLPV mapping (``literal``, ``collision``, ``diffusion``, each calibration) or a
rival with its gather (``dipole dense``, ...). Within a budget (SSLPV at ``N = budget.grid`` and
one ``K``; a rival has no N or K, so all of its settings compete in every budget) each family's
*best* setting is the one with the lowest subsurface badness of the study's first metric.

The differences are judged with the nightly's paired machinery
(:func:`harness.metrics.uncertainty.paired_difference`, :func:`harness.regression.verdict.judge`):
each family's best against the budget's best, one paired difference per metric of
``significance`` against the scene's one noisy reference, with no tolerance (tol = 0: the question
is "is the difference beyond the reference's noise?"), Bonferroni-corrected over every comparison
of the table. A cell is ``best``, ``tied`` (within noise), ``worse`` (beyond it) or, when the
metrics disagree, ``better-in-part`` or ``mixed`` (:func:`judge_cells`).

A metric with a gradient (relMSE, energy ratio, ...) is judged by the delta method; one without
(FLIP) by parametric resampling of the reference (:data:`~harness.metrics.uncertainty.DEFAULT_DRAWS`
draws, seeded by the scene, the two settings and the metric, so a table is reproducible), at
2 x draws evaluations of the metric per comparison: the default study leaves FLIP out of
``significance`` for that cost.

Limits: the ranking is by one metric; a family with no setting in a budget has no cell there;
resampled standard errors rest on :data:`~harness.metrics.uncertainty.DEFAULT_DRAWS` draws
(their degrees of freedom enter the critical value).
"""

from harness.io.images import read_exr
from harness.metrics.uncertainty import paired_difference
from harness.regression.verdict import badness, judge, resample_seed

#: A rival competes in every budget: its key in a budget's cells.
ANY_K = "any"


def _rank_value(row, metric):
    v = row.get(f"subsurface_{metric}")
    return float("inf") if v is None else badness(metric, v)


def family_order(rows):
    """Families in table order: SSLPV's (paper mappings, then calibrations), then the rivals."""
    fams = {r["family"]: r["method"] for r in rows}
    paper = ["literal", "collision", "diffusion"]
    sslpv = [f for f in paper if f in fams] + sorted(f for f, m in fams.items() if m == "sslpv" and f not in paper)
    return sslpv + sorted(f for f, m in fams.items() if m != "sslpv")


def best_cells(rows, budget, metric):
    """``{(scene, K): {family: row}}`` per budget K, and ``{scene: {family: row}}`` over all budgets
    (SSLPV rows outside the budgets, such as other N, compete in neither)."""
    per_k, overall = {}, {}
    ks = [str(k) for k in budget["steps"]]
    for r in rows:
        if r["method"] == "sslpv":
            if r["N"] != budget["grid"] or r["K"] not in ks:
                continue
            keys = [r["K"]]
        else:
            keys = ks
        for k in keys:
            cell = per_k.setdefault((r["scene"], k), {})
            if r["family"] not in cell or _rank_value(r, metric) < _rank_value(cell[r["family"]], metric):
                cell[r["family"]] = r
        o = overall.setdefault(r["scene"], {})
        if r["family"] not in o or _rank_value(r, metric) < _rank_value(o[r["family"]], metric):
            o[r["family"]] = r
    return per_k, overall


class _Images:
    """Subsurface images of render folders and references, read once."""

    def __init__(self):
        self._render, self._ref = {}, {}

    def render(self, d):
        if d not in self._render:
            self._render[d] = read_exr(f"{d}/subsurface.exr")["rgb"]
        return self._render[d]

    def reference(self, d, shape):
        if d not in self._ref:
            from harness.runs.sweep import load_reference

            self._ref[d] = load_reference(d, shape)
        return self._ref[d]


def judge_cells(groups, metric, significance, images=None):
    """Mark each cell of ``groups`` (a list of ``{family: row}``) against its group's best.

    Returns ``[{family: {"row", "status", "changes"}}]`` in the order of ``groups``; ``status``
    is ``best``, ``tied``, ``worse``, ``better-in-part`` (better beyond noise in a metric other than
    the ranking one, worse in none), ``mixed`` (worse in one, better in another), or ``unjudged`` (no
    reference standard error).
    """
    images = images or _Images()
    family = max(1, sum(len(g) - 1 for g in groups) * max(len(significance), 1))
    out = []
    for g in groups:
        if not g:
            out.append({})
            continue
        best_fam = min(g, key=lambda f: _rank_value(g[f], metric))
        best = g[best_fam]
        cells = {best_fam: {"row": best, "status": "best", "changes": []}}
        for fam, row in g.items():
            if fam == best_fam:
                continue
            old = images.render(best["render_dir"])
            ref = images.reference(best["reference_dir"], old.shape[:2])
            if ref.get("se") is None or not significance:
                cells[fam] = {"row": row, "status": "unjudged", "changes": []}
                continue
            new = images.render(row["render_dir"])
            changes = []
            for m in significance:
                diff = paired_difference(m, new, old, ref["subsurface"], ref["se"], ref["mask"], k=ref.get("K"),
                                         seed=resample_seed(row["scene"], best["setting"], row["setting"], m))
                changes.append(judge(row["scene"], row["setting"], "subsurface", diff, {"rel": 0.0, "abs": 0.0},
                                     family, against=best["setting"]))
            worse = any(c.verdict == "regression" for c in changes)
            better = any(c.verdict == "improvement" for c in changes)   # in a metric other than the ranking one
            status = "mixed" if worse and better else "worse" if worse else "better-in-part" if better else "tied"
            cells[fam] = {"row": row, "status": status, "changes": [c.as_dict() for c in changes]}
        out.append(cells)
    return out


def headline(rows, budget, metrics, significance):
    """The headline table and the per-budget table, judged.

    Returns ``{"families", "scenes", "overall": {scene: cells}, "per_budget": {scene: {K: cells}},
    "comparisons", "ks"}``; ``cells`` is ``{family: {"row", "status", "changes"}}``.
    """
    metric = metrics[0]
    per_k, overall = best_cells(rows, budget, metric)
    scenes = sorted({r["scene"] for r in rows})
    ks = [str(k) for k in budget["steps"]]
    images = _Images()
    keys = [(s, k) for s in scenes for k in ks if (s, k) in per_k]
    judged_k = judge_cells([per_k[key] for key in keys], metric, significance, images)
    judged_o = judge_cells([overall.get(s, {}) for s in scenes], metric, significance, images)
    per_budget = {}
    for key, cells in zip(keys, judged_k):
        per_budget.setdefault(key[0], {})[key[1]] = cells
    return {"families": family_order(rows), "scenes": scenes, "ks": ks, "metric": metric,
            "overall": dict(zip(scenes, judged_o)), "per_budget": per_budget,
            "comparisons": {"per_budget": sum(len(c) - 1 for c in judged_k if c),
                            "overall": sum(len(c) - 1 for c in judged_o if c)}}
