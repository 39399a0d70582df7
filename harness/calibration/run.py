"""``sslpv-harness calibrate``: fit a mapping family's free parameters to the references, per budget.

For a family (:mod:`harness.calibration.families`) and budgets ``(N, steps)`` it

1. **scans**: renders every scene at ``points`` log-spaced ``sigma_scale`` values
   (:class:`~harness.calibration.scan.Scanner`; for one ``N`` all integer step counts
   come from one propagation, ``steady`` is a direct solve);
2. **fits**, per budget, the loss of :mod:`harness.calibration.fit` (Eq. C2: the mean over
   scenes of ln relMSE of the subsurface image against the reference) over
   ``(sigma_scale, radiance_scale)`` with ``scipy.optimize``, then renders the optimum and
   refits until the fitted ``sigma_scale`` moves by less than 1 % (the figures reported
   for a fit are those of a direct render at its optimum, never of the interpolation);
3. **validates**: leave-one-scene-out (each scene judged at the parameters fitted on the
   others, rendered), the per-scene *oracle* (each scene fitted on itself, rendered: how
   far off even the best setting of the family stays), and standard errors from refitting
   against the reference's two independent halves (Eq. C3);
4. **compares** with the fixed mappings ``literal``, ``collision`` and ``diffusion``
   (:data:`~harness.calibration.families.COMPARED`) at the same budgets;
5. **writes**, atomically (the folder appears complete or not at all): ``calibrated.toml``
   (the mapping: ``--mapping calibrated:DIR/calibrated.toml``), ``calibration.json``
   (every figure), ``index.html`` with its plots (:mod:`harness.calibration.page`) and
   ``floor.json``, the family's floor from the same scan (:mod:`harness.calibration.floor`).

References are never rendered here: a scene without one at the calibration's size is an
error naming the command that renders it. The default size is each scene's committed
small reference (``baselines/refs/``).
"""

from __future__ import annotations

import json
import math
import statistics
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from harness.calibration.families import COMPARED, family as get_family
from harness.calibration.fit import best_scale, fit, fit_refined, halves_se
from harness.calibration.scan import Scanner, budget_label
from harness.errors import InputError

__all__ = ["run_calibrate", "parse_budgets", "ENERGY_TARGET", "RELMSE_TARGET_FACTOR"]

#: The issue's targets for the held-out calibrated mapping.
ENERGY_TARGET = (0.8, 1.25)
RELMSE_TARGET_FACTOR = 0.5           # median held-out relMSE <= this x the better of literal and collision
#: Refit until the fitted sigma_scale moves by less than this (in ln s), at most ROUNDS times.
U_TOL, ROUNDS = 0.01, 4
DEFAULT_STEPS = (8, 16, 32, 64, "steady")
DEFAULT_GRIDS = (32,)


# ----------------------------------------------------------------------------- inputs

def parse_budgets(grids, steps):
    """``--grid 32`` and ``--steps 8,16,steady`` -> validated ``[(N, steps), ...]``."""
    from sslpv_gl.params import SSLPVParams

    out = []
    for N in grids:
        for k in steps:
            if k == "auto":
                raise InputError("--steps", "steps", "'auto' is not a budget (its step count varies per render)",
                                 "use step counts and/or 'steady'")
            SSLPVParams(N=N, steps=k, skip=0)                        # the one validation of N and steps
            out.append((N, k))
    if len(set(out)) != len(out):
        raise InputError("--steps", "steps", "a budget appears twice", "list each step count once")
    return out


def _sigma_values(sigma_range, points):
    from sslpv_gl.calibrated import SCALE_RANGE

    lo, hi = sigma_range
    for name, v in (("min", lo), ("max", hi)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and SCALE_RANGE[0] <= v <= SCALE_RANGE[1]):
            raise InputError("--sigma-range", name, f"{v!r} is not a sigma_scale in [{SCALE_RANGE[0]:g}, "
                             f"{SCALE_RANGE[1]:g}]", "give two positive numbers, e.g. 0.0625,64")
    if not lo < hi:
        raise InputError("--sigma-range", "sigma-range", f"min {lo:g} is not below max {hi:g}",
                         "give MIN,MAX with MIN < MAX")
    if isinstance(points, bool) or not isinstance(points, int) or not 5 <= points <= 64:
        raise InputError("--points", "points", f"must be an integer in [5, 64], got {points!r}",
                         "use e.g. 11")
    return [float(x) for x in np.geomspace(lo, hi, points)]


