"""The calibration target of the study (harness/study/target.py): which figures it judges, and how.

Synthetic calibration reports and study rows: each test plants the case that one rule decides.
"""

import json

import pytest

from harness.study.present import target_table
from harness.study.target import ENERGY_RANGE, target

BUDGET = {"grid": 32, "steps": [8, 32, "steady"]}
FITTED = [f"im{i}" for i in range(5)]


def _report(held, in_sample=None, steps=(32, "steady")):
    res = {}
    for k in steps:
        res[f"N=32 steps={k}"] = {
            "held_out": {s: {"energy_ratio": e, "relmse": r} for s, (e, r) in held.items()},
            "in_sample": {s: {"energy_ratio": e, "relmse": r} for s, (e, r) in (in_sample or held).items()}}
    return {"scenes": list(held), "results": res}


def _setup(tmp_path, held, in_sample=None, candidates=None, steps=(32, "steady")):
    win = tmp_path / "form"
    win.mkdir()
    (win / "calibrated.toml").write_text("")
    (win / "calibration.json").write_text(json.dumps(_report(held, in_sample, steps)))
    cands = candidates if candidates is not None else [
        {"folder": str(win), "form": True, "budgets": {f"N=32 steps={k}": {"median_held_out_relmse": 0.01}
                                                       for k in steps}},
        {"folder": "scalar_a", "form": False, "budgets": {f"N=32 steps={k}": {"median_held_out_relmse": 0.2}
                                                          for k in steps}},
        {"folder": "scalar_b", "form": False, "budgets": {f"N=32 steps={k}": {"median_held_out_relmse": 0.1}
                                                          for k in steps}}]
    sel = tmp_path / "selection.json"
    sel.write_text(json.dumps({"winner": str(win), "candidates": cands}))
    cals = [{"file": str(win / "calibrated.toml"), "label": "calibrated collision form",
             "report": str(win / "calibration.json")}]
    return sel, cals


def _scenes(extra=()):
    info = {s: {"dielectric": False, "tags": {"homogeneous"}} for s in FITTED}
    info["glass"] = {"dielectric": True, "tags": {"dielectric"}}
    info["backlit"] = {"dielectric": False, "tags": {"homogeneous", "back-lit"}}
    info["front"] = {"dielectric": False, "tags": {"homogeneous"}}          # not fitted, not in the target
    info.update(dict(extra))
    return info


def _row(scene, k, energy, relmse=0.01):
    return {"scene": scene, "family": "calibrated collision form", "N": 32, "K": str(k),
            "subsurface_energy_ratio": energy, "subsurface_relmse": relmse}


def _rows(energy=1.0):
    return [_row(s, k, energy) for s in ("glass", "backlit", "front") for k in (32, "steady")]


def _groups(t, k):
    b = next(b for b in t["budgets"] if b["K"] == str(k))
    return {g["group"]: g for g in b["groups"]}, b


def test_met_when_every_group_is_in_range_and_the_median_is_half(tmp_path):
    sel, cals = _setup(tmp_path, {s: (1.0, 0.04) for s in FITTED})
    t = target(_rows(), cals, BUDGET, _scenes(), selection=sel)
    assert t["met"] is True
    groups, b = _groups(t, 32)
    assert [g["of"] for g in groups.values()] == [5, 1, 1]
    assert groups["index-matched, fitted (held out)"]["need"] == 4
    assert b["relmse"]["baseline"] == "scalar_b"                   # the lowest scalar median, the form left out
    assert b["relmse"]["limit"] == pytest.approx(0.05)
    intro, rows, verdict = target_table(t)
    assert "**yes**" in verdict and len(rows) == 10 and f"`{sel.resolve()}` names" in intro     # 5 rows per budget


def test_the_fitted_scenes_are_judged_held_out_not_in_sample(tmp_path):
    held = {s: (1.0, 0.04) for s in FITTED}
    held["im0"] = held["im1"] = (0.5, 0.04)
    sel, cals = _setup(tmp_path, held, in_sample={s: (1.0, 0.04) for s in FITTED})
    t = target(_rows(), cals, BUDGET, _scenes(), selection=sel)
    g = _groups(t, 32)[0]["index-matched, fitted (held out)"]
    assert g["in_range"] == 3 and g["met"] is False
    assert sorted(x["scene"] for x in g["outside"]) == ["im0", "im1"]
    assert t["met"] is False


