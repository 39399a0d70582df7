"""The calibration target: the best committed calibrated mapping, held out, against the accuracy targets.

``baselines/calibrated/best/selection.json`` (``sslpv-harness calibrate-best``; ``docs/calibration.md``)
names the best committed calibration and lists every candidate's held-out medians. For that calibration,
if the study rendered it, :func:`target` checks at the study's grid N and at each budget of
:data:`TARGET_STEPS` (K = 32, and the converged ``steady``)::

    (T1) energy ratio (subsurface) in ENERGY_RANGE on at least n - SPARE of the n index-matched
         scenes the calibration was fitted on, each as the fit's own leave-one-scene-out validation
         rendered it (the calibration fitted without the scene; its ``calibration.json``)
    (T2) ... on every dielectric scene of the study
    (T3) ... on every back-lit homogeneous scene of the study (tags ``back-lit`` and ``homogeneous``)
         that the calibration was not fitted on
    (T4) the median held-out relMSE (subsurface) over the fitted scenes at most RELMSE_FACTOR times
         the lowest such median among the selection's scalar calibrations (one (s, r) pair per
         budget; the candidates' ``form`` false) at the same budget

Beside (T4), the same median **in sample** (each fitted scene rendered with the calibration fitted on every scene,
its ``calibration.json``): no leave-one-scene-out median of that fit is expected below it, so where it exceeds
(T4)'s limit the form itself, not its generalisation to an unseen scene, stops (T4); where it lies below, the
held-out excess over it is the generalisation's. And the **floor** of the calibration's family where one was written (``floor.json`` of the calibration
or of its sources; :mod:`harness.calibration.floor`): the median over the fitted scenes of each scene at its own
best ``(s, r)`` per colour channel (Eq. L1), and ``bound``, the same median with every scene whose floor bounds no
form (its terms vary over the grid, or its least lies at an end of the scan before the loss levelled off), and every
fitted scene the floor has no row for, taken as 0. No calibration of the family, scalar or form, held out or in sample, has a median below
``bound``; where ``bound`` exceeds (T4)'s limit, (T4) is out of reach for the family.

The winner is chosen over every budget (``calibrate-best``: the geometric mean of its medians). At a budget where
another candidate has the lower median held-out relMSE, that candidate is judged by the same rules beside it
(``best_at_budget``): the settings that reproduce the suite best at that budget alone.

A scene of (T2) or (T3) that the calibration was fitted on is taken from its held-out validation like
(T1); one it was not fitted on is the study's own render with the committed file, held out by
construction (no fit saw it). A scene with neither is ``missing`` and its group is not met.

Limits: the held-out figures of (T1) are the calibration's, rendered when it was fitted, not by this
study; (T2) and (T3) judge single renders against the target range, without a noise term (the
reference's energy noise is on the headline's noise floor column, about 1e-3 of the ratio on the suite);
the selection must name a calibration of the study, else no target is judged (``"why"`` says so).
"""

import json
import statistics
from pathlib import Path

from harness import paths

#: The committed selection of the best calibration.
SELECTION = paths.REPO / "baselines" / "calibrated" / "best" / "selection.json"
#: The budgets the target is judged at (at the study's grid N).
TARGET_STEPS = (32, "steady")
#: The energy ratio's target range, the fitted scenes that may miss it, and the relMSE factor.
ENERGY_RANGE = (0.8, 1.25)
SPARE = 1
RELMSE_FACTOR = 0.5


def _in_range(e):
    return e is not None and ENERGY_RANGE[0] <= e <= ENERGY_RANGE[1]


def _same_folder(a, b):
    from sslpv_gl.calibrated import resolve_path

    return resolve_path(str(a)).resolve() == resolve_path(str(b)).resolve()


def _winner(selection, calibrations):
    """``(selection dict, the study's calibration entry of its winner)``; either may be None."""
    path = Path(selection)
    if not path.is_file():
        return None, None
    sel = json.loads(path.read_text())
    for cal in calibrations:
        if _same_folder(Path(cal["file"]).parent, sel["winner"]):
            return sel, cal
    return sel, None


