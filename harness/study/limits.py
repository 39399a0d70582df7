"""What limits SSLPV on each scene, from measured decompositions where the study has the data.

For each scene the *subject* is the best SSLPV setting of the headline (over every SSLPV family of the
headline, the extension families left out, and budget, by the study's first metric). Six decompositions, each present only where measured:

* **steps** (``K`` against ``steady``): the subject's family and settings at ``steady`` against the
  subject at its own K; a paired difference against the scene's reference (delta method), so the
  part of the error that more steps would remove, with its standard error. Absent when the subject
  is itself ``steady`` (then its K-error is nil by construction) or the study has no ``steady`` row.
* **outside** (light that leaves the object and travels through empty cells): the renderer's own
  diagnostic ``outside_share`` (the share of the accumulated energy in cells outside the mesh) of the
  subject, and, where the study rendered the subject with another ``outside`` mode (an extension family,
  :mod:`harness.study.extensions`), that row's error.
* **boundary** (index-matched against dielectric): for each ``[[twins]]`` pair, the subject's family
  and setting on both scenes; a difference of two scenes, so no paired standard error (different
  references): both noise floors are shown instead.
* **speed** (how fast the lattice moves light, ``docs/diffusion_mapping.md`` Sec. 11): over the object's
  cells at the budget's grid, the median of the medium's diffusion coefficient per cell of path,
  ``l_tr / 3`` cells, over the paper's lattice's per step, ``D_lpv(k1)`` (collision mapping); above 1 a
  K-step budget carries about the light of ``K D_lpv / D`` cells of diffusive path, and the steady state's
  diffusion length is ``sqrt(D_lpv / D)`` of the medium's. Beside it, the best row of each ``transport``
  family the study rendered (the extension that matches the two). Computed from the scene's medium (no render).
* **mapping** (calibrated, in-sample against held out): for each calibration of the study whose
  ``calibration.json`` lies beside it, the fit's own in-sample and leave-one-scene-out relMSE at the
  subject's budget, as ``sslpv-harness calibrate`` measured them (not re-rendered by the study); and
  each calibrated family's floor where one was written (``floor.json``, :mod:`harness.calibration.floor`):
  the scene at its own best scales per colour channel, what no calibration of the family beats where the
  scene's terms are uniform (and its least lies inside the scan of ``sigma_scale``). Held out far above the floor: the form's generalisation limits the scene;
  near it: the lattice itself.

* **lighting** (what no calibration of the material can do for this lighting): where
  ``benchmarks/lighting_twin.py`` committed the scene's verdicts (``baselines/lighting_twin/<scene>.json``,
  :func:`harness.study.twin.committed_verdicts`), per budget how many of the renderer's settings can put the
  scene and the same object lit from the other side both in the energy range (Eq. W3), and what a calibration
  that puts the scene in range does to that twin (Eq. W4). Computed by the benchmark, not by the study.

Limits: one subject per scene; a decomposition is reported as "not measured" with the reason when
its data is missing; the steps decomposition compares the same N only.
"""

import json
from pathlib import Path

from harness.metrics.uncertainty import paired_difference
from harness.study.extensions import is_extension
from harness.study.headline import _Images, _rank_value


def _same_but(rows, subject, **change):
    """The row of ``subject``'s scene, method and params except for ``change`` (param -> value), or None."""
    want = dict(json.loads(subject["params_json"]), **change)
    for r in rows:
        if r["scene"] == subject["scene"] and r["method"] == "sslpv" and json.loads(r["params_json"]) == want:
            return r
    return None


def subject_of(rows, scene, metric, budget):
    """The scene's best SSLPV row by ``metric`` within the budgets (None without one)."""
    ks = {str(k) for k in budget["steps"]}
    cand = [r for r in rows if r["scene"] == scene and r["method"] == "sslpv" and r["N"] == budget["grid"]
            and r["K"] in ks]
    return min(cand, key=lambda r: _rank_value(r, metric)) if cand else None


