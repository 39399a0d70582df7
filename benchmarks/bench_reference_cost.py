"""The reference cost model: fit it on the committed references and a family of spheres, validate it
leave-one-scene-out, and check it on real scenes.

``--fit`` reads what exists: every committed small reference (``baselines/refs/<scene>/
reference.json``: its pilot, its rounds, its samples, seconds and median relative SE, and
how it was rendered: passes, Russian roulette depth, integrator, absorber pass) and the
``family`` points of ``harness/reference/cost_model.json`` (32x32 homogeneous spheres,
rendered by ``--measure-family``). It fits the model of ``harness/reference/cost.py``,
then refits it 14 times, each time without one suite scene, and predicts that scene's
samples and wall time to its target from the others (leave-one-scene-out). It writes the
model (with the LOO rows) to ``cost_model.json`` and the table to ``docs/reference_cost.md``.

``--measure-family`` renders the family (``sphere_homogeneous``'s mesh, camera and light at
32x32, 8 seeds x ``--spp``; a grid of sigma_t, albedo and g) and stores the points in
``cost_model.json``. Its seconds carry the machine's load at the time; its noise does not.

``--pilot [SCENE ...]`` sets the render's own pilot beside the cost model on each suite scene: the
prediction after the pilot's first round (logged within the first minute), after the whole pilot,
and the measured final render; it writes ``docs/reference_pilot.md``.

``--check SCENE[:WxH|:committed] ...`` compares ``reference --estimate`` (today's integrator
choices) with a real render's wall time, or with the committed reference's.

Usage::

    .venv/bin/python benchmarks/bench_reference_cost.py --fit                 # seconds, renders nothing
    .venv/bin/python benchmarks/bench_reference_cost.py --measure-family      # about 3 minutes on 2 cores
    .venv/bin/python benchmarks/bench_reference_cost.py --check marble_sphere:committed
    .venv/bin/python benchmarks/bench_reference_cost.py --pilot                # minutes: renders the cheap scenes
"""

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from harness.reference import cost  # noqa: E402
from harness.reference.mitsuba_scene import integrator_blocks  # noqa: E402
from harness.scene import load_scene  # noqa: E402

DOC = ROOT / "docs" / "reference_cost.md"
FAMILY_WEIGHT = 0.25       # a family point against a suite scene's 1
FAMILY_GRID = [(st, a, 0.0) for st in (1.5, 6.0, 24.0, 96.0, 192.0) for a in (0.6, 0.9, 0.99, 0.999)] + \
              [(st, a, g) for g in (0.5, 0.9) for st in (6.0, 24.0) for a in (0.9, 0.99)]


# --------------------------------------------------------------------------- the data

def todays_choice(scene, summ):
    """The passes and Russian roulette depths today's renderer would choose for ``scene``."""
    from harness.reference import mitsuba_scene as ms

    split = ms.channel_passes(scene.medium) != (None,)
    amax = summ["albedo_max"]
    return (3 if split else 1), ([ms.rr_depth_for(a) for a in amax] if split else [ms.rr_depth_for(max(amax))])