def _scenes(names):
    from harness.scene import list_scenes, load_scene

    if names is None:
        names = [n for n in list_scenes() if load_scene(n).boundary.kind == "index-matched"]
        if len(names) < 2:
            raise InputError("--scenes", "scenes", "the suite has fewer than 2 index-matched scenes",
                             "name at least two scenes")
    names = list(dict.fromkeys(names))
    if len(names) < 2:
        raise InputError("--scenes", "scenes", f"{len(names)} scene given; leave-one-out needs at least 2",
                         "name at least two scenes")
    return names


def _reference(name, size):
    """``(scene at the calibration's size, reference folder)``, never rendering: a missing one is an error."""
    from harness.reference.cache import cache_path, read_reference_meta
    from harness.reference.committed import REF_DIR, find_committed_reference
    from harness.scene import load_scene

    scene = load_scene(name)
    if size is None:                                   # the committed small reference's size
        try:
            meta = json.loads((REF_DIR / scene.name / "reference.json").read_text())
            size = (int(meta["width"]), int(meta["height"]))
        except (OSError, ValueError, KeyError, TypeError):
            raise InputError(REF_DIR / scene.name, "reference", f"scene {name} has no committed small reference",
                             f"run `sslpv-harness baselines regenerate-references --scenes {name}`, or give "
                             "--size WxH of a cached reference") from None
    scene = scene.with_resolution(*size)
    folder = find_committed_reference(scene)
    if folder is None:
        cached = cache_path(scene)
        meta = read_reference_meta(cached)
        if meta is not None and meta.get("content_hash") == scene.content_hash:
            folder = cached
    if folder is None:
        raise InputError(f"--scenes {name}", "reference", f"scene {name} has no reference at "
                         f"{size[0]}x{size[1]} yet (calibrate never renders one)",
                         f"render it with `sslpv-harness reference {name}` (at the scene's own size), or "
                         "calibrate against the committed references (no --size)")
    return scene, folder


# ----------------------------------------------------------------------------- figures

def _figures(image, ref, r):
    """relMSE and energy ratio of ``r * image`` through the registered metrics (harness.metrics)."""
    from harness.metrics import compute

    test = np.asarray(image, np.float64) * r
    return {"relmse": float(compute("relmse", test, ref["subsurface"], ref["mask"]).value),
            "energy_ratio": float(compute("energy_ratio", test, ref["subsurface"], ref["mask"]).value)}


def _noise(ref):
    """Two noise levels of relMSE for a reference: the halves' floor (the harness's convention) and
    ``<se^2 / (R^2 + eps)>`` from the per-pixel standard error (what noise adds to the relMSE of an
    exact image)."""
    from harness.metrics import compute
    from harness.metrics.pixel import RELMSE_EPS

    m = ref["mask"]
    out = {"floor_halves": float(compute("relmse", ref["half_a"], ref["half_b"], m).value)}
    se = ref.get("se")
    if se is not None:
        R = np.asarray(ref["subsurface"], np.float64)[m]
        out["from_se"] = float(np.mean(np.asarray(se, np.float64)[m] ** 2 / (R * R + RELMSE_EPS)))
    return out


# ----------------------------------------------------------------------------- the run

