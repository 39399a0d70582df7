"""Power and false alarms of the accuracy verdicts, measured (``harness.regression.verdict``).

**Power.** Six deliberate errors in the method, each over every case of
``baselines/accuracy_matrix.toml`` (SSLPV at 64x64 against the committed image and
reference, exactly as ``pytest -m accuracy`` judges it, Bonferroni over the whole matrix):

* absorption x 2 (``sigma_lpv`` doubled);
* Eq. 3's scattering dropped (``sigma_s' = 0``);
* injection offset by half a cell (``floor(u + 0.5)`` for the cell of an RSM texel);
* Fresnel T = 1 (``fresnel_transmittance`` returns 1, in injection and shading);
* the 1/pi of Eq. 1 lost (``T / PI`` -> ``T`` in ``inject.vert``);
* the propagation matrices transposed.

Per error it prints the fraction of cases flagged *changed* among those where the error
changes the image at all (the rest are cases the error cannot touch, e.g. Fresnel on an
index-matched boundary), and the fractions flagged *regression* and *improvement*. Where an
independent reference exists (the re-seeded ones of ``benchmarks/reseeded_references.py``,
pooled, and ``baselines/refs_reseeded``) the direction of each significant verdict is
checked against the Delta measured there: a verdict is *wrong* when that Delta is
significant (z beyond the same critical value) with the opposite sign.

**False alarms.** For each scene with re-seeded references (at least 20 each, rendered by
``benchmarks/reseeded_references.py``, never in CI):

* the unchanged renderer against every re-seeded reference, judged as an accuracy run
  judges it (the render against the committed image, then, were it changed, the paired
  verdict against that reference): the number called regression or improvement;
* the calibration of the standard errors, which that count cannot show (unchanged images
  are never judged): for every deliberate error and case, Delta against each re-seeded
  reference ``j`` against Delta against the mean of the *other* references,
  ``z_j = (Delta_j - Delta_-j) / sqrt(SE_j^2 + SE_-j^2)``, a true null; printed are its
  standard deviation (1 if the SEs are right), the share beyond 1.96 (5 % promised), and
  how many are beyond the Bonferroni critical value of an accuracy run (the observed
  false-alarm count, against the promised ``alpha / (2 m)`` per comparison and direction).
  The delta-method metrics are calibrated; FLIP (resampled) only with ``--flip``.

    .venv/bin/python benchmarks/reseeded_references.py --count 20
    .venv/bin/python benchmarks/accuracy_sensitivity.py
"""

import argparse
import contextlib
import json
from pathlib import Path

import numpy as np

from harness.regression.accuracy import cases, family_size, case_reference, small_scene
from harness.regression.baselines import BASELINE_DIR, committed_image, find_entry, read_baseline
from harness.regression.verdict import ALPHA, HEADLINE, critical_value, image_change, judge_images, overall
from harness.runs.params import config_label
from harness.runs.sweep import load_reference

ANALYTIC = ("relmse", "si_relmse", "energy_ratio")


# --------------------------------------------------------------------------- the six errors

@contextlib.contextmanager
def _material(renderer, change):
    original = renderer.lpv_material
    renderer.lpv_material = lambda s, p: change(dict(original(s, p)))
    try:
        yield
    finally:
        renderer.lpv_material = original


def _rebuild(renderer):
    """Forget every program and the vertex arrays bound to them (a vertex array renders with the
    program it was made for), so that the next render compiles the shaders as they are now."""
    renderer._programs.clear()
    renderer._points = None
    renderer._meshes.clear()


@contextlib.contextmanager
def _shader_edit(renderer, edits):
    """Replace text in the shader sources (each edit must apply), rebuilding every program."""
    from sslpv_gl import shaders

    original = shaders.load_source
    hits = {old: 0 for old, _ in edits}

    def edited(name, defines=None):
        text = original(name, defines)
        for old, new in edits:
            if old in text:
                hits[old] += 1
                text = text.replace(old, new)
        return text

    shaders.load_source = edited
    _rebuild(renderer)
    try:
        yield hits
    finally:
        shaders.load_source = original
        _rebuild(renderer)


@contextlib.contextmanager
def _transposed(renderer):
    from sslpv_gl import propagate

    original = propagate.propagation_matrices
    propagate.propagation_matrices = lambda: np.ascontiguousarray(np.swapaxes(original(), -1, -2))
    _rebuild(renderer)
    try:
        yield
    finally:
        propagate.propagation_matrices = original
        _rebuild(renderer)


CELL = "floor((p.xyz - u_offset * n - u_bbox_min) / u_dx)"
ERRORS = {
    "absorption x2": lambda r: _material(r, lambda m: dict(m, sigma_lpv=m["sigma_lpv"] * 2)),
    "no Eq. 3 scattering": lambda r: _material(r, lambda m: dict(m, sigma_s_prime=np.zeros_like(m["sigma_s_prime"]))),
    "injection offset half a cell": lambda r: _shader_edit(r, [(CELL, CELL[:-1] + " + 0.5)")]),
    "Fresnel T = 1": lambda r: _shader_edit(r, [("return 1.0 - fresnel_reflectance(cos_i, eta);", "return 1.0;")]),
    "1/pi of Eq. 1 lost": lambda r: _shader_edit(r, [("(T / PI)", "(T)")]),
    "matrices transposed": _transposed,
}