def test_one_fitted_scene_may_miss_and_the_range_is_closed(tmp_path):
    held = {s: (1.0, 0.04) for s in FITTED}
    held["im0"] = (2.0, 0.04)
    held["im1"] = (ENERGY_RANGE[0], 0.04)
    held["im2"] = (ENERGY_RANGE[1], 0.04)
    sel, cals = _setup(tmp_path, held)
    t = target(_rows(), cals, BUDGET, _scenes(), selection=sel)
    g = _groups(t, 32)[0]["index-matched, fitted (held out)"]
    assert g["in_range"] == 4 and g["met"] is True


def test_the_scenes_no_fit_saw_are_the_studys_renders_at_the_budget(tmp_path):
    sel, cals = _setup(tmp_path, {s: (1.0, 0.04) for s in FITTED})
    rows = [_row("glass", 32, 0.5), _row("glass", "steady", 1.0), _row("glass", 8, 1.0),
            _row("backlit", 32, 1.0), _row("backlit", "steady", 0.1), _row("front", 32, 3.0)]
    t = target(rows, cals, BUDGET, _scenes(), selection=sel)
    g32, _ = _groups(t, 32)
    gst, _ = _groups(t, "steady")
    assert g32["dielectric"]["met"] is False and g32["dielectric"]["scenes"][0]["energy_ratio"] == 0.5
    assert gst["dielectric"]["met"] is True
    assert g32["back-lit homogeneous, not fitted"]["met"] is True
    assert gst["back-lit homogeneous, not fitted"]["met"] is False
    assert not any(x["scene"] == "front" for gr in g32.values() for x in gr["scenes"])   # not in the target


def test_a_scene_the_study_did_not_render_is_missing_and_fails_its_group(tmp_path):
    sel, cals = _setup(tmp_path, {s: (1.0, 0.04) for s in FITTED})
    t = target([r for r in _rows() if r["scene"] != "glass"], cals, BUDGET, _scenes(), selection=sel)
    d = _groups(t, 32)[0]["dielectric"]
    assert d["scenes"][0]["source"] == "missing" and d["met"] is False
    assert "(missing)" in " ".join(" ".join(r) for r in target_table(t)[1])


def test_a_fitted_dielectric_scene_is_taken_held_out(tmp_path):
    held = {s: (1.0, 0.04) for s in FITTED}
    held["glass"] = (0.3, 0.04)
    sel, cals = _setup(tmp_path, held)
    t = target(_rows(1.0), cals, BUDGET, _scenes(), selection=sel)
    groups, _ = _groups(t, 32)
    assert groups["dielectric"]["scenes"][0]["source"] == "held out"
    assert groups["dielectric"]["met"] is False
    assert groups["index-matched, fitted (held out)"]["of"] == 5


def test_the_relmse_half(tmp_path):
    sel, cals = _setup(tmp_path, {s: (1.0, 0.06) for s in FITTED})
    t = target(_rows(), cals, BUDGET, _scenes(), selection=sel)
    b = _groups(t, 32)[1]
    assert b["relmse"]["median"] == pytest.approx(0.06) and b["relmse"]["met"] is False
    assert t["met"] is False


def test_not_judged_without_the_winner_in_the_study(tmp_path):
    sel, cals = _setup(tmp_path, {s: (1.0, 0.04) for s in FITTED})
    t = target(_rows(), [], BUDGET, _scenes(), selection=sel)
    assert "not one of the study's calibrations" in t["why"]
    assert target_table(t)[0] is None
    assert "missing" in target(_rows(), cals, BUDGET, _scenes(), selection=tmp_path / "none.json")["why"]


def test_a_budget_the_calibration_lacks_is_not_met(tmp_path):
    sel, cals = _setup(tmp_path, {s: (1.0, 0.04) for s in FITTED}, steps=(32,))
    t = target(_rows(), cals, BUDGET, _scenes(), selection=sel)
    b = next(b for b in t["budgets"] if b["budget"] == "N=32 steps=steady")
    assert b["met"] is False and "no budget" in b["why"]
    assert t["met"] is False


def _floor(folder, values, uniform=True, steps=(32, "steady")):
    folder.mkdir(exist_ok=True)
    rows = {s: {"relmse": v, "scalar": {"relmse": 1.5 * v}, "uniform": uniform if isinstance(uniform, bool)
                else s in uniform} for s, v in values.items()}
    (folder / "floor.json").write_text(json.dumps({"budgets": {f"N=32 steps={k}": {"N": 32, "steps": k, "scenes": rows}
                                                               for k in steps}}))