def ref_entry(meta, summ, cores_model, today=None):
    """A committed reference's row (how it WAS rendered), time points and noise point; ``today``: the
    (passes, rr_depths) today's renderer would choose, to flag references rendered with other choices."""
    per_pass = integrator_blocks(meta["integrator"])
    row = cost.scene_row(summ, covered=meta["covered_pixels"], passes=len(per_pass),
                         absorber=bool(meta.get("seeds_absorber")), integrator=per_pass[0]["type"],
                         rr_depth=[p["rr_depth"] for p in per_pass], dielectric=meta.get("boundary") != "index-matched")
    P, passes = meta["covered_pixels"], row["passes"]
    pilot = meta["pilot"]
    pilot_spp = pilot["K"] * pilot["spp"]
    # On a cluster the jobs' seconds are summed over workers of ``drjit_threads`` threads each: divide by the
    # model machine's cores for the seconds of a serial render with all of them.
    threads = (meta.get("drjit_threads") or [cores_model])[0]
    scale = threads / cores_model if meta.get("executor", "serial") != "serial" else 1.0
    n_rounds = len(meta["rounds"])
    pilot_jobs = pilot["K"] * (2 if "early" in pilot else 1)    # a two-round pilot renders two jobs per seed
    times = [dict(row, seconds=pilot["seconds"], jobs=pilot_jobs * passes, renders=passes, samples=pilot_spp * P * passes,
                  weight=0.5),
             dict(row, seconds=meta["render_seconds"] * scale, jobs=(pilot_jobs + meta["K"] * n_rounds) * passes,
                  renders=passes,
                  samples=(pilot_spp + meta["spp_total"]) * P * passes, weight=0.5)]
    noise = dict(row, v=meta["median_rel_se_subsurface"] ** 2 * meta["spp_total"], weight=1.0)
    return {"scene": meta["scene"], "row": row, "time": times, "noise": noise, "target": meta["target_rel_se"],
            "rounds": n_rounds, "K": meta["K"], "spp_total": meta["spp_total"], "wall": meta["wall_seconds"],
            "overhead": meta["wall_seconds"] - meta["render_seconds"] * scale,
            "executor": meta.get("executor", "serial"),
            "pilot_predicted": pilot.get("predicted_wall_seconds"),
            "changed": today is not None and (today[0] != len(per_pass) or
                                              list(today[1]) != [p["rr_depth"] for p in per_pass])}


def family_entries(points):
    out = []
    for p in points:
        summ = {"tau": [p["tau"]] * 3, "albedo": [p["albedo"]] * 3, "albedo_max": [p["albedo"]] * 3,
                "g": p.get("g", 0.0), "cv": 0.0}
        row = cost.scene_row(summ, covered=p["covered_pixels"], passes=1, absorber=False, integrator="volpath",
                             rr_depth=[p["rr_depth"]], dielectric=False, family=True)
        t = [dict(row, seconds=p["render_s"], jobs=8, renders=1, samples=p["spp_total"] * p["covered_pixels"],
                  weight=FAMILY_WEIGHT)] if "render_s" in p and p.get("use_time", True) else []
        out.append({"time": t, "noise": dict(row, v=p["v"], weight=FAMILY_WEIGHT)})
    return out


#: The suite's references rendered to their targets by ``--pilot --full-below inf`` on one machine, at
#: one commit, with today's integrator choices: their ``reference.json`` metadata, which ``--fit`` uses
#: in place of the committed references' (rendered over weeks, under other loads and other choices).
MEASURED = ROOT / "harness" / "reference" / "cost_suite.json"


def measured_metas():
    """``{scene: reference.json}`` of :data:`MEASURED` (``{}`` when absent) and its header."""
    if not MEASURED.is_file():
        return {}, {}
    data = json.loads(MEASURED.read_text())
    return data.get("refs", {}), {k: v for k, v in data.items() if k != "refs"}


def load_refs(cores_model):
    """One entry per suite scene: its reference measured by ``--pilot`` where there is one, else the
    committed reference's metadata."""
    from harness.reference.committed import REF_DIR

    measured, _ = measured_metas()
    entries = []
    for f in sorted(Path(REF_DIR).glob("*/reference.json")):
        meta = json.loads(f.read_text())
        meta = measured.get(meta["scene"], meta)
        scene = load_scene(meta["scene"])
        summ = cost.medium_summary(scene)
        entries.append(ref_entry(meta, summ, cores_model, todays_choice(scene, summ)))
    return entries


# --------------------------------------------------------------------------- fit and validation

def fit_all(entries, family):
    tpts = [p for e in entries + family for p in e["time"]]
    npts = [e["noise"] for e in entries + family]
    c_job, c_render, tcoef, trms = cost.fit_time(tpts)
    ncoef, nrms = cost.fit_noise(npts)
    overhead = float(np.median([e["overhead"] for e in entries if e["executor"] == "serial"]))
    return {"time": {"c_job": c_job, "c_render": c_render, "coef": tcoef.tolist(), "rms_log": trms},
            "noise": {"coef": ncoef.tolist(), "rms_log": nrms}, "overhead_s": {"serial": overhead}}