def run_calibrate(family="diffusion", out=None, scenes=None, grids=DEFAULT_GRIDS, steps=DEFAULT_STEPS, size=None,
                  sigma_range=None, points=11, settings=None, progress=True, renderer=None, argv=None, cache=True):
    """Calibrate ``family`` on ``scenes`` at the budgets ``grids x steps`` and write ``out``.

    Returns the summary that ``--json`` prints (paths written, fitted values, targets, times).
    ``settings`` overrides the family's renderer settings (:data:`sslpv_gl.calibrated.SETTINGS`).
    ``cache``: serve and store the renders through the result cache (:func:`harness.runs.cache.open_cache`'s
    argument; :mod:`harness.calibration.scan`), False to render everything.
    """
    from harness.io.atomic import _check_replaceable
    from harness.progress import Progress
    from harness.runs.sweep import load_reference
    from sslpv_gl.calibrated import SETTINGS
    from sslpv_gl.params import SSLPVParams

    t_start = time.perf_counter()
    fam = get_family(family)
    if out is None:
        raise InputError("--out", "out", "is required", "give an output folder")
    out = Path(out)
    _check_replaceable(out)                      # refuse a foreign folder before hours of work
    budgets = parse_budgets(grids, steps)
    s_values = _sigma_values(sigma_range or fam.sigma_range, points)
    fit_settings = {k: getattr(SSLPVParams(), k) for k in SETTINGS}
    fit_settings.update(fam.settings)
    for k, v in (settings or {}).items():
        if k not in SETTINGS:
            raise InputError(f"--{k.replace('_', '-')}", k, "is not a setting a calibration can fix",
                             f"use: {', '.join(SETTINGS)}")
        fit_settings[k] = v
    base = SSLPVParams(mapping=fam.mapping, **fit_settings)

    names = _scenes(scenes)
    scene_objs, refs, ref_dirs = {}, {}, {}
    for n in names:
        scene, folder = _reference(n, size)
        scene_objs[n] = scene
        ref_dirs[n] = str(folder)
        refs[n] = load_reference(folder, (scene.camera.height, scene.camera.width))
    noise = {n: _noise(refs[n]) for n in names}

    if renderer is None:
        from sslpv_gl.renderer import SSLPVRenderer

        renderer = SSLPVRenderer()
    n_groups = sum(1 for N in {N for N, _ in budgets} if any(n == N and isinstance(k, int) for n, k in budgets)) \
        + sum(1 for _, k in budgets if isinstance(k, str))     # GL calls per (scene, sigma_scale)
    planned = len(names) * (len(s_values) * n_groups + 3 * len(budgets)) + len(COMPARED) * len(names) * n_groups
    phases = {}
    with Progress(f"calibrate {fam.name}", total=planned, unit="renders", enabled=progress) as prog:
        from harness.runs.cache import open_cache

        results_cache = open_cache(cache, "calibrate")
        scanner = Scanner(renderer, scene_objs, refs, base, budgets, prog, label=f"{fam.name} family",
                          cache=results_cache)

        # 1. the scan
        t0 = time.perf_counter()
        for n in names:
            for s in s_values:
                scanner.render(n, s)
        phases["scan_s"] = time.perf_counter() - t0

        # 2.-3. fits and validation, per budget
        t0 = time.perf_counter()
        results = {}
        for b in budgets:
            results[budget_label(*b)] = _calibrate_budget(scanner, b, names, refs, prog)
        phases["fit_s"] = time.perf_counter() - t0

        # 4. the fixed mappings at the same budgets
        t0 = time.perf_counter()
        compared, compare_renders, served = {}, 0, scanner.served
        for mapping, over in COMPARED.items():
            cs = Scanner(renderer, scene_objs, refs, base.replace(mapping=mapping, **over), budgets, prog,
                         cache=results_cache)
            for n in names:
                cs.render(n, 1.0)
            compare_renders += cs.renders
            served += cs.served
            for b in budgets:
                compared.setdefault(budget_label(*b), {})[mapping] = {
                    n: (_figures(cs.image(b, n, 1.0), refs[n], 1.0) if cs.image(b, n, 1.0) is not None
                        else {"relmse": None, "energy_ratio": None, "failed": _failure(cs, n, b)})
                    for n in names}
        phases["compare_s"] = time.perf_counter() - t0
    if results_cache is not None:
        results_cache.prune()

    for label, res in results.items():
        res["compared"] = compared[label]
        res["targets"] = _targets(res, compared[label])
        res["limits"] = _limits(res, compared[label])
    wall = time.perf_counter() - t_start
    info = {
        "format": "sslpv-calibration-report", "family": fam.name, "mapping": fam.mapping, "doc": fam.doc,
        "settings": fit_settings, "scenes": names, "references": ref_dirs,
        "sizes": {n: [scene_objs[n].camera.width, scene_objs[n].camera.height] for n in names},
        "content_hashes": {n: scene_objs[n].content_hash for n in names},
        "sigma_scan": s_values, "budgets": [list(b) for b in budgets], "noise": noise,
        "loss": "mean over scenes of ln relMSE(subsurface), relMSE eps 1e-2, over the reference's mask (Eq. C2 "
                "of harness.calibration.fit)",
        "results": results, "compared_settings": COMPARED,
        "render_failures": [list(f) for f in scanner.failures],
        "renders": scanner.renders + compare_renders, "served_from_cache": served,
        "render_seconds": scanner.seconds,
        "time": dict(phases, wall_s=wall), "gl_renderer": renderer.gl_renderer,
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "command": "sslpv-harness " + " ".join(argv) if argv else None,
    }
    from harness.calibration.floor import floor_info

    floor = floor_info(scanner, info, fit_settings, scene_objs, info["command"], wall_s=None)
    _write(out, info, scanner, refs, floor)
    return _summary(out, info)


