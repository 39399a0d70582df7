"""Name the best calibrated mapping: the one whose held-out figures are best at a grid.

``sslpv-harness calibrate-best --from DIR... --out OUT [--grid N]`` reads calibrations (folders of
``sslpv-harness calibrate`` or ``calibrate-form``: ``calibrated.toml`` and ``calibration.json``) and
ranks them by what each one's own validation measured, scene left out (``docs/calibration.md``):

* per budget ``(N, K)`` at the grid, the median over scenes of the held-out relMSE (the target's
  quantity, ``targets.median_held_out_relmse``) and the scenes whose held-out energy ratio lies
  outside ``[0.8, 1.25]`` (``targets.energy_outside``);
* the score of a calibration: the geometric mean of its median held-out relMSE over the budgets
  every candidate was fitted for (S1); the lowest score wins.

    score(c) = exp( mean_{b in B} ln median_s relMSE_held_out(c, b, s) ),  B = budgets common to all   (S1)

The winner's ``calibrated.toml`` is copied to ``OUT/calibrated.toml`` under a header that names the
selection, and ``OUT/selection.json`` keeps every candidate's figures; both are written atomically.
The copy renders bit for bit as its source (same settings, same scales; ``--mapping
calibrated:OUT/calibrated.toml``).

Limits:

* Candidates must have been validated on the same scenes (else their held-out medians are not
  comparable): a folder fitted on other scenes is refused.
* The held-out medians carry the references' noise, which the calibration reports as the noise
  floor; a difference in score well below it is not a ranking. ``selection.json`` gives each
  candidate's score, so a near tie can be seen.
* The score weighs every common budget alike; a calibration best at ``steps = steady`` but worse
  at the short budgets can lose.
* The ranking is at one grid. A winner that also holds other grids may rank lower there:
  ``selection.json``'s ``other_grids`` ranks, by (S1) at each such grid, the candidates that hold it
  (``calibrated.toml``'s header names the leader where it is not the winner), so that a render at
  another grid can take that grid's leader instead.
"""

from __future__ import annotations

import json
import math
from datetime import datetime, timezone
from pathlib import Path

from harness.calibration.scan import budget_label
from harness.errors import InputError

__all__ = ["candidate", "select", "write_best"]


def _load(folder):
    folder = Path(folder)
    for name in ("calibrated.toml", "calibration.json"):
        if not (folder / name).is_file():
            raise InputError(folder, name, "is missing",
                             "give a folder written by sslpv-harness calibrate or calibrate-form")
    try:
        cal = json.loads((folder / "calibration.json").read_text())
    except ValueError as e:
        raise InputError(folder / "calibration.json", "file", f"is not JSON ({e.msg})",
                         "give a folder written by sslpv-harness calibrate or calibrate-form") from None
    for key in ("scenes", "budgets", "results"):
        if key not in cal:
            raise InputError(folder / "calibration.json", key, "is missing",
                             "give a folder written by sslpv-harness calibrate or calibrate-form")
    return cal


def candidate(folder, grid, cal=None):
    """One calibration's held-out figures at ``grid`` -> dict (label -> median, energy outside); ``cal``: its
    ``calibration.json`` where already read."""
    folder = Path(folder)
    cal = _load(folder) if cal is None else cal
    budgets = {}
    for N, steps in cal["budgets"]:
        if int(N) != int(grid):
            continue
        label = budget_label(int(N), steps)
        t = cal["results"].get(label, {}).get("targets")
        if not t or t.get("median_held_out_relmse") is None:
            raise InputError(folder / "calibration.json", f"results.{label}.targets.median_held_out_relmse",
                             "is missing", "give a calibration whose held-out validation ran")
        budgets[label] = {"median_held_out_relmse": float(t["median_held_out_relmse"]),
                          "energy_outside": sorted(t.get("energy_outside", {})),
                          "scenes": len(cal["scenes"])}
    return {"folder": str(folder), "family": cal.get("family"), "form": "coefficients" in next(
        iter(cal["results"].values()), {}), "scenes": sorted(cal["scenes"]),
        "settings": cal.get("settings", {}), "budgets": budgets,
        "grids": sorted({int(N) for N, _ in cal["budgets"]})}


