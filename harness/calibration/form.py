"""A calibration that depends on the material: fit the form (F1) over the suite, validate it by renders.

``sslpv-harness calibrate-form --from DIR... --out OUT`` (or ``python -m harness.calibration.form``) reads calibrations of one family
(each ``DIR``: ``calibrated.toml`` and ``calibration.json`` of ``sslpv-harness calibrate``, e.g. one
per grid; their budgets are taken together) and

1. takes each scene's own optimum ``(s_i, r_i)`` at each budget (the calibration's *oracle*) and
   its scene-level terms of Eq. (F1) (:func:`scene_terms`, the mean over the scene's inside LPV
   cells and colours, :mod:`sslpv_gl.material_form`);
2. fits the form by ridge regression (Eq. F5, :mod:`harness.calibration.form_fit`) on all
   scenes (*in-sample*) and, for each scene, on the others alone (*held out*: the penalty too
   is chosen without it, :func:`fold_fits`);
3. RENDERS every scene with the in-sample file and each scene with its own held-out file
   (a version 3 ``calibrated.toml`` each, read by the renderer as ``--mapping calibrated:PATH``
   would): the reported figures are those renders', never the regression's;
4. judges them as :mod:`harness.calibration.run` does, beside the scene's oracle and the fixed
   mappings (both from ``DIR``), and against the held-out median relMSE of every calibrated family
   given with ``--against``: targets ``energy ratio in [0.8, 1.25]`` held out on every scene and the
   median held-out relMSE at most :data:`FORM_RELMSE_FACTOR` times the best family's;
5. writes, atomically, ``OUT/calibrated.toml`` (version 3) and ``OUT/calibration.json``.

With ``slopes = "radiance"`` (``--slopes radiance``) the form is *conditional* (Eq. F7): ``sigma_scale`` stays
the scalar fit's (every sigma slope 0), and only ``ln r`` depends on the material. Its targets are not the
oracle's ``(s_i, r_i)``, which scatter along the loss's valley, but each training scene's best radiance scale
at the fold's own scalar ``s`` (its held-out ``s`` for a fold, its in-sample ``s`` for the file):

    y_i = ln(B_i(s) / A_i(s))     (the minimum over r of Eq. C1, scene i rendered at sigma_scale s)         (F7)

regressed on the terms as in (F5) and anchored at the fold's scalar ``r`` as in (F6). Each target is a render
of a training scene at its fold's ``s`` (:func:`radiance_targets`), so nothing of the held-out scene reaches
its fold.

With ``slopes = "loss"`` (``--slopes loss``) both scales' coefficients are fitted on the render loss (C2) itself,
through each scene's images at the calibration's scan of ``sigma_scale`` and their spline (Eq. F8,
:mod:`harness.calibration.form_loss`): no oracle and no anchor, so the scenes' valleys in ``(ln s, ln r)``
trade off as the loss says. It needs every scene at every scanned ``sigma_scale`` (the scan of ``sslpv-harness
calibrate``), served from the result cache where that calibration ran on this machine, else rendered.
``slopes = "channels"`` (``--slopes channels``) fits the same loss with each colour channel at its own terms
(Eq. F9 of :mod:`harness.calibration.form_loss`); its report keeps those terms (``channel_terms``).

``ln_extent_per_step`` (F4) is a term of the integer budgets only: ``steps = steady`` has no
step count and its form drops the term. Limits: the fit regresses the oracle's parameters, not
the render loss (C2) itself (:mod:`harness.calibration.form_fit`); the scene's oracle is the
family's (one ``(s, r)`` per scene), so the form may beat it on a heterogeneous scene.

The conditional form gives a slope only to a term that leave-one-out can test
(:func:`~harness.calibration.form_fit.loo_testable_terms`): on the suite at N = 32 nine scenes share one
``ln_extent_per_step`` and ``backlit_slab`` and ``thin_ring`` each have their own, so in either one's fold
the other alone sets the term apart. The ridge penalty is on standardised coefficients, and such a term
got a slope steep enough to fit that one scene (-50 at K = 8); the held-out scene beyond it
extrapolated many times too bright. The full form (F5) keeps every term that is not constant.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from harness.calibration.form_files import against_medians, form_toml, read_sources
from harness.calibration.form_fit import fit_form, predictive_power
from harness.calibration.run import ENERGY_TARGET, _figures
from harness.calibration.scan import budget_label
from harness.errors import InputError

__all__ = ["scene_terms", "budget_terms", "fold_fits", "fold_anchor", "radiance_targets", "fold_fits_radiance",
           "fold_fits_loss",
           "form_toml", "run_form", "FORM_RELMSE_FACTOR", "SLOPES", "main"]

#: Target: median held-out relMSE at most this times the best calibrated family's at the budget.
FORM_RELMSE_FACTOR = 0.5
#: Which scales depend on the material: both (F5, on the oracle), the radiance scale alone (F7), or both fitted on
#: the render loss itself, with each scene at its mean terms (F8) or each colour channel at its own (F9).
SLOPES = ("both", "radiance", "loss", "channels")


def budget_terms(steps):
    """The terms of (F1) a budget's form uses: all, less ``ln_extent_per_step`` at ``steps = steady``."""
    from sslpv_gl.material_form import TERMS

    return tuple(t for t in TERMS if isinstance(steps, int) or t != "ln_extent_per_step")


