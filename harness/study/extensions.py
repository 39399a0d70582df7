"""The extensions beside the published method: each one's effect on every scene, judged, and the outside
treatment the extensions default to.

An *extension* is an SSLPV option that the paper does not have (:data:`PAPER`: the paper's value of each):
the outside treatments ``interior``, ``absorb``, ``extrapolated`` and ``material`` (``outside``;
``docs/diffusion_mapping.md`` Sec. 8), the dielectric boundary's internal reflection (``boundary_reflect =
rdr``, Sec. 10), delta-Eddington scaling of forward-peaked media (``phase_scaling``, Sec. 9), the
``eta^2`` radiance compression (``eta2``), an inward injection offset (``inject_offset``, in scene units, and
``inject_depth``, in reduced mean free paths of the medium; :mod:`sslpv_gl.inject` Eq. (J1)), the shading's
read of the grid below the surface (``shade_depth``, in cells; :mod:`sslpv_gl.shade` Eq. (S1)), its read
interpolated between cell centres (``lookup = trilinear``; the paper reads each cell's own coefficients) and the
``transport`` mapping (Sec. 11: one step is one cell of path), which is judged against the paper's
``collision`` (:data:`MAPPING_BASE`) and needs an outside treatment that takes light out. A
configuration with any of them competes in its own family, named after its mapping's family and its
extensions (``collision + interior``, ``diffusion + R_dr``; :func:`family_suffix`), never in the
paper's, so the headline table keeps the published method and each calibration as they are.

:func:`effects`: for every extension family and every scene, the family's best setting within the
study's real-time budgets (N = the budget's grid, K in its steps; ranked by the study's first metric)
against the best setting of its *base* family (the same mapping without the extensions), judged as the
headline judges its cells (:func:`harness.study.headline.judge_cells`: paired differences against the
same reference, Bonferroni over every comparison of this table). Per family: the median over scenes of
the ratio of the ranking metric (extension / base), and the scenes where the extension is better or
worse beyond the reference's noise.

:func:`default_outside`: the outside treatment for the extensions, chosen by the measured effect on the
suite: among the families whose only extension is an outside treatment (an extension mapping's families
left out), the treatment whose median
ratio, pooled over their mappings' scenes, is lowest, provided it is below 1 (the paper's ``vacuum``
is the ratio 1 by definition, and stays the choice when no treatment beats it); ``None`` when the
study rendered none. The
paper's own default (``vacuum``) stays SSLPV's default: this choice is what the extensions are
measured and calibrated with.

Limits: a base family the study did not render leaves its extension families unjudged (``"no base"``);
the ratio is of the ranking metric only (the other metrics' judgements are in ``status``); a scene where
the base's metric is 0 has no ratio.
"""

import statistics

from harness.study.headline import best_cells, judge_cells
from sslpv_gl.params import EXTENSION_MAPPINGS, PAPER_SETTINGS

#: Each extension's parameter and the paper's value of it.
PAPER = PAPER_SETTINGS
#: How a non-paper value is named in a family (the value itself where absent).
NAMES = {"boundary_reflect": {"rdr": "R_dr"}, "phase_scaling": {"delta-eddington": "δ-Eddington"},
         "eta2": {True: "η²"}, "exitance": {"boundary": "J exitance"}}
SEPARATOR = " + "
#: Mappings that are themselves extensions, and the published mapping each is judged against.
MAPPING_BASE = EXTENSION_MAPPINGS


def extension_tags(params):
    """The names of the extensions ``params`` (a dict) turns on, in :data:`PAPER`'s order."""
    tags = []
    for key, paper in PAPER.items():
        v = params.get(key, paper)
        if v is None or v == paper:
            continue
        if key == "inject_offset":
            tags.append(f"offset {v:g}")
        elif key == "inject_depth":
            tags.append(f"depth {v:g} mfp'")
        elif key == "shade_depth":
            tags.append(f"read {v:g} cell{'' if v == 1 else 's'} deep")
        else:
            tags.append(NAMES.get(key, {}).get(v, str(v)))
    return tags


def family_suffix(params):
    """``" + interior + R_dr"`` for a configuration with extensions, ``""`` for the paper's."""
    tags = extension_tags(params)
    return "".join(SEPARATOR + t for t in tags)


def is_extension(row):
    """Whether a study row (:mod:`harness.study.table`) belongs to an extension family."""
    return row.get("method") == "sslpv" and SEPARATOR in row.get("family", "")