def _steps(rows, subject, images):
    if subject["K"] == "steady":
        return {"measured": False, "why": "the best setting is already the steady state"}
    steady = _same_but(rows, subject, steps="steady")
    if steady is None:
        return {"measured": False, "why": f"the study has no steady-state row of {subject['setting']}"}
    new, old = images.render(steady["render_dir"]), images.render(subject["render_dir"])
    ref = images.reference(subject["reference_dir"], old.shape[:2])
    out = {"measured": True, "steady": steady["setting"], "at": subject["setting"]}
    if ref.get("se") is None:
        out["why"] = "the reference has no standard error: values only"
    for m in ("relmse", "energy_ratio"):
        if ref.get("se") is None:
            out[m] = {"at_k": subject[f"subsurface_{m}"], "steady": steady[f"subsurface_{m}"]}
            continue
        d = paired_difference(m, new, old, ref["subsurface"], ref["se"], ref["mask"], k=ref.get("K"))
        out[m] = {"at_k": d.old, "steady": d.new, "delta": d.delta, "se": d.se}
    return out


def _outside(rows, subject):
    share = subject.get("outside_share")
    out = {"measured": share is not None, "outside_share": share}
    if share is None:
        out["why"] = "the renderer recorded no outside share for this row"
    p = json.loads(subject["params_json"])
    others = []
    from sslpv_gl.boundary import OUTSIDE_MODES

    for mode in OUTSIDE_MODES:
        if mode != p.get("outside"):
            r = _same_but(rows, subject, outside=mode)
            if r is not None:
                others.append({"outside": mode, "setting": r["setting"], "relmse": r["subsurface_relmse"],
                               "energy_ratio": r["subsurface_energy_ratio"]})
    out["other_modes"] = others
    return out


def _boundary(rows, subject, twins):
    found = []
    for t in twins:
        if subject["scene"] not in (t["index_matched"], t["dielectric"]):
            continue
        p = json.loads(subject["params_json"])
        pair = {}
        for role in ("index_matched", "dielectric"):
            r = next((x for x in rows if x["scene"] == t[role] and x["method"] == "sslpv"
                      and json.loads(x["params_json"]) == p), None)
            if r is not None:
                pair[role] = {"scene": t[role], "relmse": r["subsurface_relmse"],
                              "floor": r["subsurface_relmse_floor"], "energy_ratio": r["subsurface_energy_ratio"]}
        if len(pair) == 2:
            found.append(dict(pair, setting=subject["setting"]))
    if not found:
        return {"measured": False, "why": "no index-matched/dielectric twin of this scene in the study"
                if not any(subject["scene"] in (t["index_matched"], t["dielectric"]) for t in twins)
                else "the twin was not rendered at this setting"}
    return {"measured": True, "pairs": found}


def _speed(rows, scene, metric, budget):
    """The lattice's diffusion speed against the medium's on ``scene`` (module docstring), and the transport rows."""
    import numpy as np

    from harness.errors import InputError
    from harness.scene import load_scene
    from harness.scene.geometry import grid_inside
    from sslpv_gl.material import lattice_diffusion, medium_diffusion, resample_medium

    N = int(budget["grid"])
    try:
        sc = load_scene(scene)
    except InputError as exc:
        return {"measured": False, "why": f"the scene does not load here ({exc})"}
    med = sc.medium
    inside = grid_inside(sc.mesh, med.bbox_min, med.bbox_max, N)
    st, al, g = (a[inside] for a in resample_medium(med, N, "box"))
    dx = float(med.bbox_max[0] - med.bbox_min[0]) / N
    D = medium_diffusion(st, al, g, dx)
    ok = np.isfinite(D)
    ratio = D[ok] / lattice_diffusion(st, al, g, dx)[ok]
    out = {"measured": bool(ok.any()), "grid": N, "l_tr_cells": float(np.median(3.0 * D[ok])) if ok.any() else None,
           "ratio": float(np.median(ratio)) if ok.any() else None, "transport": []}
    if not ok.any():
        out["why"] = "the object's cells hold no scattering medium"
    ks = {str(k) for k in budget["steps"]}
    for fam in sorted({r["family"] for r in rows if r["family"].split(" + ")[0] == "transport"}):
        cand = [r for r in rows if r["scene"] == scene and r["family"] == fam and r["N"] == N and r["K"] in ks]
        if cand:
            best = min(cand, key=lambda r: _rank_value(r, metric))
            out["transport"].append({"family": fam, "setting": best["setting"], "relmse": best["subsurface_relmse"],
                                     "energy_ratio": best["subsurface_energy_ratio"]})
    return out