def grid_medium(scene, N, settings):
    """The scene's medium on the LPV grid at ``N`` as the renderer maps it: ``(sigma_t, albedo, g, dx)`` after
    the fit's resampling and phase scaling (``settings``), with ``dx`` the cell width."""
    from sslpv_gl.material import delta_eddington, resample_medium

    med = scene.medium
    st, a, g = resample_medium(med, N, settings["resample"])
    if settings.get("phase_scaling", "none") == "delta-eddington":
        st, a, g = delta_eddington(st, a, g)
    dx = float(np.asarray(med.bbox_max, np.float64)[0] - np.asarray(med.bbox_min, np.float64)[0]) / N
    return st, a, g, dx


def scene_terms(scene, N, steps, settings, per_channel=False):
    """The scene-level terms of (F1) at grid ``N`` and step count ``steps``: each term's mean over the
    inside cells and colours of the medium as the renderer maps it (same resampling, phase scaling, eta);
    ``per_channel``: a list of three such lists, each the mean over the inside cells of one colour (Eq. F9)."""
    from harness.scene.geometry import grid_inside
    from sslpv_gl.material_form import cell_numbers, extent_cells, mean_numbers

    med = scene.medium
    inside = grid_inside(scene.mesh, med.bbox_min, med.bbox_max, N)
    st, a, g, dx = grid_medium(scene, N, settings)
    numbers = cell_numbers(st, a, g, dx, float(scene.boundary.eta), extent_cells(inside, N), steps)
    if per_channel:
        out = []
        for c in range(np.shape(st)[-1]):
            m = mean_numbers({name: x[..., c] for name, x in numbers.items()}, inside)
            out.append([m[name] for name in budget_terms(steps)])
        return out
    means = mean_numbers(numbers, inside)
    return {t: means[t] for t in budget_terms(steps)}


def fold_fits(names, X, ln_s, ln_r, held, anchor=None):
    """Eq. (F5) on every scene but ``held`` (None: on all) -> :func:`~harness.calibration.form_fit.fit_form`'s
    dict. ``X`` (scene -> term values), ``ln_s`` and ``ln_r`` (scene -> oracle) are read for the training
    scenes only, so nothing of the held-out scene reaches its fit. ``anchor`` (Eq. F6): the scalar
    ``(ln s, ln r)`` the source calibration fitted on the same training scenes (its held-out pair of
    ``held``, its in-sample pair for None), or None for the regression's own level."""
    train = [n for n in names if n != held]
    return fit_form([X[n] for n in train], [ln_s[n] for n in train], [ln_r[n] for n in train],
                    anchor) | {"scenes": train}


def fold_anchor(res, held):
    """Eq. (F6)'s ``(ln s*, ln r*)`` for a fold: the source calibration's scalar pair fitted on the same
    training scenes, i.e. its held-out pair of ``held`` (fitted without it), or its in-sample pair for None."""
    pair = (res["sigma_scale"], res["radiance_scale"]) if held is None else \
        (res["held_out"][held]["s"], res["held_out"][held]["r"])
    return math.log(pair[0]), math.log(pair[1])