@pytest.mark.parametrize("floor, reach", [(0.02, "reachable"), (0.06, "**out of reach**")])
def test_the_familys_floor_says_whether_the_limit_is_reachable(tmp_path, floor, reach):
    """The floor of the winner's source (floor.json beside it, found through the form's ``sources``) is a row of
    the table; its least median over the fitted scenes decides whether the relMSE limit (0.05 here) is reachable."""
    sel, cals = _setup(tmp_path, {s: (1.0, 0.08) for s in FITTED})
    report = json.loads((tmp_path / "form" / "calibration.json").read_text())
    report["sources"] = [str(tmp_path / "scalar")]
    (tmp_path / "form" / "calibration.json").write_text(json.dumps(report))
    _floor(tmp_path / "scalar", {s: floor for s in FITTED})
    t = target(_rows(), cals, BUDGET, _scenes(), selection=sel)
    _, b = _groups(t, "steady")
    fl = b["relmse"]["floor"]
    assert fl["median"] == pytest.approx(floor) and fl["bound"] == pytest.approx(floor) and fl["varying"] == []
    assert fl["median_scalar"] == pytest.approx(1.5 * floor)
    _, rows, verdict = target_table(t)
    got = [r for r in rows if r[1].startswith("floor of the family")]
    assert len(got) == 2 and all(r[4] == reach for r in got)
    assert ("out of reach for the best's family at N=32 steps=32, N=32 steps=steady" in verdict) == (floor > 0.05)


def test_the_floor_bound_takes_scenes_whose_terms_vary_as_zero(tmp_path):
    """Three of five fitted scenes vary on the grid: a form may beat their floor, so the least median is the
    median of (0, 0, 0, floor, floor): reachable although every floor is above the limit."""
    sel, cals = _setup(tmp_path, {s: (1.0, 0.08) for s in FITTED})
    _floor(tmp_path / "form", {s: 0.3 for s in FITTED}, uniform=set(FITTED[:2]))
    t = target(_rows(), cals, BUDGET, _scenes(), selection=sel)
    _, b = _groups(t, 32)
    fl = b["relmse"]["floor"]
    assert fl["median"] == pytest.approx(0.3) and fl["bound"] == 0.0 and fl["varying"] == FITTED[2:]
    assert target_table(t)[1][-1][4] == "reachable"


def test_a_fitted_scene_without_a_floor_row_counts_as_zero(tmp_path):
    """Two of five fitted scenes have no floor row (too few usable samples): they cannot bound anything, so the least
    median is that of (0, 0, f, f, f)."""
    sel, cals = _setup(tmp_path, {s: (1.0, 0.08) for s in FITTED})
    _floor(tmp_path / "form", {s: 0.3 for s in FITTED[:3]})
    t = target(_rows(), cals, BUDGET, _scenes(), selection=sel)
    _, b = _groups(t, 32)
    fl = b["relmse"]["floor"]
    assert fl["median"] == pytest.approx(0.3) and fl["bound"] == pytest.approx(0.3)
    assert fl["varying"] == FITTED[3:] and (fl["scenes"], fl["of"]) == (3, 5)
    _floor(tmp_path / "form", {s: 0.3 for s in FITTED[:2]})
    fl = _groups(target(_rows(), cals, BUDGET, _scenes(), selection=sel), 32)[1]["relmse"]["floor"]
    assert fl["bound"] == 0.0


@pytest.mark.parametrize("inside, verdict", [(0.02, "within"), (0.07, "**above**")])
def test_the_in_sample_median_splits_form_from_generalisation(tmp_path, inside, verdict):
    """Beside the held-out median, the in-sample one (the fit on every scene): its row says whether the form misses
    the limit (0.05 here) even on the scenes it saw; the target itself stays the held-out median's."""
    held = {s: (1.0, 0.08) for s in FITTED}
    in_sample = {s: (1.0, inside + 0.001 * i) for i, s in enumerate(FITTED)}
    sel, cals = _setup(tmp_path, held, in_sample=in_sample)
    t = target(_rows(), cals, BUDGET, _scenes(), selection=sel)
    _, b = _groups(t, 32)
    assert b["relmse"]["in_sample"] == pytest.approx(inside + 0.002) and b["relmse"]["met"] is False
    _, rows, said = target_table(t)
    got = [r for r in rows if r[1].startswith("median in-sample relMSE")]
    assert len(got) == 2 and all(r[4] == verdict for r in got)
    both = "N=32 steps=32, N=32 steps=steady"
    assert (f"At {both} the best misses the relMSE limit even in sample" in said) == (inside > 0.05)
    assert (f"At {both} it meets the relMSE limit in sample and misses it held out" in said) == (inside < 0.05)