def predict_entry(model, e, cores_model):
    spp, _, _, render_s = cost.predict_run(model, e["row"], e["target"], K=e["K"], rounds=e["rounds"])
    return spp, render_s + model["overhead_s"]["serial"]


def validate(entries, family, cores_model):
    """Rows per scene: in-sample and leave-one-scene-out predictions of spp and wall seconds."""
    full = fit_all(entries, family)
    rows = []
    for i, e in enumerate(entries):
        loo = fit_all(entries[:i] + entries[i + 1:], family)
        spp_in, s_in = predict_entry(full, e, cores_model)
        spp_loo, s_loo = predict_entry(loo, e, cores_model)
        rows.append({"scene": e["scene"], "target": e["target"], "spp_measured": e["spp_total"],
                     "seconds_measured": e["wall"], "executor": e["executor"], "spp_in": spp_in, "seconds_in": s_in,
                     "spp_loo": spp_loo, "seconds_loo": s_loo, "factor_in": factor(s_in, e["wall"]),
                     "factor_loo": factor(s_loo, e["wall"]), "spp_factor_loo": factor(spp_loo, e["spp_total"]),
                     "per_spp_factor_loo": factor(s_loo / spp_loo, e["wall"] / e["spp_total"]),
                     "pilot_factor": factor(e["pilot_predicted"], e["wall"]) if e["pilot_predicted"] else None,
                     "integrator_changed": e["changed"]})
    return full, rows


def factor(pred, meas):
    """Signed factor error: ``pred / meas`` when over, ``-(meas / pred)`` when under."""
    r = pred / meas
    return float(r if r >= 1 else -1.0 / r)


