"""The study's findings as text: table cells and the "what limits SSLPV" sentences, shared by the page
(:mod:`harness.study.page`) and ``docs/results.md`` (:mod:`harness.study.docs`), so both say the same.

Every number is formatted from the results here; nothing is typed by hand.
"""

STATUS_MARK = {"best": "best", "tied": "≈", "worse": "worse", "better-in-part": "≈+", "mixed": "±", "unjudged": "?"}


def g(x, digits=3):
    """A number in ``digits`` significant figures; ``–`` for None."""
    if x is None or x == "":
        return "–"
    return f"{float(x):.{digits}g}"


def cell(c, metrics):
    """One judged cell -> ``{"values", "setting", "cost", "status", "mark"}`` as text."""
    r = c["row"]
    vals = " / ".join(g(r.get(f"subsurface_{m}")) for m in metrics)
    k = f" K={r['K']}" if r["K"] is not None else ""
    cost = f"{g(r['frame_ms'])} ms, {g(r['work'], 2)} work"
    return {"vals": vals, "setting": r["setting"], "k": k.strip(), "cost": cost, "status": c["status"],
            "mark": STATUS_MARK[c["status"]]}


def floors(cells, metrics):
    """The scene's noise floors of ``metrics`` (the same for every row of a scene)."""
    r = next(iter(cells.values()))["row"] if cells else {}
    return " / ".join(g(r.get(f"subsurface_{m}_floor")) for m in metrics)


def headline_rows(head, metrics):
    """``[{"scene", "floor", "cells": [cell or None per family]}]`` of the one-row-per-scene table."""
    out = []
    for scene in head["scenes"]:
        cells = head["overall"].get(scene, {})
        out.append({"scene": scene, "floor": floors(cells, metrics),
                    "cells": [cell(cells[f], metrics) if f in cells else None for f in head["families"]]})
    return out


def budget_rows(head, metrics):
    """``[{"scene", "k", "floor", "cells"}]`` of the per-budget table."""
    out = []
    for scene in head["scenes"]:
        for k in head["ks"]:
            cells = head["per_budget"].get(scene, {}).get(k)
            if not cells:
                continue
            out.append({"scene": scene, "k": k, "floor": floors(cells, metrics),
                        "cells": [cell(cells[f], metrics) if f in cells else None for f in head["families"]]})
    return out


def _pm(d):
    return f"{d['delta']:+.3g} ± {d['se']:.2g}" if "delta" in d else "(no SE)"