def _failure(scanner, name, budget):
    for n, b, s, err in scanner.failures:
        if n == name and tuple(b) == tuple(budget):
            return err
    return "no image"


def _direct(scanner, budget, name, s, r, refs):
    img = scanner.image(budget, name, s)
    if img is None:
        return {"relmse": None, "energy_ratio": None, "failed": _failure(scanner, name, budget)}
    return _figures(img, refs[name], r)


def _calibrate_budget(scanner, budget, names, refs, prog):
    prog.log(f"fitting {budget_label(*budget)}")
    f, surrogate = fit_refined(scanner.samples_for(budget, names),
                               lambda s: [scanner.render(n, s, [budget]) for n in names], rounds=ROUNDS, u_tol=U_TOL)
    in_sample = {n: _direct(scanner, budget, n, f.s, f.r, refs) for n in names}
    direct_loss = float(np.mean([math.log(max(v["relmse"], 1e-300)) for v in in_sample.values()
                                 if v["relmse"] is not None]))
    fa, fb = fit(scanner.samples_for(budget, names), "half_a"), fit(scanner.samples_for(budget, names), "half_b")
    se_s, se_r = halves_se(fa, fb)
    loo, oracle = {}, {}
    for n in names:
        others = [m for m in names if m != n]
        g = fit(scanner.samples_for(budget, others))
        scanner.render(n, g.s, [budget])
        loo[n] = dict(_direct(scanner, budget, n, g.s, g.r, refs), s=g.s, r=g.r, at_bound=g.at_bound)
        o = fit(scanner.samples_for(budget, [n]))
        scanner.render(n, o.s, [budget])
        o_r = math.exp(best_scale([scanner.samples[(budget, n)].coefficients(math.log(o.s))])[0])
        oracle[n] = dict(_direct(scanner, budget, n, o.s, o_r, refs), s=o.s, r=o_r, at_bound=o.at_bound)
    return {"N": budget[0], "steps": budget[1], "sigma_scale": f.s, "radiance_scale": f.r,
            "sigma_scale_se": se_s, "radiance_scale_se": se_r, "at_bound": f.at_bound,
            "loss": direct_loss, "loss_interpolated": surrogate,
            "halves": {"half_a": {"s": fa.s, "r": fa.r}, "half_b": {"s": fb.s, "r": fb.r}},
            "in_sample": in_sample, "held_out": loo, "oracle": oracle}


def _median(values):
    vals = [v for v in values if v is not None]
    return statistics.median(vals) if vals else None