def radiance_targets(render_at, names, s):
    """Eq. (F7)'s targets: ``{scene: ln(B / A)}``, each scene's best ``ln r`` at ``sigma_scale = s``.
    ``render_at(name, s)`` returns ``(A, B, C)`` of Eq. (C1) or None (no image: that scene is left out)."""
    out = {}
    for n in names:
        abc = render_at(n, s)
        if abc is not None and abc[0] > 0.0 and abc[1] > 0.0:
            out[n] = math.log(abc[1] / abc[0])
    return out


def fold_fits_radiance(names, X, targets, held, anchor):
    """Eq. (F7) on every scene but ``held``: ``sigma`` is the anchor's ``ln s`` with every slope 0; ``radiance``
    the ridge regression (F5) of ``targets`` (scene -> ln r at that ``s``, the training scenes' only) with its
    level at the anchor's ``ln r`` (F6); only terms that leave-one-out can test on the training scenes get a
    slope (:func:`~harness.calibration.form_fit.loo_testable_terms`). Same dict as :func:`fold_fits`."""
    from harness.calibration.form_fit import choose_lambda, ridge

    train = [n for n in names if n != held and n in targets]
    Xt = np.asarray([X[n] for n in train], dtype=np.float64)
    y = np.asarray([targets[n] for n in train], dtype=np.float64)
    lam = choose_lambda(Xt, (y,), testable=True)
    _, b = ridge(Xt, y, lam, testable=True)
    b0 = float(anchor[1] - Xt.mean(axis=0) @ b)
    return {"sigma": [float(anchor[0])] + [0.0] * Xt.shape[1], "radiance": [b0, *map(float, b)], "lam": lam,
            "scenes": train}


def fold_fits_loss(names, X, tables, u_grid, held):
    """Eq. (F8) on every scene but ``held`` (None: on all): both scales' coefficients fitted on the render loss
    (C2) through each training scene's table (``tables``: scene -> (A, B, C) on ``u_grid``,
    :func:`~harness.calibration.form_loss.scene_table`; a scene without one is left out), ``lam`` by
    leave-one-out on the training scenes alone. Same dict as :func:`fold_fits`."""
    from harness.calibration.form_loss import choose_lambda_loss, fit_loss_form

    train = [n for n in names if n != held and n in tables]
    Xt, tabs = [X[n] for n in train], [tables[n] for n in train]
    lam = choose_lambda_loss(Xt, u_grid, tabs)
    sigma, radiance = fit_loss_form(Xt, u_grid, tabs, lam)
    return {"sigma": sigma, "radiance": radiance, "lam": lam, "scenes": train}


def _render(renderer, scene, path, settings, N, steps_list):
    """``{steps: subsurface image}`` of ``scene`` with the calibrated file ``path`` (integer counts from one
    grouped call, as the renderer groups them; ``steady`` alone). A failed render is left out."""
    from sslpv_gl.params import SSLPVParams

    out = {}
    ints = sorted(k for k in steps_list if isinstance(k, int))
    base = {k: v for k, v in settings.items()}
    if ints:
        params = SSLPVParams(N=N, steps=ints[-1], mapping=f"calibrated:{path}", **base)
        for k, res in zip(ints, renderer.render_steps(scene, params, ints)):
            out[k] = np.asarray(res.subsurface, dtype=np.float64)
    for k in (k for k in steps_list if not isinstance(k, int)):
        try:
            out[k] = np.asarray(renderer.render(scene, SSLPVParams(N=N, steps=k, mapping=f"calibrated:{path}",
                                                                   **base)).subsurface, dtype=np.float64)
        except (ValueError, FloatingPointError):       # no steady state with these scales
            pass
    return out


def _judge(images, ref):
    return {k: _figures(img, ref, 1.0) if np.all(np.isfinite(img)) else {"relmse": None, "energy_ratio": None}
            for k, img in images.items()}


def _median(values):
    vals = [v for v in values if v is not None]
    return statistics.median(vals) if vals else None