def _study_value(rows, label, scene, grid, k):
    for r in rows:
        if r["scene"] == scene and r["family"] == label and r["N"] == grid and r["K"] == str(k):
            return r.get("subsurface_energy_ratio"), r.get("subsurface_relmse")
    return None, None


def _entry(scene, fitted, held, rows, label, grid, k):
    if scene in fitted:
        h = held.get(scene) or {}
        return {"scene": scene, "energy_ratio": h.get("energy_ratio"), "relmse": h.get("relmse"),
                "source": "held out"}
    e, rel = _study_value(rows, label, scene, grid, k)
    return {"scene": scene, "energy_ratio": e, "relmse": rel, "source": "not fitted" if e is not None else "missing"}


def _group(name, entries, need):
    inside = [x for x in entries if _in_range(x["energy_ratio"])]
    return {"group": name, "scenes": entries, "need": need, "of": len(entries), "in_range": len(inside),
            "met": bool(entries) and len(inside) >= need,
            "outside": [x for x in entries if not _in_range(x["energy_ratio"])]}


def _median_relmse(figures, fitted):
    """The median relMSE over the ``fitted`` scenes that ``figures`` (scene -> figures) has one for, or None."""
    rel = [figures[s]["relmse"] for s in fitted if figures.get(s, {}).get("relmse") is not None]
    return statistics.median(rel) if rel else None


def _lowest(sel, key, scalar=False):
    """``(folder, median held-out relMSE)`` of the selection's candidate with the lowest median at ``key`` (only
    the scalar calibrations, ``form`` false, with ``scalar``), or None."""
    best = None
    for c in sel.get("candidates", []):
        m = (c.get("budgets") or {}).get(key, {}).get("median_held_out_relmse")
        if not (scalar and c.get("form")) and m is not None and (best is None or m < best[1]):
            best = (c["folder"], m)
    return best


def _floor(report, key, fitted):
    """The family's floor at ``key`` over the ``fitted`` scenes (module docstring), or None where none was written."""
    from harness.calibration.floor import bounds, floor_for, median_bound

    entry, path = floor_for(report, key)
    if entry is None:
        return None
    rows = entry.get("scenes") or {}
    names = [n for n in fitted if n in rows]
    if not names:
        return None
    where = Path(path).resolve()
    return {"file": str(where.relative_to(paths.REPO) if where.is_relative_to(paths.REPO) else where),
            "median": statistics.median(rows[n]["relmse"] for n in names),
            "median_scalar": statistics.median(rows[n]["scalar"]["relmse"] for n in names),
            "bound": median_bound(entry, fitted),
            "varying": [n for n in names if not bounds(rows[n])] + [n for n in fitted if n not in rows],
            "scenes": len(names), "of": len(fitted)}


def scene_info(names):
    """``{scene: {"dielectric", "tags"}}`` of the named scenes (suite names or folders), as :func:`target` takes it."""
    from harness.scene import load_scene

    out = {}
    for name in names:
        s = load_scene(name)
        out[name] = {"dielectric": s.boundary.kind == "dielectric", "tags": set(s.tags)}
    return out