def _targets(res, compared):
    """The issue's two targets for the held-out calibrated mapping at one budget."""
    held = res["held_out"]
    lo, hi = ENERGY_TARGET
    outside = {n: v["energy_ratio"] for n, v in held.items()
               if v["energy_ratio"] is None or not lo <= v["energy_ratio"] <= hi}
    med_held = _median(v["relmse"] for v in held.values())
    med = {m: _median(v["relmse"] for v in compared[m].values()) for m in ("literal", "collision")}
    known = [v for v in med.values() if v is not None]
    better = min(known) if known else None
    return {"energy_range": list(ENERGY_TARGET), "energy_outside": outside, "energy_met": not outside,
            "median_held_out_relmse": med_held, "median_relmse_literal": med["literal"],
            "median_relmse_collision": med["collision"], "relmse_factor": RELMSE_TARGET_FACTOR,
            "relmse_met": (med_held is not None and better is not None
                           and med_held <= RELMSE_TARGET_FACTOR * better)}


def _limits(res, compared):
    """What stops a target, from the measurements: each scene's oracle (the family at its best for that
    scene alone) against its held-out result, and how far apart the scenes' own optima lie."""
    lo, hi = ENERGY_TARGET
    oracle, held = res["oracle"], res["held_out"]
    rows = []
    for n, h in held.items():
        o = oracle[n]
        if h["energy_ratio"] is None or lo <= h["energy_ratio"] <= hi:
            continue
        if o["energy_ratio"] is None or not lo <= o["energy_ratio"] <= hi:
            why = ("the family itself: even fitted on this scene alone its best (sigma_scale "
                   f"{o['s']:.3g}, radiance_scale {o['r']:.3g}) has energy ratio {o['energy_ratio']:.3g}"
                   if o["energy_ratio"] is not None else "the family itself: no oracle image")
        else:
            why = (f"the scenes disagree: alone this scene wants sigma_scale {o['s']:.3g}, radiance_scale "
                   f"{o['r']:.3g} (energy {o['energy_ratio']:.3g}, relMSE {o['relmse']:.3g}); fitted on the others "
                   f"it gets {h['s']:.3g}, {h['r']:.3g}")
        rows.append({"scene": n, "held_out_energy": h["energy_ratio"], "oracle_energy": o["energy_ratio"],
                     "why": why})
    ok = {n: o for n, o in oracle.items() if o["relmse"] is not None}

    def spread(key):
        if not ok:
            return None
        lo_n, hi_n = min(ok, key=lambda n: ok[n][key]), max(ok, key=lambda n: ok[n][key])
        return {"min": ok[lo_n][key], "min_scene": lo_n, "max": ok[hi_n][key], "max_scene": hi_n,
                "at_bound": sorted(n for n, o in ok.items() if o["at_bound"]) if key == "s" else []}

    med = {m: _median(v["relmse"] for v in compared[m].values()) for m in ("literal", "collision")}
    known = [v for v in med.values() if v is not None]
    med_oracle = _median(o["relmse"] for o in ok.values())
    return {"scenes": rows, "oracle_sigma_scale": spread("s"), "oracle_radiance_scale": spread("r"),
            "oracle_energy_outside": {n: o["energy_ratio"] for n, o in ok.items()
                                      if o["energy_ratio"] is None or not lo <= o["energy_ratio"] <= hi},
            "median_oracle_relmse": med_oracle,
            "oracle_relmse_met": (med_oracle is not None and bool(known)
                                  and med_oracle <= RELMSE_TARGET_FACTOR * min(known))}


# ----------------------------------------------------------------------------- output