def _second(tmp_path, held, steady_median, k32_median=0.5):
    """A second calibration of the study, ``other``, with its own report and label; its candidate's medians."""
    other = tmp_path / "other"
    other.mkdir()
    (other / "calibrated.toml").write_text("")
    (other / "calibration.json").write_text(json.dumps(_report(held)))
    cal = {"file": str(other / "calibrated.toml"), "label": "calibrated collision (interior)",
           "report": str(other / "calibration.json")}
    cand = {"folder": str(other), "form": True, "budgets": {"N=32 steps=32": {"median_held_out_relmse": k32_median},
                                                            "N=32 steps=steady": {"median_held_out_relmse":
                                                                                  steady_median}}}
    return cal, cand


def test_the_best_at_one_budget_alone_is_judged_where_it_is_not_the_winner(tmp_path):
    """A candidate with a lower median than the winner at the steady state only is judged there, from its own
    calibration.json and the study's rows under its own label; at K = 32, where the winner is lowest, nothing."""
    from harness.study.present import best_at_budget_table

    sel, cals = _setup(tmp_path, {s: (1.0, 0.04) for s in FITTED})
    held = {s: (1.0, 0.02) for s in FITTED}
    held["im0"] = held["im1"] = (0.3, 0.02)                     # two fitted scenes out: its group is not met
    cal, cand = _second(tmp_path, held, steady_median=0.005)
    data = json.loads(sel.read_text())
    data["candidates"].append(cand)
    sel.write_text(json.dumps(data))
    rows = _rows() + [dict(_row(s, k, 1.1), family=cal["label"]) for s in ("glass", "backlit") for k in (32, "steady")]
    t = target(rows, cals + [cal], BUDGET, _scenes(), selection=sel)
    assert [e["budget"] for e in t["best_at_budget"]] == ["N=32 steps=steady"]
    e = t["best_at_budget"][0]
    assert e["calibration"] == str(tmp_path / "other") and e["label"] == cal["label"]
    groups = {g["group"]: g for g in e["judged"]["groups"]}
    assert groups["index-matched, fitted (held out)"]["in_range"] == 3 and e["judged"]["met"] is False
    assert groups["dielectric"]["scenes"][0]["energy_ratio"] == 1.1          # the study's render of its own file
    assert e["judged"]["relmse"]["median"] == pytest.approx(0.02)
    assert t["met"] is True                                     # the winner's own verdict is unchanged
    intro, table = best_at_budget_table(t)
    assert "`" + str(tmp_path / "other") + "`" in intro and len(table) == 5
    assert all(r[0] == "N=32 steps=steady" for r in table)


def test_no_best_at_one_budget_where_the_winner_is_lowest_or_the_study_lacks_it(tmp_path):
    from harness.study.present import best_at_budget_table

    sel, cals = _setup(tmp_path, {s: (1.0, 0.04) for s in FITTED})
    t = target(_rows(), cals, BUDGET, _scenes(), selection=sel)
    assert t["best_at_budget"] == [] and best_at_budget_table(t) == (None, [])
    _, cand = _second(tmp_path, {s: (1.0, 0.02) for s in FITTED}, steady_median=0.005)
    data = json.loads(sel.read_text())
    data["candidates"].append(cand)
    sel.write_text(json.dumps(data))
    t = target(_rows(), cals, BUDGET, _scenes(), selection=sel)           # the study did not render `other`
    assert t["best_at_budget"] == [{"budget": "N=32 steps=steady", "calibration": str(tmp_path / "other"),
                                    "why": f"{tmp_path / 'other'} is not one of the study's calibrations"}]
    intro, table = best_at_budget_table(t)
    assert table == [["N=32 steps=steady", "–", "–", t["best_at_budget"][0]["why"], "no"]]


def test_the_winners_rank_at_other_grids_is_said_beside_the_target(tmp_path):
    """``selection.json``'s ``other_grids`` reaches the target's intro: the winner's rank and score at each other
    grid, and the leader there where it is not the winner; no sentence without other grids."""
    sel, cals = _setup(tmp_path, {s: (1.0, 0.04) for s in FITTED})
    assert "ranks" not in target_table(target(_rows(), cals, BUDGET, _scenes(), selection=sel))[0]
    data = json.loads(sel.read_text())
    win = data["winner"]
    data["other_grids"] = [{"grid": 64, "budgets": ["N=64 steps=32"], "leader": "lead", "winner_rank": 2,
                            "candidates": [{"folder": "lead", "score": 0.03}, {"folder": win, "score": 0.09}]}]
    sel.write_text(json.dumps(data))
    intro = target_table(target(_rows(), cals, BUDGET, _scenes(), selection=sel))[0]
    assert "at N = 64 it ranks 2 of 2 (score 0.09), behind `lead` (0.03)" in intro