def write_doc(rows, model, command, path=DOC):
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                            text=True).stdout.strip() or "unknown"
    dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", ".",
                            ":!docs/reference_cost.md", ":!harness/reference/cost_model.json"], cwd=ROOT,
                           capture_output=True, text=True).stdout.strip()
    n2 = sum(abs(r["factor_loo"]) <= 2 for r in rows)
    measured, hdr = measured_metas()
    lines = ["# Reference cost model: leave-one-scene-out validation",
             "", f"Written by `{command}` at commit `{commit}`{' (with uncommitted changes)' if dirty else ''}, "
             f"{model['fitted']}. Do not edit by hand.", "",
             "Model: `harness/reference/cost.py` (its docstring states the form, the features and the limits). " +
             (f"Measured: each suite scene's small reference rendered to its target, serially, with today's "
              f"integrator choices, by `{hdr.get('command')}` at commit `{hdr.get('commit')}` on "
              f"{hdr.get('cores')} cores, last updated {hdr.get('updated')} "
              f"(`harness/reference/cost_suite.json`: {len(measured)} scenes); "
              if measured else "") +
             "where a scene has no such measurement, the committed small reference's wall time to its target "
             "and its samples (`baselines/refs/<scene>/reference.json`), rendered with the integrator choices "
             "recorded there; each prediction below uses the choices its measurement recorded. "
             "LOO: fitted without the scene, "
             "on the 13 others and the 32x32 family. Factor: predicted / measured, negative when under "
             "(-2.0 = half the measured).", "",
             f"Within a factor of 2 (LOO): {n2} of {len(rows)} scenes. Time model RMS log error "
             f"{model['time']['rms_log']:.2f} (x{np.exp(model['time']['rms_log']):.2f}), per-job cost "
             f"{model['time']['c_job']:.3g} s, per-render (kernel compilation) cost {model['time']['c_render']:.3g} s; noise model RMS {model['noise']['rms_log']:.2f} "
             f"(x{np.exp(model['noise']['rms_log']):.2f}), in-sample.", "",
             "| scene | target | measured spp | LOO spp | spp factor | measured s | LOO s | LOO factor "
             "| s/spp factor | in-sample s | in-sample factor | pilot's factor | rendered with other choices "
             "than today's |", "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        pf = f"{r['pilot_factor']:+.1f}" if r.get("pilot_factor") else "not recorded"
        lines.append(f"| {r['scene']} | {r['target']:.1%} | {r['spp_measured']} | {r['spp_loo']} | "
                     f"{r['spp_factor_loo']:+.1f} | {r['seconds_measured']:.1f} | {r['seconds_loo']:.1f} | "
                     f"{r['factor_loo']:+.1f} | {r['per_spp_factor_loo']:+.1f} | {r['seconds_in']:.1f} | "
                     f"{r['factor_in']:+.1f} | {pf} | {'yes' if r['integrator_changed'] else 'no'} |")
    out = [r["scene"] for r in rows if abs(r["factor_loo"]) > 2]
    lines += ["", f"Outside a factor of 2 (LOO): {', '.join(out) or 'none'}. The error splits into the noise "
              "model's (spp factor) and the time model's (s/spp factor: seconds per sample, predicted over "
              "measured). The last column flags references whose passes or Russian roulette depth differ "
              "from what today's renderer chooses (one RGB pass where sigma_t differs between channels; "
              "roulette from depth 5 at any albedo): their measured time is that of another integrator "
              "than the one `--estimate` predicts today. The pilot's factor is the render's own "
              "prediction after its pilot, where the reference records it (`pilot.predicted_wall_seconds`). "
              "The references do not record the machine's load; on this shared 2-core machine it ranged "
              "from about 2 to 19 and scales seconds, not samples."]
    tail = model.get("pilot_tail") or {}
    if tail.get("loo"):
        lines += ["", f"The pilot's heavy-tail factor (`harness.reference.cost.tail_factor`): exponent "
                  f"{tail['exponent']:.2f}, fitted on the measured references. Per scene, the noise's fall from the "
                  "pilot's first round to the whole pilot (2 without heavy tails), the samples the final render "
                  "needed over the pilot's prediction from the noise, and the factor predicted with the exponent "
                  "fitted without the scene:", "", "| scene | fall | needed | LOO factor |", "|---|---|---|---|"]
        lines += [f"| {n} | {fall:.3f} | {need:.2f} | {pred:.2f} |" for n, fall, need, pred in tail["loo"]]
    lines += ["", "Coefficients (time: " + ", ".join(cost.TIME_TERMS) + "): "
              + ", ".join(f"{c:.3f}" for c in model["time"]["coef"]),
              "", "Coefficients (noise: " + ", ".join(cost.NOISE_TERMS) + "): "
              + ", ".join(f"{c:.3f}" for c in model["noise"]["coef"]), ""]
    Path(path).write_text("\n".join(lines))


def fit_tail(metas):
    """The exponent of :func:`harness.reference.cost.tail_factor`, by least squares through the origin of
    ``log(final spp / pilot's spp)`` on ``log(2 / the noise's fall)`` over references rendered to their target
    with a two-round pilot; and each scene's leave-one-out prediction ``[(scene, fall, needed, predicted)]``."""
    pts = []
    for name, m in sorted(metas.items()):
        p = m.get("pilot") or {}
        if "early" not in p or not m.get("target_met"):
            continue
        fall = p["early"]["median_rel_se_subsurface"] / p["median_rel_se_subsurface"]
        want = p.get("spp_per_seed_from_noise", p["first_spp_per_seed"])
        pts.append((name, fall, m["spp_per_seed"] / want, max(np.log(2.0 / fall), 0.0), np.log(m["spp_per_seed"] / want)))

    def fit(rows):
        sxx = sum(x * x for *_, x, _ in rows)
        return sum(x * y for *_, x, y in rows) / sxx if sxx > 0 else 0.0

    k = fit(pts)
    loo = [(n, fall, need, cost.tail_factor(fall, 1.0, fit([q for q in pts if q[0] != n]), 4.0))
           for n, fall, need, _, _ in pts]
    return k, loo


def do_fit(out, doc):
    import mitsuba

    old = cost.load_model(out)
    cores_model = int(old["machine"]["cores"])
    entries = load_refs(cores_model)
    family = family_entries(old["family_points"])
    model, rows = validate(entries, family, cores_model)
    model = {"fitted": datetime.now(timezone.utc).isoformat(timespec="seconds"),
             "command": "benchmarks/bench_reference_cost.py --fit",
             "machine": old["machine"] | {"mitsuba": mitsuba.__version__},
             "family": old["family"], **model,
             "overhead_s": model["overhead_s"] | {"cluster_start": old["overhead_s"]["cluster_start"]},
             "loo": {"worst_factor": max(abs(r["factor_loo"]) for r in rows), "rows": rows},
             "pilot_tail": dict(zip(("exponent", "loo"), fit_tail(measured_metas()[0]))),
             "family_points": old["family_points"]}
    Path(out).write_text(json.dumps(model, indent=1) + "\n")
    print(f"{'scene':<24} {'spp':>6} {'LOO spp':>8} {'wall s':>8} {'LOO s':>8} {'LOO x':>6} {'in s':>8} {'in x':>6}")
    for r in rows:
        print(f"{r['scene']:<24} {r['spp_measured']:>6} {r['spp_loo']:>8} {r['seconds_measured']:>8.1f} "
              f"{r['seconds_loo']:>8.1f} {r['factor_loo']:>+6.1f} {r['seconds_in']:>8.1f} {r['factor_in']:>+6.1f}")
    print(f"time: c_job {model['time']['c_job']:.3g} s, c_render {model['time']['c_render']:.3g} s, coef {np.round(model['time']['coef'], 3).tolist()}, "
          f"RMS {model['time']['rms_log']:.3f}; noise coef {np.round(model['noise']['coef'], 3).tolist()}, "
          f"RMS {model['noise']['rms_log']:.3f}; wrote {out}")
    write_doc(rows, model, "benchmarks/bench_reference_cost.py --fit", doc)
    print(f"wrote {doc}")


def measure_point(base, sigma_t, albedo, g, spp, K=8):
    from harness.reference.render import render_reference

    shape = base.medium.sigma_t.shape
    scene = base.with_medium(sigma_t=np.full(shape, sigma_t, np.float32), albedo=np.full(shape, albedo, np.float32),
                             g=np.full(shape, g, np.float32))
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        meta = render_reference(scene, f"{tmp}/ref", spp=spp, K=K)
        wall = time.perf_counter() - t0
    n, r = meta["spp_total"], meta["median_rel_se_subsurface"]
    return {"sigma_t": sigma_t, "albedo": albedo, "g": g, "tau": sigma_t * cost.mean_chord(scene.mesh),
            "spp_total": n, "covered_pixels": meta["covered_pixels"], "render_s": meta["render_seconds"],
            "wall_s": wall, "rel_se": r, "v": r * r * n, "rr_depth": meta["integrator"]["rr_depth"],
            "load": os.getloadavg()[0]}


def do_measure_family(spp, out):
    model = cost.load_model(out)
    base = load_scene("sphere_homogeneous").with_resolution(32, 32)
    points = []
    for st, a, g in FAMILY_GRID:
        points.append(measure_point(base, st, a, g, spp))
        print(json.dumps(points[-1]), flush=True)
    model["family_points"] = points
    model["machine"] |= {"cores": os.cpu_count(), "cpu": platform.processor() or platform.machine()}
    Path(out).write_text(json.dumps(model, indent=1) + "\n")
    print(f"wrote {len(points)} family points to {out}; run --fit next")


def do_check(specs):
    from harness.runs.references import run_reference_cmd

    for spec in specs:
        load = os.getloadavg()[0]
        name, _, size = spec.partition(":")
        scene = load_scene(name)
        target = scene.tolerances.get("small_reference_rel_se") or scene.tolerances.get("reference_rel_se") or 0.05
        if size == "committed":
            from harness.reference.committed import REF_DIR

            meta = json.loads((REF_DIR / name / "reference.json").read_text())
            scene = scene.with_resolution(meta["width"], meta["height"])
            target = meta["target_rel_se"]
            workers = (meta.get("slots") or 1) if meta.get("executor", "serial") != "serial" else None
            est = cost.estimate_reference(scene, target, workers=workers)
            measured, how, spp_measured = meta["wall_seconds"], f"committed ({meta.get('executor')})", meta["spp_total"]
        else:
            w, h = (int(x) for x in size.lower().split("x")) if size else (scene.camera.width, scene.camera.height)
            scene = scene.with_resolution(w, h)
            est = cost.estimate_reference(scene, target, workers=os.cpu_count())
            with tempfile.TemporaryDirectory() as tmp:
                os.environ["SSLPV_CACHE"] = tmp
                t0 = time.perf_counter()
                res = run_reference_cmd(name, size=f"{w}x{h}", target=target, force=True, progress=False)
                measured = time.perf_counter() - t0
            how, spp_measured = "rendered now (LocalCluster)", res["spp_total"]
        print(f"{name:<24} {scene.camera.width}x{scene.camera.height} target {target:.2%}: predicted "
              f"{est['predicted_spp_total']:>7} spp {est['predicted_seconds']:>8.1f} s | measured {spp_measured:>7} "
              f"spp {measured:>8.1f} s ({how}, load average {load:.1f} before) | time factor "
              f"{factor(est['predicted_seconds'], measured):+.1f}", flush=True)


PILOT_DOC = ROOT / "docs" / "reference_pilot.md"


def pilot_row(name, full_below, reuse=False):
    """One suite scene at its committed reference's size and target: the cost model's prediction of the
    final render, the pilot's after its first round and after both, and the final render's measured wall
    time: rendered now when the committed reference took less than ``full_below`` seconds, else the
    committed reference's (its wall time less its pilot's). ``reuse``: where :data:`MEASURED` has the
    scene, render the pilot only and take the measured final render from there."""
    from harness.reference.committed import REF_DIR
    from harness.reference.render import render_reference

    meta_c = json.loads((REF_DIR / name / "reference.json").read_text())
    scene = load_scene(name).with_resolution(meta_c["width"], meta_c["height"])
    target = meta_c["target_rel_se"]
    kept = measured_metas()[0].get(name) if reuse else None
    full = meta_c["wall_seconds"] < full_below and kept is None
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        meta = render_reference(scene, f"{tmp}/ref", target_rel_se=target, K=meta_c["K"],
                                max_seconds=None if full else 1.0, progress=False)
    pilot = meta["pilot"]
    if full and meta["target_met"]:
        _keep_measured(meta)
    if full:
        measured, how = meta["rounds"][-1]["seconds"] - pilot["elapsed_seconds"], "rendered now"
    elif kept is not None:
        measured = kept["rounds"][-1]["seconds"] - kept["pilot"]["elapsed_seconds"]
        how = f"rendered to the target {kept.get('bench_when', 'earlier')} (`cost_suite.json`)"
    else:
        slots = meta_c.get("slots") or 1
        measured = meta_c["wall_seconds"] - (meta_c.get("pilot") or {}).get("seconds", 0.0) / slots
        how = "the committed reference" + (" (other integrator choices)" if meta_c.get("passes") != meta["passes"]
                                           or meta_c.get("integrator", {}).get("rr_depth")
                                           != meta["integrator"].get("rr_depth") else "")
    return {"scene": name, "size": f"{meta['width']}x{meta['height']}", "target": target, "load": load,
            "model_s": pilot.get("cost_model_seconds"), "early_at_s": pilot["early"]["elapsed_seconds"],
            "early_s": pilot["early"]["predicted_wall_seconds"], "pilot_at_s": pilot["elapsed_seconds"],
            "pilot_s": pilot["predicted_wall_seconds"], "measured_s": measured, "how": how,
            "target_met_now": meta["target_met"] if full else None}


def _keep_measured(meta):
    """Add one reference's metadata to :data:`MEASURED` (written after each scene: an interrupted run keeps
    what it measured)."""
    import mitsuba

    refs, _ = measured_metas()
    refs[meta["scene"]] = dict(meta, bench_when=datetime.now(timezone.utc).isoformat(timespec="minutes"))
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                            text=True).stdout.strip() or "unknown"
    MEASURED.write_text(json.dumps({"command": "benchmarks/bench_reference_cost.py --pilot --full-below inf",
                                    "commit": commit, "cores": os.cpu_count(), "mitsuba": mitsuba.__version__,
                                    "updated": datetime.now(timezone.utc).isoformat(timespec="seconds"),
                                    "refs": dict(sorted(refs.items()))}, indent=1, default=float) + "\n")