def base_family(family):
    """The family of the same mapping without extensions: ``collision + interior`` -> ``collision``; an extension
    mapping's family against the published mapping it extends (:data:`MAPPING_BASE`): ``transport + absorb`` ->
    ``collision``."""
    head = family.split(SEPARATOR, 1)[0]
    return MAPPING_BASE.get(head, head)


def _best(rows, budget, metric):
    """``{(scene, family): row}``: each SSLPV family's best row per scene within the budgets (the headline's
    :func:`~harness.study.headline.best_cells`)."""
    _, overall = best_cells(rows, budget, metric)
    return {(s, f): r for s, cells in overall.items() for f, r in cells.items() if r["method"] == "sslpv"}


def _outcome(ext, base):
    """The extension's judged outcome from a two-member group's cells."""
    if ext["status"] == "best":
        return {"tied": "≈", "worse": "better", "better-in-part": "≈ (base better in part)",
                "mixed": "mixed", "unjudged": "?"}[base["status"]]
    return {"tied": "≈", "worse": "worse", "better-in-part": "≈ (better in part)", "mixed": "mixed",
            "unjudged": "?"}[ext["status"]]


def effects(rows, budget, metrics, significance, images=None):
    """Each extension family against its base family, per scene (see the module docstring).

    Returns ``{"families": [{"family", "base", "median_ratio", "scenes", "better", "worse", "cells":
    {scene: {"ratio", "outcome", "setting", "base_setting", "values", "base_values"}}}], "scenes",
    "comparisons"}``.
    """
    metric = metrics[0]
    best = _best(rows, budget, metric)
    fams = sorted({f for (_, f) in best if SEPARATOR in f})
    scenes = sorted({s for (s, _) in best})
    pairs, groups = [], []
    for fam in fams:
        for s in scenes:
            ext, base = best.get((s, fam)), best.get((s, base_family(fam)))
            if ext is not None and base is not None:
                pairs.append((fam, s))
                groups.append({fam: ext, base_family(fam): base})
    judged = judge_cells(groups, metric, significance, images)
    by = dict(zip(pairs, judged))
    out = []
    for fam in fams:
        base = base_family(fam)
        cells, ratios = {}, []
        for s in scenes:
            if (fam, s) not in by:
                if (s, fam) in best:
                    cells[s] = {"ratio": None, "outcome": "no base", "setting": best[(s, fam)]["setting"]}
                continue
            c = by[(fam, s)]
            e, b = c[fam]["row"], c[base]["row"]
            ev, bv = e.get(f"subsurface_{metric}"), b.get(f"subsurface_{metric}")
            ratio = None if ev is None or not bv else float(ev) / float(bv)
            if ratio is not None:
                ratios.append(ratio)
            cells[s] = {"ratio": ratio, "outcome": _outcome(c[fam], c[base]), "setting": e["setting"],
                        "base_setting": b["setting"],
                        "values": [e.get(f"subsurface_{m}") for m in metrics],
                        "base_values": [b.get(f"subsurface_{m}") for m in metrics]}
        out.append({"family": fam, "base": base, "median_ratio": statistics.median(ratios) if ratios else None,
                    "scenes": len(ratios), "better": sum(c["outcome"] == "better" for c in cells.values()),
                    "worse": sum(c["outcome"] == "worse" for c in cells.values()), "cells": cells})
    return {"families": out, "scenes": scenes, "metric": metric,
            "comparisons": sum(len(g) - 1 for g in groups)}


def default_outside(found):
    """``{"outside", "median_ratio", "by_mode"}``: the outside treatment for the extensions (module docstring)."""
    from sslpv_gl.boundary import OUTSIDE_MODES

    pooled = {}
    for f in found["families"]:
        head, *tags = f["family"].split(SEPARATOR)
        if len(tags) != 1 or tags[0] not in OUTSIDE_MODES or head in MAPPING_BASE:
            continue                                  # an extension mapping's ratio is not the outside's alone
        pooled.setdefault(tags[0], []).extend(c["ratio"] for c in f["cells"].values() if c["ratio"] is not None)
    by_mode = {m: statistics.median(v) for m, v in pooled.items() if v}
    if not by_mode:
        return None
    best = min(by_mode, key=by_mode.get)
    mode = best if by_mode[best] < 1.0 else PAPER["outside"]     # the paper's treatment is ratio 1 by definition
    return {"outside": mode, "median_ratio": by_mode.get(mode, 1.0), "by_mode": by_mode,
            "scenes": {m: len(v) for m, v in pooled.items()}}