def limit_lines(lim):
    """The decompositions of one scene (:func:`harness.study.limits.limits`) as sentences."""
    out = [f"Best SSLPV setting: {lim['subject']} (relMSE {g(lim['relmse'])}, noise floor {g(lim['floor'])})."]
    s = lim["steps"]
    if s["measured"]:
        r, e = s["relmse"], s["energy_ratio"]
        out.append(f"Steps not converged: at {s['at']} relMSE {g(r['at_k'])}, energy ratio {g(e['at_k'])}; its "
                   f"steady state {g(r['steady'])}, {g(e['steady'])}; change in badness (steady − K, paired, "
                   f"± SE): relMSE {_pm(r)}, |E − 1| {_pm(e)}.")
    else:
        out.append(f"Steps not converged: not measured ({s['why']}).")
    o = lim["outside"]
    if o["measured"]:
        line = (f"Light outside the object: {100 * o['outside_share']:.1f} % of the accumulated energy lies in cells "
                "outside the mesh (the renderer's diagnostic)")
        if o["other_modes"]:
            line += "; with outside = " + ", ".join(
                f"{m['outside']}: relMSE {g(m['relmse'])}, E {g(m['energy_ratio'])}" for m in o["other_modes"])
        out.append(line + ".")
    else:
        out.append(f"Light outside the object: not measured ({o['why']}).")
    b = lim["boundary"]
    if b["measured"]:
        for p in b["pairs"]:
            im, di = p["index_matched"], p["dielectric"]
            out.append(f"Boundary ({p['setting']}): index-matched {im['scene']} relMSE {g(im['relmse'])} (floor "
                       f"{g(im['floor'])}), E {g(im['energy_ratio'])}; dielectric {di['scene']} relMSE "
                       f"{g(di['relmse'])} (floor {g(di['floor'])}), E {g(di['energy_ratio'])} (two references: "
                       "no paired SE).")
    else:
        out.append(f"Boundary: not measured ({b['why']}).")
    sp = lim.get("speed")
    if sp and sp["measured"]:
        line = (f"Lattice speed: the medium diffuses {g(sp['ratio'])} times as fast per cell of path as the paper's "
                f"lattice per step (median over the object's cells at N = {sp['grid']}; reduced mean free path "
                f"{g(sp['l_tr_cells'])} cells)")
        if sp["transport"]:
            line += "; the transport mapping's best: " + ", ".join(
                f"{t['family']} {t['setting']}: relMSE {g(t['relmse'])}, E {g(t['energy_ratio'])}"
                for t in sp["transport"])
        out.append(line + ".")
    elif sp:
        out.append(f"Lattice speed: not measured ({sp['why']}).")
    m = lim["mapping"]
    if m["measured"]:
        for f in m["fits"]:
            out.append(f"Mapping ({f.get('label', 'calibrated ' + f['family'])}, {f['budget']}, from its calibration.json): relMSE "
                       f"in-sample {g(f['in_sample'])}, held out {g(f['held_out'])} (E {g(f['in_sample_energy'])} / "
                       f"{g(f['held_out_energy'])}).")
        for f in m.get("floors") or []:
            out.append(f"Floor of the {f['family']} family ({f['budget']}, its floor.json): relMSE {g(f['relmse'])} with "
                       f"each colour channel at its own best scales, {g(f['scalar'])} with one pair (E {g(f['energy_ratio'])}"
                       f" at the former); " + ("no calibration of the family does better (terms uniform on the grid)."
                                               if f["bounds"] else "a form may do better (terms vary on the grid)."
                                               if not f["uniform"] else "a form may do better beyond the scan of "
                                               "sigma_scale (a channel's least at its end)."))
    else:
        out.append(f"Mapping: not measured ({m['why']}).")
    lt = lim.get("lighting")
    if lt and lt["measured"] and lt["budgets"]:
        parts = []
        for steps, v in lt["budgets"].items():
            k = "steady" if steps == "steady" else f"K = {steps}"
            parts.append(f"{k}: {v['possible']} of {v['of']}" + ("" if v["possible"] else
                         f" (with the closest, {v['closest']}, the other lighting renders at least "
                         f"{g(v['twin_at_least'])} times its truth when this one is in range)"))
        out.append(f"Lighting twin ({lt['page']}): a calibration of the material gives this scene and the same object "
                   "lit from the other side the same scales; settings of the renderer that can put both in the energy "
                   "target: " + "; ".join(parts) + ".")
    elif lt:
        out.append(f"Lighting twin: not measured ({lt.get('why', 'none of the study budgets')}).")
    return out


def judging_methods(significance):
    """How the significance metrics are judged: the delta method, or resampling where there is no gradient."""
    from harness.metrics.uncertainty import DEFAULT_DRAWS, GRADIENTS

    resampled = [m for m in significance if m not in GRADIENTS]
    if not resampled:
        return "delta method"
    return (("delta method; " if len(resampled) < len(significance) else "")
            + f"{', '.join(resampled)} by resampling the reference, {DEFAULT_DRAWS} draws")


def extension_rows(ext, metrics):
    """``[{"family", "base", "median", "counts", "cells": [text per scene]}]`` of the extensions' table
    (:func:`harness.study.extensions.effects`): per scene the ratio of the ranking metric, extension over
    base, and the judged outcome."""
    out = []
    for f in ext["families"]:
        cells = []
        for s in ext["scenes"]:
            c = f["cells"].get(s)
            cells.append("–" if c is None else f"{g(c['ratio'])} {c['outcome']}")
        out.append({"family": f["family"], "base": f["base"], "median": g(f["median_ratio"]),
                    "counts": f"{f['better']} / {f['worse']} / {f['scenes']}", "cells": cells})
    return out