def calibrated_toml(info):
    """The calibrated mapping file (:mod:`sslpv_gl.calibrated`, version 2) for a calibration's results."""
    from sslpv_gl.calibrated import FORMAT, VERSION

    def val(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, float):
            return repr(v)
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(val(x) for x in v) + "]"
        return str(v)

    lines = [f"# Written by sslpv-harness calibrate on {info['created']}; use it as --mapping calibrated:PATH.",
             f'format = "{FORMAT}"', f"version = {VERSION}", f'family = "{info["mapping"]}"', "",
             "[settings]   # the renderer settings of the fit: a render must use the same"]
    lines += [f"{k} = {val(v)}" for k, v in info["settings"].items()]
    lines += ["", "[fit]", f"loss = {val(info['loss'])}", f"scenes = {val(info['scenes'])}",
              f"sigma_scan = {val([round(s, 6) for s in info['sigma_scan']])}",
              f"gl_renderer = {val(info['gl_renderer'])}", f"created = {val(info['created'])}"]
    if info.get("command"):
        lines.append(f"command = {val(info['command'])}")
    for res in info["results"].values():
        lines += ["", "[[budget]]", f"N = {res['N']}", f"steps = {val(res['steps'])}",
                  f"sigma_scale = {val(float(res['sigma_scale']))}",
                  f"radiance_scale = {val(float(res['radiance_scale']))}",
                  f"sigma_scale_se = {val(float(res['sigma_scale_se']))}",
                  f"radiance_scale_se = {val(float(res['radiance_scale_se']))}",
                  f"loss = {val(float(res['loss']))}"]
        held = _median(v["relmse"] for v in res["held_out"].values())
        if held is not None:
            lines.append(f"loss_held_out = {val(float(math.log(held)))}   # ln of the median held-out relMSE")
    return "\n".join(lines) + "\n"


def _write(out, info, scanner, refs, floor=None):
    from harness.calibration.floor import FILE
    from harness.calibration.page import write_page
    from harness.io.atomic import atomic_dir
    from sslpv_gl.calibrated import load_calibrated
    from sslpv_gl.material import MAPPINGS

    with atomic_dir(out) as tmp:
        (tmp / "calibrated.toml").write_text(calibrated_toml(info))
        load_calibrated(tmp / "calibrated.toml", tuple(MAPPINGS))     # what we write must read back
        (tmp / "calibration.json").write_text(json.dumps(info, indent=1, default=_json_default) + "\n")
        write_page(tmp, info, scanner, refs)
        if floor is not None:                     # the family's floor (harness.calibration.floor), from the same scan
            (tmp / FILE).write_text(json.dumps(floor, indent=1, default=_json_default) + "\n")


def _json_default(obj):
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    return str(obj)


def _summary(out, info):
    budgets = {}
    for label, res in info["results"].items():
        t = res["targets"]
        budgets[label] = {"sigma_scale": res["sigma_scale"], "sigma_scale_se": res["sigma_scale_se"],
                          "radiance_scale": res["radiance_scale"], "radiance_scale_se": res["radiance_scale_se"],
                          "loss": res["loss"], "median_held_out_relmse": t["median_held_out_relmse"],
                          "energy_met": t["energy_met"], "relmse_met": t["relmse_met"]}
    return {"out": str(out), "mapping_file": str(out / "calibrated.toml"), "report": str(out / "index.html"),
            "family": info["family"], "scenes": info["scenes"], "budgets": budgets,
            "renders": info["renders"], "served_from_cache": info.get("served_from_cache", 0),
            "wall_s": info["time"]["wall_s"]}


def print_summary(summary, stream=None):
    """The human-readable table of a calibration (the command's output without --json)."""
    stream = stream or sys.stdout
    lines = [f"calibrated {summary['family']} on {len(summary['scenes'])} scenes in {summary['wall_s']:.0f} s "
             f"({summary['renders']} renders, {summary.get('served_from_cache', 0)} images from the result cache): "
             f"{summary['mapping_file']}",
             f"{'budget':<18} {'sigma_scale':>16} {'radiance_scale':>18} {'held-out relMSE':>16} targets"]
    for label, b in summary["budgets"].items():
        med = b["median_held_out_relmse"]
        lines.append(f"{label:<18} {b['sigma_scale']:9.4g} ±{b['sigma_scale_se']:<6.2g}"
                     f"{b['radiance_scale']:11.4g} ±{b['radiance_scale_se']:<6.2g}"
                     f"{med if med is None else format(med, '16.4g')} "
                     f"energy {'met' if b['energy_met'] else 'NOT met'}, relMSE {'met' if b['relmse_met'] else 'NOT met'}")
    lines.append(f"report: {summary['report']}")
    return "\n".join(lines)