def run_form(source, out, against=(), anchored=True, renderer=None, argv=None, progress=print,
             command="python -m harness.calibration.form", slopes="both", cache=True):
    """Fit, validate and write the form for the calibrations in ``source`` (a folder, or a list of folders of one
    family whose budgets are taken together; module docstring) -> the report dict. ``slopes``: ``"both"`` (F5),
    ``"radiance"`` (F7, always anchored) or ``"loss"`` (F8: the levels from the loss, never anchored). ``cache``: the
    scan's renders through the result cache (:func:`harness.runs.cache.open_cache`'s argument), False to render them all."""
    from harness.io.atomic import _check_replaceable, atomic_dir
    from sslpv_gl.calibrated import load_calibrated
    from sslpv_gl.material import MAPPINGS

    t0 = time.perf_counter()
    sources = [str(p) for p in ([source] if isinstance(source, (str, Path)) else source)]
    out = Path(out)
    _check_replaceable(out)
    cal, settings = read_sources(sources)
    names = list(cal["scenes"])
    budgets = [(int(N), k) for N, k in cal["budgets"]]
    if slopes not in SLOPES:
        raise InputError("--slopes", "slopes", f"unknown {slopes!r}", f"use one of: {', '.join(SLOPES)}")
    # (F7)'s renders: the family's mapping at a fold's sigma_scale, memoised (failed renders left out) by the scan's
    # own renderer of a calibration
    from harness.calibration.fit import relmse_coefficients
    from harness.calibration.scan import calibration_scanner

    scanner, scenes, results_cache = calibration_scanner(cal, settings, Path(sources[0]) / "calibration.json",
                                                         renderer, cache, "calibrate-form")
    renderer, refs = scanner.renderer, scanner.refs

    def at(n, N, k, s):
        scanner.render(n, s, [(N, k)])
        img, m = scanner.image((N, k), n, s), refs[n]["mask"]
        return None if img is None else relmse_coefficients(img[m].ravel(),
                                                            np.asarray(refs[n]["subsurface"], np.float64)[m].ravel())

    if slopes in ("loss", "channels"):                                              # (F8), (F9): the calibration's scan
        from harness.calibration.form_loss import loss_power, scan_grid, scene_table, scene_table_channels

        u_grid = scan_grid(cal["sigma_scan"])
        for n in names:
            for s in cal["sigma_scan"]:
                scanner.render(n, s)
            progress(f"scanned {n} at every sigma_scale of the calibration's scan")

    # 1.-2. terms, oracle, fits (in-sample: held=None)
    fits = {}
    for N, k in budgets:
        label, res = budget_label(N, k), cal["results"][budget_label(N, k)]
        terms = budget_terms(k)
        X = {n: list(scene_terms(scenes[n], N, k, settings).values()) for n in names}      # in the order of terms
        ln_s = {n: math.log(res["oracle"][n]["s"]) for n in names}
        ln_r = {n: math.log(res["oracle"][n]["r"]) for n in names}
        lam = fold_fits(names, X, ln_s, ln_r, None)["lam"]
        power = {key: predictive_power([X[n] for n in names], [y[n] for n in names], lam)
                 for key, y in (("ln_s", ln_s), ("ln_r", ln_r))}
        if slopes == "radiance":                                                    # (F7)
            folds, targets = {}, {}
            for held in [None, *names]:
                anchor = fold_anchor(res, held)
                t = radiance_targets(lambda n, s: at(n, N, k, s), [n for n in names if n != held],
                                     math.exp(anchor[0]))
                folds[held] = fold_fits_radiance(names, X, t, held, anchor)
                if held is None:
                    targets = t
                progress(f"{label}: radiance targets of the fold without {held or 'no scene'}")
            power["ln_r_at_s"] = predictive_power([X[n] for n in targets], list(targets.values()), folds[None]["lam"],
                                                   testable=True)
        elif slopes in ("loss", "channels"):                                        # (F8), (F9)
            table = scene_table if slopes == "loss" else scene_table_channels
            tables = {n: table(scanner.samples[((N, k), n)], u_grid) for n in names
                      if len(scanner.samples[((N, k), n)].u) >= 3}
            Xf = X if slopes == "loss" else {n: scene_terms(scenes[n], N, k, settings, per_channel=True) for n in names}
            folds = {}
            for held in [None, *names]:
                folds[held] = fold_fits_loss(names, Xf, tables, u_grid, held)
                progress(f"{label}: the loss form fitted without {held or 'no scene'}")
            power["loss"] = loss_power([Xf[n] for n in tables], u_grid, list(tables.values()), folds[None]["lam"])
        else:
            folds = {held: fold_fits(names, X, ln_s, ln_r, held, fold_anchor(res, held) if anchored else None)
                     for held in [None, *names]}
        fits[label] = {"terms": terms, "X": X, "power": power, "folds": folds}
        if slopes == "channels":
            fits[label]["X_channels"] = Xf

    if slopes in ("loss", "channels"):
        anchored = False
        loss = ("both scales' coefficients fitted on the render loss (Eq. C2) through the scan's interpolated images "
                + ("(Eq. F8 of harness.calibration.form_loss)" if slopes == "loss" else
                   "with each colour channel at its own terms (Eq. F9 of harness.calibration.form_loss)")
                + ", ridge penalty by leave-one-out")
    elif slopes == "radiance":
        anchored = True
        loss = ("sigma_scale: the source's scalar fit; ln r: ridge regression (Eq. F5 of harness.calibration.form_fit)"
                " of each training scene's best ln r at that sigma_scale (Eq. F7 of harness.calibration.form), level "
                "anchored to the scalar fit on the same scenes (Eq. F6)")
    else:
        loss = ("ridge regression (Eq. F5 of harness.calibration.form_fit) of ln s and ln r on the per-scene oracle "
                "of the source calibration" + (", level anchored to its scalar fit on the same scenes (Eq. F6)"
                                               if anchored else ""))
    fit_info = {"sources": sources, "loss": loss, "slopes": slopes,
                "anchored": anchored, "scenes": names,
                "created": datetime.now(timezone.utc).isoformat(timespec="seconds")}
    if argv:
        fit_info["command"] = command + " " + " ".join(argv)

    def toml_for(held):
        rows = [(N, k, fits[budget_label(N, k)]["terms"], fits[budget_label(N, k)]["folds"][held]["sigma"],
                 fits[budget_label(N, k)]["folds"][held]["radiance"]) for N, k in budgets]
        return form_toml(cal["mapping"], settings, rows, fit_info | ({"held_out": held} if held else {}))

    # 3. renders: every scene in-sample, each scene with its own held-out file
    figs = {"in_sample": {}, "held_out": {}}
    renders = 0
    with tempfile.TemporaryDirectory(prefix="sslpv-form-") as tmp:
        for held in [None, *names]:
            path = Path(tmp) / f"{held or 'all'}.toml"
            path.write_text(toml_for(held))
            load_calibrated(path, tuple(MAPPINGS))
            for n in (names if held is None else [held]):
                which = "in_sample" if held is None else "held_out"
                for N in sorted({N for N, _ in budgets}):
                    imgs = _render(renderer, scenes[n], path, settings, N, [k for M, k in budgets if M == N])
                    renders += 1 + sum(1 for k in imgs if not isinstance(k, int))
                    for k, f in _judge(imgs, refs[n]).items():
                        figs[which].setdefault(budget_label(N, k), {})[n] = f
                progress(f"rendered {n} with the form fitted on {'all scenes' if held is None else 'the others'}")

    # 4. figures and targets
    best = against_medians(against)
    results = {}
    for N, k in budgets:
        label = budget_label(N, k)
        src, f = cal["results"][label], fits[label]
        held = {n: figs["held_out"].get(label, {}).get(n, {"relmse": None, "energy_ratio": None}) for n in names}
        results[label] = {
            "N": N, "steps": k, "terms": list(f["terms"]),
            "coefficients": {key: f["folds"][None][key] for key in ("sigma", "radiance", "lam")},
            "folds": {n: {key: f["folds"][n][key] for key in ("sigma", "radiance", "lam")} for n in names},
            "scene_terms": f["X"], "predictive_power": f["power"],
            **({"channel_terms": f["X_channels"]} if "X_channels" in f else {}),
            "in_sample": {n: figs["in_sample"].get(label, {}).get(n, {"relmse": None, "energy_ratio": None})
                          for n in names},
            "held_out": held,
            "oracle": {n: {key: src["oracle"][n][key] for key in ("relmse", "energy_ratio", "s", "r", "at_bound")}
                       for n in names},
            "compared": src["compared"], "source": src["source"],
            "scalar": {"sigma_scale": src["sigma_scale"], "radiance_scale": src["radiance_scale"],
                       "held_out": {n: {key: src["held_out"][n][key] for key in ("relmse", "energy_ratio", "s", "r")}
                                    for n in names}},
            "targets": _targets(held, {fam: med.get(label) for fam, med in best.items()}),
        }
    info = {"format": "sslpv-calibration-form-report", "family": cal["family"], "mapping": cal["mapping"],
            "sources": sources, "anchored": anchored, "slopes": slopes, "loss": fit_info["loss"], "settings": settings, "scenes": names, "budgets": [list(b) for b in budgets],
            "against": [str(d) for d in against], "results": results, "renders": renders + scanner.renders,
            "served_from_cache": scanner.served,
            "time": {"wall_s": time.perf_counter() - t0}, "gl_renderer": renderer.gl_renderer,
            "created": fit_info["created"], "command": fit_info.get("command")}
    if results_cache is not None:
        results_cache.prune()
    with atomic_dir(out) as tmp:
        (tmp / "calibrated.toml").write_text(toml_for(None))
        load_calibrated(tmp / "calibrated.toml", tuple(MAPPINGS))        # what we write must read back
        (tmp / "calibration.json").write_text(json.dumps(info, indent=1) + "\n")
    return info