def extension_lines(ext):
    """The outside treatment chosen for the extensions, as sentences."""
    d = ext.get("default_outside")
    if d is None:
        return ["The study rendered no family whose only extension is an outside treatment: no default is chosen."]
    modes = ", ".join(f"{m} {g(v)} ({d['scenes'][m]} scene-mapping pairs)" for m, v in sorted(d["by_mode"].items()))
    return [f"Median {ext['metric']} ratio against the paper's outside treatment (vacuum), pooled over the mappings "
            f"and scenes: {modes}.",
            (f"Outside treatment for the extensions, by that measure: **{d['outside']}** (median ratio "
             f"{g(d['median_ratio'])}). SSLPV's own default stays the paper's (vacuum)." if d["outside"] != "vacuum"
             else "Outside treatment for the extensions, by that measure: **vacuum**, the paper's: no treatment has a "
                  "median ratio below 1 on this suite, so none is made the extensions' default.")]


def _yes(ok):
    return "**yes**" if ok else "no"


def _budget_rows(b):
    """One judged budget of the target as ``[budget, target, needed, value, met]`` rows."""
    from harness.study.target import RELMSE_FACTOR

    name = b["budget"]
    if "why" in b:
        return [[name, "–", "–", b["why"], "no"]]
    rows = []
    for gr in b["groups"]:
        out = ", ".join(f"{x['scene']} {g(x['energy_ratio'])}" + (" (missing)" if x["source"] == "missing" else "")
                        for x in gr["outside"])
        value = f"{gr['in_range']} in range" + (f"; outside: {out}" if out else "") if gr["of"] else "no scene"
        rows.append([name, f"energy: {gr['group']}", f"{gr['need']} of {gr['of']}", value, _yes(gr["met"])])
    r = b["relmse"]
    need = (f"≤ {g(r['limit'])} ({g(RELMSE_FACTOR)} × {r['baseline']} {g(r['baseline_median'])})"
            if r["limit"] is not None else "no scalar calibration to compare")
    rows.append([name, "median held-out relMSE", need, g(r["median"]), _yes(r["met"])])
    if r.get("in_sample") is not None and r["limit"] is not None:
        rows.append([name, "median in-sample relMSE: the same calibration fitted on every scene, each rendered "
                     "with it; above the limit, the form misses even on the scenes it saw; below, the held-out "
                     "excess over it is the generalisation to an unseen scene", f"≤ {g(r['limit'])}",
                     g(r["in_sample"]), "within" if r["in_sample"] <= r["limit"] else "**above**"])
    fl = r.get("floor")
    if fl is not None and r["limit"] is not None:
        varying = ", ".join(fl["varying"]) or "none"
        rows.append([name, "floor of the family: median relMSE, each fitted scene at its own best scales per "
                     f"colour channel (`{fl['file']}`; per scene, one pair: {g(fl['median_scalar'])}); the least "
                     "any calibration of the family can reach, with the scenes whose floor bounds no form (terms "
                     f"that vary on the grid, or a least at the scan's end: {varying}) taken as 0",
                     f"≤ {g(r['limit'])} to be reachable",
                     f"floor {g(fl['median'])}; least {g(fl['bound'])}",
                     "reachable" if fl["bound"] <= r["limit"] else "**out of reach**"])
    return rows


def best_at_budget_table(t):
    """The target's ``best_at_budget`` (:func:`harness.study.target.target`) as ``(intro, rows)``, or ``(None, [])``
    where the winner is also the best at every judged budget: the same rows as :func:`target_table`, per budget for
    the candidate with the lowest median held-out relMSE there."""
    entries = t.get("best_at_budget") or []
    if "why" in t or not entries:
        return None, []
    names = ", ".join(f"{e['budget']}: `{e['calibration']}`" + (f" ({e['label']})" if "label" in e else "")
                      for e in entries)
    intro = ("The same target for the calibration with the lowest median held-out relMSE at one budget alone, where "
             f"that is not the best over every budget ({names}; `selection.json` ranks every candidate at each "
             "budget). A calibrated file carries one set of renderer settings, so this is the best the committed "
             "calibrations reach at that budget, not a mapping the selection could combine with the winner.")
    rows = []
    for e in entries:
        rows += [[e["budget"], "–", "–", e["why"], "no"]] if "why" in e else _budget_rows(e["judged"])
    return intro, rows