def _mapping(subject, calibrations, budget):
    scene = subject["scene"]
    k = subject["K"] if subject["K"] is not None else None
    key = f"N={subject['N']} steps={k}" if k in {str(s) for s in budget["steps"]} else None
    fits = []
    for cal in calibrations:
        if not cal.get("report"):
            continue
        data = json.loads(Path(cal["report"]).read_text())
        res = (data.get("results") or {}).get(key) if key else None
        if res is None:
            res = (data.get("results") or {}).get(f"N={budget['grid']} steps={budget['steps'][0]}")
        if not res:
            continue
        ins, held = (res.get("in_sample") or {}).get(scene), (res.get("held_out") or {}).get(scene)
        if ins and held:
            fits.append({"family": cal["family"], "label": cal.get("label", f"calibrated {cal['family']}"),
                         "budget": f"N={res['N']} K={res['steps']}", "file": cal["file"],
                         "in_sample": ins["relmse"], "held_out": held["relmse"],
                         "in_sample_energy": ins.get("energy_ratio"), "held_out_energy": held.get("energy_ratio")})
    if not fits:
        return {"measured": False, "why": "no calibration of the study was fitted on this scene"}
    return {"measured": True, "fits": fits, "floors": _floors(scene, calibrations, key or
                                                              f"N={budget['grid']} steps={budget['steps'][0]}")}


def _floors(scene, calibrations, key):
    """The scene's floor (Eq. L1 of :mod:`harness.calibration.floor`) in each calibrated family of the study that
    has one at ``key``, once per floor file."""
    from harness.calibration.floor import bounds, floor_for

    out, seen = [], set()
    for cal in calibrations:
        if not cal.get("report"):
            continue
        entry, path = floor_for(cal["report"], key)
        row = (entry or {}).get("scenes", {}).get(scene)
        if row is None or path.resolve() in seen:
            continue
        seen.add(path.resolve())
        out.append({"family": Path(path).parent.name, "budget": f"N={entry['N']} K={entry['steps']}",
                    "relmse": row["relmse"], "scalar": row["scalar"]["relmse"], "uniform": bool(row.get("uniform")),
                    "bounds": bounds(row),
                    "energy_ratio": row.get("energy_ratio")})
    return out


def limits(rows, scenes, metric, twins, calibrations, budget, images=None):
    """``{scene: {"subject", "steps", "outside", "boundary", "speed", "mapping", "lighting"}}`` (see the module docstring)."""
    images = images or _Images()
    out = {}
    for scene in scenes:
        # the subject is the published method's or a calibration's (the headline's families); the extension
        # rows serve the outside decomposition below
        s = subject_of([r for r in rows if not is_extension(r)], scene, metric, budget)
        if s is None:
            continue
        out[scene] = {"subject": s["setting"], "relmse": s["subsurface_relmse"],
                      "floor": s["subsurface_relmse_floor"], "steps": _steps(rows, s, images),
                      "outside": _outside(rows, s), "boundary": _boundary(rows, s, twins),
                      "speed": _speed(rows, scene, metric, budget), "mapping": _mapping(s, calibrations, budget),
                      "lighting": lighting(scene, budget)}
    return out


def lighting(scene, budget):
    """The committed lighting-twin verdicts of ``scene`` at the study's grid, for its budgets
    (:func:`harness.study.twin.committed_verdicts`)."""
    from harness.scene import load_scene
    from harness.study.twin import VERDICTS, committed_verdicts, no_verdicts

    if not (VERDICTS / f"{scene}.json").is_file():          # the scene is loaded only where a file may judge it
        return {"measured": False, "why": no_verdicts(scene)}
    got = committed_verdicts(load_scene(scene), budget["grid"])
    if got["measured"]:
        steps = {str(b) for b in budget["steps"]}
        got["budgets"] = {k: v for k, v in got["budgets"].items() if k in steps}
    return got