def do_pilot(names, full_below, path=PILOT_DOC, reuse=False):
    from harness.reference.committed import REF_DIR

    rows = []
    for name in names or sorted(p.name for p in REF_DIR.iterdir() if (p / "reference.json").is_file()):
        r = pilot_row(name, full_below, reuse)
        rows.append(r)
        print(f"{name:<24} model {r['model_s'] or float('nan'):>8.1f} s | first round at {r['early_at_s']:>6.1f} s: "
              f"{r['early_s']:>8.1f} s | pilot at {r['pilot_at_s']:>6.1f} s: {r['pilot_s']:>8.1f} s | measured "
              f"{r['measured_s']:>8.1f} s ({r['how']})", flush=True)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                            text=True).stdout.strip() or "unknown"
    dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", ".", f":!{path.relative_to(ROOT)}"],
                           cwd=ROOT, capture_output=True, text=True).stdout.strip()

    def fx(pred, meas):
        return f"{factor(pred, meas):+.1f}" if pred and meas and meas > 0 else "—"

    def mark(pred, meas):
        return "" if pred and meas and abs(factor(pred, meas)) <= 2 else " ✗"

    early_late = [r["scene"] for r in rows if r["early_at_s"] > 60]
    loo = {r["scene"]: r["factor_loo"] for r in cost.load_model().get("loo", {}).get("rows", [])}
    # The scenes the model does not predict within a factor of 2 when it has not seen them (leave-one-out).
    off_model = [r for r in rows if r["scene"] not in loo or abs(loo[r["scene"]]) > 2]
    off_early = [r for r in off_model if abs(factor(r["early_s"], r["measured_s"])) > 2]
    off_pilot = [r for r in off_model if abs(factor(r["pilot_s"], r["measured_s"])) > 2]
    late = [r["scene"] for r in rows if r["pilot_at_s"] > 60]
    missed = [f"{r['scene']}, {factor(r['pilot_s'], r['measured_s']):+.1f}" for r in off_pilot]
    lines = ["# The reference's pilot against the cost model", "",
             f"Written by `.venv/bin/python benchmarks/bench_reference_cost.py --pilot --full-below {full_below:g}"
             f"{' --reuse-measured' if reuse else ''}` at "
             f"commit `{commit}`{' (with uncommitted changes)' if dirty else ''}, "
             f"{datetime.now(timezone.utc).isoformat(timespec='seconds')}, on {os.cpu_count()} cores. "
             "Do not edit by hand.", "",
             "Each suite scene's reference at its committed size and target, serial renderer. Every figure is "
             "the final render's wall time (the pilot excluded): predicted by the cost model before anything "
             "renders (`reference --estimate`, today's integrator choices; fitted on every scene, this one "
             "included: its leave-one-scene-out error is in `docs/reference_cost.md`), by the pilot after its first round "
             "(4 of 16 samples per seed; `at`: seconds after the start, when the log prints it), by the whole "
             f"pilot, and measured: rendered to the target by this command (or, with `--reuse-measured`, by its "
             "earlier run, kept in `harness/reference/cost_suite.json`) where the committed reference took under "
             f"{full_below:g} s, "
             "else the committed reference's (wall time less its pilot; rendered on another day's load, some "
             "with other integrator choices, so those factors are indicative only). Factor: predicted / "
             "measured, negative when under; ✗ beyond a factor of 2.", "",
             "| scene | size | target | cost model s | factor | LOO factor | first round at s | its prediction s | factor "
             "| pilot at s | its prediction s | factor | measured s | measured how | load before |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        m = r["measured_s"]
        lines.append(f"| {r['scene']} | {r['size']} | {r['target']:.1%} | "
                     f"{r['model_s'] or float('nan'):.1f} | {fx(r['model_s'], m)}{mark(r['model_s'], m)} | "
                     + (f"{loo[r['scene']]:+.1f}{'' if abs(loo[r['scene']]) <= 2 else ' ✗'} | " if r["scene"] in loo
                        else "— | ") +
                     f"{r['early_at_s']:.1f} | {r['early_s']:.1f} | {fx(r['early_s'], m)}{mark(r['early_s'], m)} | "
                     f"{r['pilot_at_s']:.1f} | {r['pilot_s']:.1f} | {fx(r['pilot_s'], m)}{mark(r['pilot_s'], m)} | "
                     f"{m:.1f} | {r['how']} | {r['load']:.1f} |")
    lines += ["", "LOO factor: the cost model's error on the scene when fitted without it (`docs/reference_cost.md`). "
              f"Left out of the fit, the cost model is within a factor of 2 on {len(rows) - len(off_model)} of "
              f"{len(rows)} scenes; "
              f"on the other {len(off_model)} ({', '.join(r['scene'] for r in off_model) or 'none'}) the pilot's "
              f"first round is within a factor of 2 on {len(off_model) - len(off_early)}"
              + (f" (not on {', '.join(r['scene'] for r in off_early)})" if off_early else "")
              + f", the whole pilot's on {len(off_model) - len(off_pilot)}"
              + (f" (not on {', '.join(missed)})" if missed else "")
              + f". The first round's prediction was logged within the first minute on "
              f"{len(rows) - len(early_late)} of {len(rows)} scenes"
              + (f" (later on {', '.join(early_late)})" if early_late else "")
              + f", the whole pilot's on {len(rows) - len(late)} of {len(rows)}" + (f" (later on {', '.join(late)})" if late
                                                                                    else "") + ".", ""]
    path.write_text("\n".join(lines))
    print(f"wrote {path}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fit", action="store_true", help="fit on the committed references and the family, run LOO")
    ap.add_argument("--measure-family", action="store_true", help="render the 32x32 family points")
    ap.add_argument("--spp", type=int, default=32, help="samples per pixel per seed for --measure-family (8 seeds)")
    ap.add_argument("--out", default=str(cost.MODEL_FILE), help="model file")
    ap.add_argument("--doc", default=str(DOC), help="markdown table written by --fit")
    ap.add_argument("--pilot", nargs="*", metavar="SCENE", help="the pilot's predictions against the cost model's "
                    "on suite scenes (default: all), written to docs/reference_pilot.md")
    ap.add_argument("--full-below", type=float, default=150.0, help="--pilot renders to the target a scene whose "
                    "committed reference took under this many seconds (else pilot and first step only)")
    ap.add_argument("--reuse-measured", action="store_true", help="--pilot renders only the pilot of a scene "
                    "that harness/reference/cost_suite.json has rendered to its target, and takes its time from there")
    ap.add_argument("--check", nargs="*", metavar="SCENE[:WxH|:committed]", help="compare prediction and measurement")
    args = ap.parse_args()
    if args.measure_family:
        do_measure_family(args.spp, args.out)
    if args.fit:
        do_fit(args.out, args.doc)
    if args.check:
        do_check(args.check)
    if args.pilot is not None:
        do_pilot(args.pilot, args.full_below, reuse=args.reuse_measured)


if __name__ == "__main__":
    main()