def select(folders, grid=32):
    """Rank the calibrations in ``folders`` by (S1) at ``grid`` -> the selection dict (winner first)."""
    if not folders:
        raise InputError("--from", "folders", "none given", "name at least one calibration folder")
    cals = {str(f): _load(f) for f in folders}                   # each calibration.json read once, for every grid
    cands = [candidate(f, grid, cals[str(f)]) for f in folders]
    for c in cands:
        if not c["budgets"]:
            raise InputError(c["folder"], "budgets", f"none at N = {grid}",
                             "give calibrations fitted at that grid, or choose it with --grid")
        if c["scenes"] != cands[0]["scenes"]:
            raise InputError(c["folder"], "scenes", f"fitted on other scenes than {cands[0]['folder']}, so their "
                             "held-out medians are not comparable", "select among calibrations of one scene set")
    common = _rank(cands)
    if not common:
        raise InputError("--from", "budgets", f"the calibrations share no budget at N = {grid}",
                         "select among calibrations fitted for the same budgets")
    return {"format": "sslpv-calibration-selection", "grid": int(grid), "budgets": common,
            "rule": "lowest geometric mean over the common budgets of the median held-out relMSE (Eq. S1 of "
                    "harness.calibration.select)",
            "winner": cands[0]["folder"], "candidates": cands,
            "other_grids": _other_grids(cals, cands[0], grid)}


def _rank(cands):
    """Score every candidate by (S1) over the budgets they all hold and sort them, lowest first, in place ->
    those budgets (empty: none in common, nothing scored)."""
    common = [b for b in cands[0]["budgets"] if all(b in c["budgets"] for c in cands)]
    if common:
        for c in cands:
            logs = [math.log(c["budgets"][b]["median_held_out_relmse"]) for b in common]
            c["score"] = math.exp(sum(logs) / len(logs))
        cands.sort(key=lambda c: c["score"])
    return common


def _held_out_at(folder, grid, cal):
    """:func:`candidate` at ``grid``, or None where a budget there has no held-out validation."""
    try:
        return candidate(folder, grid, cal)
    except InputError:
        return None


def _other_grids(cals, winner, grid):
    """At each other grid the winner holds: (S1) over the candidates (``cals``: folder -> its calibration.json)
    that hold that grid's budgets -> ``[{"grid", "budgets", "leader", "winner_rank", "candidates": [{"folder",
    "score"}]}]``."""
    out = []
    for n in sorted(set(winner["grids"]) - {int(grid)}):
        here = [c for c in (_held_out_at(f, n, cal) for f, cal in cals.items()) if c]
        mine = next((c for c in here if c["folder"] == winner["folder"]), None)
        if mine is None:
            continue                                                # not validated there: nothing to rank
        here = [c for c in here if set(mine["budgets"]) <= set(c["budgets"])]   # on the winner's budgets there
        common = _rank(here)
        if not common:
            continue
        ranked = [c["folder"] for c in here]
        out.append({"grid": n, "budgets": common, "leader": ranked[0],
                    "winner_rank": ranked.index(winner["folder"]) + 1,
                    "candidates": [{"folder": c["folder"], "score": c["score"]} for c in here]})
    return out


def write_best(folders, out, grid=32, command="sslpv-harness calibrate-best"):
    """Select (:func:`select`) and write ``out/calibrated.toml`` and ``out/selection.json`` -> the selection."""
    from harness.io.atomic import _check_replaceable, atomic_dir
    from harness.store.provenance import git_commit
    from sslpv_gl.calibrated import load_calibrated
    from sslpv_gl.material import MAPPINGS

    out = Path(out)
    _check_replaceable(out)
    sel = select(folders, grid)
    win = sel["candidates"][0]
    created = datetime.now(timezone.utc).isoformat(timespec="seconds")
    sel |= {"created": created, "command": command, "commit": git_commit()}
    header = (f"# The best calibrated mapping at N = {grid}, chosen by {command} on {created} from "
              f"{len(folders)} calibrations\n# by {sel['rule']}: {win['folder']} (score {win['score']:.4g}; "
              f"selection.json beside this file ranks them all).\n")
    for o in sel["other_grids"]:
        lead = o["candidates"][0]
        header += (f"# At N = {o['grid']} it ranks {o['winner_rank']} of {len(o['candidates'])} by the same rule"
                   + ("" if o["winner_rank"] == 1 else f"; {lead['folder']} leads there (score {lead['score']:.4g})")
                   + ".\n")
    header += "# Its own file follows unchanged.\n"
    with atomic_dir(out) as tmp:
        (tmp / "calibrated.toml").write_text(header + (Path(win["folder"]) / "calibrated.toml").read_text())
        load_calibrated(tmp / "calibrated.toml", tuple(MAPPINGS))        # what we write must read back
        (tmp / "selection.json").write_text(json.dumps(sel, indent=1) + "\n")
    return sel