# --------------------------------------------------------------------------- references

def independent_references(scene_name, shape=(64, 64)):
    """Re-seeded references of a scene: those of benchmarks/reseeded_references.py, else baselines/refs_reseeded."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from reseeded_references import reference_dirs

    dirs = reference_dirs(scene_name)
    if not dirs and (BASELINE_DIR / "refs_reseeded" / scene_name).is_dir():
        dirs = [BASELINE_DIR / "refs_reseeded" / scene_name]
    return [load_reference(d, shape) for d in dirs]


def pooled(refs):
    """The mean of independent references, with its standard error."""
    out = dict(refs[0])
    out["subsurface"] = np.mean([r["subsurface"] for r in refs], axis=0)
    out["se"] = np.sqrt(np.sum([r["se"] ** 2 for r in refs], axis=0)) / len(refs)
    out["K"] = sum(r["K"] for r in refs)
    return out


# --------------------------------------------------------------------------- main

def main():
    from sslpv_gl.renderer import SSLPVRenderer

    ap = argparse.ArgumentParser(description="power and false alarms of the accuracy verdicts")
    ap.add_argument("--errors", default=",".join(ERRORS), help="comma-separated subset of the six errors")
    ap.add_argument("--flip", action="store_true", help="also calibrate FLIP's resampled SE (slow)")
    ap.add_argument("--metrics", default=",".join(HEADLINE),
                    help="headline metrics to judge (default all; FLIP's resampling dominates the run time)")
    ap.add_argument("--scenes", help="comma-separated subset of the matrix's scenes")
    ap.add_argument("--json", type=Path, help="write every verdict here")
    args = ap.parse_args()
    errors = [e.strip() for e in args.errors.split(",")]
    metrics = tuple(x.strip() for x in args.metrics.split(","))
    renderer = SSLPVRenderer()
    all_cases = [c for c in cases() if not args.scenes or c[0] in args.scenes.split(",")]
    m = family_size()                 # the family of a whole accuracy run, whatever is judged here
    t_run = critical_value(m)
    committed = {}
    for scene, params, _ in all_cases:
        entry = find_entry(read_baseline(scene), [64, 64], params.as_dict())
        committed[(scene, config_label(params))] = committed_image(scene, entry)
    refs = {s: case_reference(small_scene(s)) for s in {c[0] for c in all_cases}}
    indep = {s: independent_references(s) for s in refs}
    indep = {s: r for s, r in indep.items() if r}
    print(f"{len(all_cases)} cases, Bonferroni over m = {m}, alpha = {ALPHA}: |z| critical {t_run:.2f} "
          f"(normal); judged metrics: {', '.join(metrics)}; independent references: " + ", ".join(f"{s} {len(r)}" for s, r in indep.items()), flush=True)

    # ---------------- false alarms of the unchanged renderer
    fa_judged = fa_flagged = fa_changed = 0
    for scene, params, tol in all_cases:
        if scene not in indep or len(indep[scene]) < 2:
            continue
        label = config_label(params)
        res = renderer.render(small_scene(scene), params)
        old, old_mask = committed[(scene, label)]
        ic = image_change(res.subsurface, old, res.mask, old_mask)
        for r in indep[scene]:
            fa_judged += 1
            fa_changed += ic.changed
            if ic.changed:
                ch = judge_images(scene, label, "subsurface", res.subsurface, old, r["subsurface"], r["se"],
                                  r["mask"], tol, m, k=r["K"], metrics=metrics)
                fa_flagged += overall(ch) in ("regression", "improvement")
    print(f"unchanged renderer against re-seeded references: {fa_judged} case x reference verdicts, "
          f"{fa_changed} images changed, {fa_flagged} regression or improvement", flush=True)

    # ---------------- the six errors
    rows, calib, spread = [], {"delta": [], "flip": []}, {}
    for name in errors:
        counts = {"cases": 0, "touched": 0, "changed": 0, "regression": 0, "improvement": 0, "checked": 0,
                  "wrong": 0}
        with ERRORS[name](renderer) as hits:
            for scene, params, tol in all_cases:
                label = config_label(params)
                res = renderer.render(small_scene(scene), params)
                old, old_mask = committed[(scene, label)]
                ic = image_change(res.subsurface, old, res.mask, old_mask)
                # "touched": the error moves the image at all (beyond one float32 rounding)
                touched = bool(ic.mask_flips) or not np.array_equal(res.subsurface[res.mask], old[res.mask])
                counts["cases"] += 1
                counts["touched"] += touched
                counts["changed"] += ic.changed
                row = {"error": name, "scene": scene, "config": label, "touched": touched, "changed": ic.changed,
                       "image": ic.line(), "verdict": "unchanged", "checks": []}
                if ic.changed:
                    ref = refs[scene]
                    checks = judge_images(scene, label, "subsurface", res.subsurface, old, ref["subsurface"],
                                          ref["se"], ref["mask"], tol, m, k=ref["K"], metrics=metrics)
                    row["verdict"] = overall(checks, True)
                    row["checks"] = [c.as_dict() for c in checks]
                    counts[row["verdict"]] = counts.get(row["verdict"], 0) + 1
                    if scene in indep:
                        truth = pooled(indep[scene])
                        other = judge_images(scene, label, "subsurface", res.subsurface, old, truth["subsurface"],
                                             truth["se"], truth["mask"], tol, m, k=truth["K"], metrics=metrics)
                        for a, b in zip(checks, other):
                            if a.verdict in ("regression", "improvement"):
                                counts["checked"] += 1
                                if abs(b.z) > b.critical and np.sign(b.delta) != np.sign(a.delta):
                                    counts["wrong"] += 1
                        # calibration of the SEs against each independent reference (leave one out)
                        if len(indep[scene]) >= 3:
                            calibrated = ANALYTIC + (("flip",) if args.flip else ())
                            for j, r in enumerate(indep[scene]):
                                rest = pooled([x for i, x in enumerate(indep[scene]) if i != j])
                                aj = judge_images(scene, label, "subsurface", res.subsurface, old, r["subsurface"],
                                                  r["se"], r["mask"], tol, m, k=r["K"], metrics=calibrated)
                                bj = judge_images(scene, label, "subsurface", res.subsurface, old,
                                                  rest["subsurface"], rest["se"], rest["mask"], tol, m,
                                                  k=rest["K"], metrics=calibrated)
                                for a, b in zip(aj, bj):
                                    z = (a.delta - b.delta) / max(np.hypot(a.se, b.se), 1e-300)
                                    calib["flip" if a.metric == "flip" else "delta"].append(
                                        (z, a.critical, name, scene, label, a.metric))
                                    spread.setdefault((scene, name, label, a.metric), []).append((a.delta, a.se))
                rows.append(row)
        if hasattr(hits, "values") and not all(hits.values()):
            raise SystemExit(f"{name}: a shader edit did not apply ({hits}); the benchmark would test nothing")
        # the error is gone again: a clean render equals its committed image
        scene, params, _ = all_cases[0]
        res = renderer.render(small_scene(scene), params)
        if image_change(res.subsurface, *committed[(scene, config_label(params))][:1], res.mask,
                        committed[(scene, config_label(params))][1]).changed:
            raise SystemExit(f"{name}: the renderer did not return to its committed images after the error")
        t = max(counts["touched"], 1)
        below = [r["image"] for r in rows if r["error"] == name and r["touched"] and not r["changed"]]
        print(f"{name}: touches {counts['touched']} of {counts['cases']} cases (any bit); flagged changed in "
              f"{counts['changed']} of {counts['touched']} ({counts['changed'] / t:.0%}); regression in "
              f"{counts['regression']}, improvement in {counts['improvement']}, within noise in "
              f"{counts.get('changed-within-noise', 0)} (of the changed); direction checked on "
              f"{counts['checked']} significant metric verdicts, wrong in {counts['wrong']}", flush=True)
        for line in below:
            print(f"    touched but within the floating-point tolerance: {line}")

    for kind, zs in calib.items():
        if not zs:
            continue
        z = np.array([x[0] for x in zs])
        crit = np.array([x[1] for x in zs])
        beyond = int(np.count_nonzero(np.abs(z) > crit))
        print(f"SE calibration ({'delta method: ' + ', '.join(ANALYTIC) if kind == 'delta' else 'FLIP, resampled'}): "
              f"{len(z)} leave-one-out comparisons, std of z {z.std():.3f}, |z| > 1.96 in "
              f"{np.mean(np.abs(z) > 1.96):.2%} (5% promised), beyond the run's critical value in {beyond} "
              f"(promised rate {ALPHA / m:.1e} per comparison: {ALPHA / m * len(z):.3f} expected)")
    # the SEs against the spread of Delta over the independent references, per scene
    by_scene = {}
    for (scene, _, _, metric), v in spread.items():
        d, se = np.array(v).T
        by_scene.setdefault((scene, metric), []).append(d.std(ddof=1) / np.sqrt(np.mean(se ** 2)))
    for (scene, metric), r in sorted(by_scene.items()):
        print(f"spread of Delta over {scene}'s references / its SE ({metric}): median {np.median(r):.3f}, "
              f"range {min(r):.3f}-{max(r):.3f} over {len(r)} error x case pairs")
    if args.json:
        args.json.write_text(json.dumps({"rows": rows, "false_alarm": {"judged": fa_judged, "changed": fa_changed,
                                                                       "flagged": fa_flagged}}, indent=1))


if __name__ == "__main__":
    from page import run

    raise SystemExit(run(main, "accuracy_sensitivity", 'Power and false alarms of the accuracy verdicts'))