def _other_grids_text(t):
    """The selection's ranking at the other grids its winner holds (``selection.json``'s ``other_grids``), as a
    sentence; empty where it has none."""
    parts = []
    for o in t.get("other_grids") or []:
        lead = o["candidates"][0]
        mine = o["candidates"][o["winner_rank"] - 1]
        parts.append(f"at N = {o['grid']} it ranks {o['winner_rank']} of {len(o['candidates'])} (score "
                     f"{g(mine['score'])})" + ("" if o["winner_rank"] == 1 else
                                               f", behind `{lead['folder']}` ({g(lead['score'])})"))
    if not parts:
        return ""
    return (f" The selection ranks at N = {t['grid']}; by the same rule (Eq. S1 of `harness/calibration/select.py`) over the "
            "candidates that hold another grid, " + "; ".join(parts) + ": a render at that grid may take the leader "
            "there instead.")


def target_table(t):
    """The calibration target (:func:`harness.study.target.target`) as ``(intro, rows, verdict)``: ``rows`` are
    ``[budget, target, needed, value, met]`` text cells; ``intro`` is None when no target was judged."""
    from harness.study.target import ENERGY_RANGE, RELMSE_FACTOR, SPARE

    if "why" in t:
        return None, [], f"The calibration target is not judged: {t['why']}."
    lo, hi = ENERGY_RANGE
    intro = (f"The best committed calibration (`{t['selection']}` names "
             f"`{t['calibration']}`, the study's {t['label']}), held out, at the budgets below "
             "(`harness/study/target.py`): energy ratio (subsurface) in "
             f"[{g(lo)}, {g(hi)}] on all but {SPARE} of the index-matched scenes it was fitted on (as its own "
             "leave-one-scene-out validation rendered them), on every dielectric scene and on every back-lit "
             "homogeneous scene it was not fitted on (the study's renders of the committed file); and a median "
             f"held-out relMSE at most {g(RELMSE_FACTOR)} × the lowest among the selection's scalar calibrations."
             + _other_grids_text(t))
    rows = [r for b in t["budgets"] for r in _budget_rows(b)]
    verdict = f"Target met at every budget: {_yes(t['met'])}. Where a scene misses, *What limits SSLPV here* gives the measured decomposition."
    floors = [(b["budget"], b["relmse"]) for b in t["budgets"] if "why" not in b and b["relmse"].get("floor")
              and b["relmse"]["limit"] is not None]
    out = [name for name, r in floors if r["floor"]["bound"] > r["limit"]]
    if out:
        verdict += (f" The relMSE target is out of reach for the best's family at {', '.join(out)}: even each scene at "
                    "its own best scales per channel leaves a median above the limit, so no calibration of that mapping "
                    "and those settings meets it there.")
    split = [(b["budget"], b["relmse"]) for b in t["budgets"] if "why" not in b and not b["relmse"]["met"]
             and b["relmse"].get("in_sample") is not None and b["relmse"]["limit"] is not None]
    form = [name for name, r in split if r["in_sample"] > r["limit"]]
    unseen = [name for name, r in split if r["in_sample"] <= r["limit"]]
    if form:
        verdict += (f" At {', '.join(form)} the best misses the relMSE limit even in sample, fitted on every scene: "
                    "its form, not its generalisation, is what misses there.")
    if unseen:
        verdict += (f" At {', '.join(unseen)} it meets the relMSE limit in sample and misses it held out: what it "
                    "lacks there is generalisation to a scene it was not fitted on.")
    if floors and len(out) < len(floors):
        verdict += (" Where the floor lies below the limit, what separates the best from it is the form and its "
                    "generalisation to a scene it was not fitted on (each scene's floor beside its held-out figure, below).")
    return intro, rows, verdict