def _targets(held, best):
    """Energy ratio in range held out on every scene; median held-out relMSE at most FORM_RELMSE_FACTOR x the
    best calibrated family's (``best``: family -> its median held-out relMSE at this budget)."""
    lo, hi = ENERGY_TARGET
    outside = {n: v["energy_ratio"] for n, v in held.items()
               if v["energy_ratio"] is None or not lo <= v["energy_ratio"] <= hi}
    med = _median(v["relmse"] for v in held.values())
    known = {fam: v for fam, v in best.items() if v is not None}
    best_fam = min(known, key=known.get) if known else None
    return {"energy_range": list(ENERGY_TARGET), "energy_outside": outside, "energy_met": not outside,
            "median_held_out_relmse": med, "best_family": best_fam,
            "best_family_median": known.get(best_fam), "relmse_factor": FORM_RELMSE_FACTOR,
            "relmse_met": bool(med is not None and best_fam is not None
                               and med <= FORM_RELMSE_FACTOR * known[best_fam]),
            "better_than_best": bool(med is not None and best_fam is not None and med < known[best_fam])}


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    ap = argparse.ArgumentParser(prog="python -m harness.calibration.form", description=__doc__.splitlines()[0])
    ap.add_argument("--from", dest="source", nargs="+", required=True,
                    help="calibrate --out folders of one family (the oracle, the scalar pairs and the settings; their "
                         "budgets together, e.g. one folder per grid)")
    ap.add_argument("--out", required=True, help="the folder to write (calibrated.toml, calibration.json)")
    ap.add_argument("--against", nargs="*", default=[], help="calibrate --out folders whose held-out medians the "
                    "relMSE target compares with (default: the --from folder)")
    ap.add_argument("--free-level", action="store_true", help="the regression's own a0 and b0 (Eq. F5), not the "
                    "source's scalar pair (Eq. F6)")
    ap.add_argument("--slopes", choices=SLOPES, default="both", help="both scales from the material (Eq. F5, on the "
                    "oracle), the radiance scale alone at the scalar sigma_scale (Eq. F7), or both fitted on the render "
                    "loss (Eq. F8)")
    ap.add_argument("--no-cache", action="store_true", help="render the scan afresh instead of serving it from the "
                    "result cache (cache/results/)")
    args = ap.parse_args(argv)
    try:
        info = run_form(args.source, args.out, args.against or args.source, anchored=not args.free_level, argv=argv,
                        progress=lambda m: print(m, file=sys.stderr, flush=True), slopes=args.slopes,
                        cache=not args.no_cache)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for label, res in info["results"].items():
        t = res["targets"]
        print(f"{label}: median held-out relMSE {t['median_held_out_relmse']:.4g} (best family {t['best_family']} "
              f"{t['best_family_median']:.4g}); energy {'met' if t['energy_met'] else 'NOT met'}, relMSE "
              f"{'met' if t['relmse_met'] else 'NOT met'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