def _judge(cal, report, sel, rows, scenes, grid, k):
    """One budget of the target (module docstring) for the study's calibration entry ``cal`` and its
    ``calibration.json`` ``report``: ``{"budget", "K", "groups", "relmse", "met"}``, or ``{"budget", "why", "met":
    False}`` where its file has no such budget."""
    fitted = list(report.get("scenes") or [])
    index_matched = [s for s in fitted if not scenes.get(s, {}).get("dielectric")]
    dielectric = sorted(s for s, i in scenes.items() if i.get("dielectric"))
    backlit = sorted(s for s, i in scenes.items() if {"back-lit", "homogeneous"} <= set(i.get("tags", ()))
                     and s not in fitted)
    key = f"N={grid} steps={k}"
    res = (report.get("results") or {}).get(key)
    if res is None:
        return {"budget": key, "why": f"the calibration has no budget {key}", "met": False}
    held = res.get("held_out") or {}
    groups = [
        _group("index-matched, fitted (held out)",
               [_entry(s, fitted, held, rows, cal["label"], grid, k) for s in index_matched],
               max(len(index_matched) - SPARE, 0)),
        _group("dielectric", [_entry(s, fitted, held, rows, cal["label"], grid, k) for s in dielectric],
               len(dielectric)),
        _group("back-lit homogeneous, not fitted",
               [_entry(s, fitted, held, rows, cal["label"], grid, k) for s in backlit], len(backlit)),
    ]
    median = _median_relmse(held, fitted)
    base = _lowest(sel, key, scalar=True)
    relmse = {"median": median, "baseline": base[0] if base else None, "baseline_median": base[1] if base else None,
              "limit": RELMSE_FACTOR * base[1] if base else None}
    relmse["met"] = median is not None and base is not None and median <= relmse["limit"]
    relmse["in_sample"] = _median_relmse(res.get("in_sample") or {}, fitted)
    relmse["floor"] = _floor(cal["report"], key, fitted)
    return {"budget": key, "K": str(k), "groups": groups, "relmse": relmse,
            "met": all(g["met"] for g in groups) and relmse["met"]}


def target(rows, calibrations, budget, scenes, selection=SELECTION):
    """The target of the module docstring: ``{"selection", "calibration", "label", "file", "budgets": [...], "met",
    "best_at_budget": [...]}``, or ``{"why": ...}`` when it cannot be judged. ``scenes``: ``{scene: {"dielectric":
    bool, "tags": set}}`` of the study's scenes; ``rows``: the study's rows (:mod:`harness.study.table`).

    ``best_at_budget`` judges, at each budget where another candidate of the selection has a lower median held-out
    relMSE than the winner and the study rendered it, that candidate the same way (``{"calibration", "label",
    "file", "judged"}``): the settings that reproduce the suite best at that budget alone, which the winner,
    chosen over every budget, need not be. ``"why"`` stands for ``"judged"`` where the study did not render it."""
    sel, cal = _winner(selection, calibrations)
    if sel is None:
        return {"why": f"no selection of the best calibration ({Path(selection).name} missing)"}
    if cal is None:
        return {"why": f"the best calibration ({sel['winner']}) is not one of the study's calibrations"}
    if not cal.get("report"):
        return {"why": f"the best calibration ({sel['winner']}) has no calibration.json beside it"}
    report = json.loads(Path(cal["report"]).read_text())
    grid = budget["grid"]
    where = Path(selection).resolve()
    shown = where.relative_to(paths.REPO) if where.is_relative_to(paths.REPO) else where
    out = {"selection": str(shown), "calibration": sel["winner"], "label": cal["label"], "file": cal["file"],
           "budgets": [_judge(cal, report, sel, rows, scenes, grid, k) for k in TARGET_STEPS], "best_at_budget": [],
           "grid": grid, "other_grids": sel.get("other_grids", [])}
    out["met"] = all(b["met"] for b in out["budgets"])
    for k in TARGET_STEPS:
        folder, _ = _lowest(sel, f"N={grid} steps={k}") or (None, None)
        if folder is None or _same_folder(folder, sel["winner"]):
            continue
        other = next((c for c in calibrations if _same_folder(Path(c["file"]).parent, folder)), None)
        entry = {"budget": f"N={grid} steps={k}", "calibration": folder}
        if other is None or not other.get("report"):
            entry["why"] = f"{folder} is not one of the study's calibrations"
        else:
            judged = _judge(other, json.loads(Path(other["report"]).read_text()), sel, rows, scenes, grid, k)
            entry.update(label=other["label"], file=other["file"], judged=judged)
        out["best_at_budget"].append(entry)
    return out
