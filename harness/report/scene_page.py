"""One scene's page of the report: its reference, its plots and tables, one card per configuration, the methods view.

Tone mapping: the reference and every image of one kind (subsurface or full) share
one exposure, :func:`harness.io.images.auto_exposure` of the reference. The relative
error map is ``mean_c |x - y| / (y + eps)`` with ``eps`` = 1 % of the reference's mean
(over the mask), shown on [0, 1] (``RELERR``); FLIP maps (``FLIPMAP``) come from
``harness.metrics.compute("flip", ...)``. The best configuration of a scene is the
lowest ranked error within the cost budget (else the cheapest, said so). Pages are
drawn in processes of their own from :data:`PARALLEL_FROM` scenes on.
"""

import json
import os
from pathlib import Path

import numpy as np

from harness.errors import InputError
from harness.io import images
from harness.metrics.coverage import comparison_mask
from harness.store import STAGES
from . import plots
from .html import _environment, _place, _plot, _rel
from .memo import Memo

IMAGE_KINDS = ("subsurface", "full")
#: Metrics in table order (those present in the store but not listed follow).
METRIC_ORDER = ("relmse", "si_relmse", "rmse", "mae", "smape", "energy_ratio", "ssim", "flip",
                "ciede2000_mean", "ciede2000_p95")
#: (image, metric) pairs that get the error-vs-steps/grid/cost plots and the heat map.
PLOT_METRICS = (("subsurface", "relmse"), ("subsurface", "flip"), ("full", "relmse"))
RELERR = {"cmap": "viridis", "vmin": 0.0, "vmax": 1.0, "eps_fraction": 0.01}
FLIPMAP = {"cmap": "magma", "vmin": 0.0, "vmax": 1.0}


# ------------------------------------------------------------------ one scene

#: Scene pages are drawn in parallel (one process per core) from this many scenes on.
PARALLEL_FROM = 4


def _pages(jobs):
    """Each job's scene page (:func:`_page_job`), in order: in processes of their own when there are
    :data:`PARALLEL_FROM` scenes or more and more than one core (a page's pictures are independent of
    every other page's), else here."""
    workers = min(len(jobs), os.cpu_count() or 1)
    if workers > 1 and len(jobs) >= PARALLEL_FROM:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as pool:
            return list(pool.map(_page_job, jobs))
    return [_page_job(job) for job in jobs]


def _page_job(job):
    """One scene page from a picklable job -> ``(its summary, its notes, its configurations as shown,
    (memo hits, memo misses))``."""
    common, folder, scene, cs, budget, flip_on, flip_note, methods, memo_root = job
    flip_compute = None
    if flip_on:
        from harness.metrics import compute as flip_compute
    notes = []
    memo = Memo(memo_root)
    info = _scene_page(_environment(), common, folder, scene, cs, budget, flip_compute, flip_note, notes, methods,
                       memo)
    return info, notes, cs, (memo.hits, memo.misses)


def _scene_page(env, common, folder, scene, configs, budget, flip_compute, flip_note, notes, methods=("sslpv",),
                memo=None):
    """Write one scene's folder (images, EXRs, plots, index.html); returns its summary.

    ``memo`` (:class:`harness.report.memo.Memo`) serves pictures whose inputs were drawn before."""
    memo = memo or Memo(None)
    img_dir, exr_dir, plot_dir = folder / "img", folder / "exr", folder / "plots"
    for d in (img_dir, exr_dir, plot_dir):
        d.mkdir(parents=True, exist_ok=True)
    if len(methods) > 1:                           # show each configuration's method beside its parameters
        for c in configs:
            c["params"] = {"method": c.get("method", "sslpv"), **c["params"]}
    ok = [c for c in configs if c["status"] == "ok"]
    failed = [c for c in configs if c["status"] != "ok"]
    keys = plots.varying_params(configs)
    all_keys = sorted({k for c in configs for k in c["params"]})
    const = {k: configs[0]["params"].get(k) for k in all_keys if k not in keys}
    scene_notes = []

    # References: one per reference_dir (normally one per scene).
    refs, ref_of = [], {}
    for c in ok:
        rdir = c["reference_dir"]
        if rdir not in ref_of:
            ref_of[rdir] = _reference(rdir, len(refs), img_dir, exr_dir)
            refs.append(ref_of[rdir])

    cards = []
    for c in ok:
        ref = ref_of[c["reference_dir"]]
        views = {}
        for kind in IMAGE_KINDS:
            views[kind] = _views(c, kind, ref, img_dir, exr_dir, flip_compute, scene_notes, memo)
        cards.append({**c, "views": views, "timing_list": [(s, c["timings"][s]) for s in STAGES
                                                          if s in c["timings"]]})

    # Plots.
    plot_list, plot_notes = [], []
    cs_plot = [c for c in ok if c.get("method", "sslpv") == "sslpv"]   # SSLPV's axes; every method: methods view
    if not cs_plot:
        plot_notes.append("No successful configurations to plot.")
    else:
        gk = plots.grid_key(cs_plot)
        gridded = plots.has_axes(cs_plot, "steps", gk)
        refined = len({plots.num(c["params"].get(gk)) for c in cs_plot} - {None}) > 1
        for image, metric in PLOT_METRICS:
            if not any(plots.value(c, image, metric) is not None for c in cs_plot):
                plot_notes.append(f"No {metric} ({image}) values: its plots are left out.")
                continue
            tag = f"{image}_{metric}"
            if gridded:
                p = plot_dir / f"{tag}_vs_steps.png"
                _plot(memo, plots.error_vs_param, cs_plot, image, metric, p, "steps", gk)
                plot_list.append({"src": _rel(p, folder), "title": f"{metric} vs steps",
                                  "caption": f"{metric} ({image}) vs propagation steps, one line per grid "
                                             f"resolution {gk}; dotted: median noise floor."})
            if refined:        # grid refinement: also for steps = steady or auto alone
                p = plot_dir / f"{tag}_vs_grid.png"
                _plot(memo, plots.error_vs_param, cs_plot, image, metric, p, gk, "steps")
                plot_list.append({"src": _rel(p, folder), "title": f"{metric} vs grid",
                                  "caption": f"{metric} ({image}) vs grid resolution {gk}, one line per step "
                                             f"count (steady: the converged accumulation)."})
            if gridded:
                p = plot_dir / f"{tag}_heatmap.png"
                _plot(memo, plots.heatmap, cs_plot, image, metric, p)
                plot_list.append({"src": _rel(p, folder), "title": f"{metric} heat map",
                                  "caption": f"{metric} ({image}) over grid resolution {gk} \u00d7 steps."})
            if any(c["cost_ms"] is not None for c in cs_plot):
                p = plot_dir / f"{tag}_vs_cost.png"
                _plot(memo, plots.error_vs_cost, cs_plot, image, metric, p, budget)
                plot_list.append({"src": _rel(p, folder), "title": f"{metric} vs cost",
                                  "caption": f"{metric} ({image}) vs SSLPV cost; circled and joined: the Pareto "
                                             f"front (no configuration is both cheaper and better)."})
        if not gridded:
            plot_notes.append(f"The parameters have no '{gk}' and 'steps': plots over them are left out.")
        if gridded and any(plots.value(c, "subsurface", "energy_ratio") is not None for c in cs_plot):
            p = plot_dir / "energy_vs_steps.png"
            _plot(memo, plots.energy_vs_steps, cs_plot, p)
            plot_list.append({"src": _rel(p, folder), "title": "energy ratio vs steps",
                              "caption": "Left: energy ratio sum(SSLPV)/sum(reference) of the subsurface image vs "
                                         "steps, with the ratios implied by the paper's compensation factors "
                                         "(Fig. 8: \u00d73, \u00d72, \u00d71.2 at 8, 16, 32 steps). Right: the scale "
                                         "the data asks for (si_relmse's optimal per-channel scale, mean over RGB; "
                                         "1/energy ratio where it is not stored) vs the paper's factors."})

    best, best_note, worst = _best_worst(ok, budget)
    method_view = _methods_view(ok, cards, methods, budget, plot_dir, folder, memo) if len(methods) > 1 else None
    metric_names = sorted({m for c in ok for ms in c["metrics"].values() for m in ms},
                          key=lambda m: (METRIC_ORDER.index(m) if m in METRIC_ORDER else len(METRIC_ORDER), m))
    tables = [{"image": img, "metrics": [m for m in metric_names if any(m in c["metrics"].get(img, {}) for c in ok)],
               "rows": sorted(ok, key=lambda c: c["id"])}
              for img in IMAGE_KINDS if any(img in c["metrics"] for c in ok)]
    numeric_keys = {k for k in keys if all(plots.num(c["params"].get(k)) is not None for c in configs)}
    page = env.get_template("scene.html.j2").render(
        **common, root="../../",
        scene={"name": scene, "hashes": sorted({c["scene_hash"] for c in configs}), "param_keys": keys,
               "const_params": const, "n_ok": len(ok), "n_failed": len(failed)},
        refs=refs, plots=plot_list, plot_notes=plot_notes, tables=tables, configs=cards, failed=failed,
        best=best, best_note=best_note, worst=worst, numeric_keys=numeric_keys,
        relerr_bar="../../static/cbar_relerr.png", flip_bar="../../static/cbar_flip.png",
        flip_available=flip_compute is not None, flip_note=flip_note, notes=scene_notes, methods_view=method_view,
        method_metrics=METHOD_METRICS)
    (folder / "index.html").write_text(page, encoding="utf-8")
    notes.extend(f"{scene}: {n}" for n in scene_notes)
    # Thumbnails for the index: the reference and the best configuration (subsurface).
    thumbs = []
    if refs and refs[0]["png"].get("subsurface"):
        thumbs.append({"src": refs[0]["png"]["subsurface"], "alt": "reference (subsurface)"})
    for c in cards:
        if best is not None and c["id"] == best["id"] and c["views"]["subsurface"].get("test_png"):
            thumbs.append({"src": c["views"]["subsurface"]["test_png"], "alt": f"best: configuration {c['id']}"})
    return {"n_ok": len(ok), "n_failed": len(failed), "best": best and dict(best), "best_note": best_note,
            "worst": worst and dict(worst), "keys": keys, "thumbs": thumbs,
            "method_best": method_view["best"] if method_view else {}}


# ------------------------------------------------------------------ methods (harness.methods)

#: (image, metric) of the methods table and view.
METHOD_METRICS = (("subsurface", "relmse"), ("subsurface", "flip"))


def _methods(configs):
    """The methods of a run, SSLPV first (a store from before methods: SSLPV only)."""
    return sorted({c.get("method", "sslpv") for c in configs}, key=lambda m: (m != "sslpv", m))


def _methods_view(ok, cards, methods, budget, plot_dir, folder, memo):
    """Per method: the best configuration under the budget; the error-vs-cost plots across methods;
    the images side by side (reference, then each method's best)."""
    best = {}
    for m in methods:
        mine = [c for c in ok if c.get("method", "sslpv") == m]
        b, note, _ = _best_worst(mine, budget) if mine else (None, "no successful configuration", None)
        card = next((k for k in cards if b is not None and k["id"] == b["id"]), None)
        best[m] = {"config": b, "note": note, "metrics": {f"{img}/{met}": b["metrics"].get(img, {}).get(met)
                                                           for img, met in METHOD_METRICS} if b else {},
                   "precompute_ms": _precompute_ms(b) if b else None,
                   "work": total_work(b) if b else None,
                   "png": card["views"]["subsurface"].get("test_png") if card else None}
    plot_list = []
    for image, metric in METHOD_METRICS:
        if any(plots.value(c, image, metric) is not None for c in ok):
            p = plot_dir / f"methods_{image}_{metric}_vs_cost.png"
            _plot(memo, plots.methods_error_vs_cost, ok, image, metric, p, budget)
            plot_list.append({"src": _rel(p, folder), "title": f"{metric} vs cost, every method",
                              "caption": f"{metric} ({image}) of every configuration of every method against its "
                                         "frame time (left, ms on the recorded renderer) and its work count (right, "
                                         "the sum over stages of each stage's own unit: texels, cell updates, kernel "
                                         "evaluations); circled and joined: the Pareto front across methods; dotted: "
                                         "the median noise floor."})
    return {"best": best, "plots": plot_list, "methods": methods}


def _precompute_ms(c):
    pre = c.get("precompute") or {}
    vals = [v.get("ms") for v in pre.values() if isinstance(v, dict) and v.get("ms") is not None]
    return float(sum(vals)) if vals else None


def total_work(c):
    return plots.total_work(c)


def _best_worst(ok, budget):
    ranked = [c for c in ok if c["rank"] is not None]
    if not ranked:
        return None, "no ranked configuration", None
    worst = max(ranked, key=lambda c: c["rank"]["value"])
    if budget is None:
        return min(ranked, key=lambda c: c["rank"]["value"]), "", worst
    afford = [c for c in ranked if c["cost_ms"] is not None and c["cost_ms"] <= budget]
    if afford:
        return min(afford, key=lambda c: c["rank"]["value"]), "", worst
    timed = [c for c in ranked if c["cost_ms"] is not None]
    if timed:
        cheapest = min(timed, key=lambda c: (c["cost_ms"], c["rank"]["value"]))
        return cheapest, f"(none within {budget:.4g} ms; the cheapest is shown)", worst
    return None, "(no timings)", worst


def _reference(rdir, index, img_dir, exr_dir):
    """Load one reference folder, write its PNGs and place its EXRs; returns a dict for the template."""
    tag = "ref" if index == 0 else f"ref{index}"
    out = {"dir": rdir, "label": f"reference {index + 1}", "images": {}, "rgb": {}, "exposure": {}, "info": {},
           "mask": None, "png": {}, "exr": {}}
    if rdir is None:
        for kind in IMAGE_KINDS:
            out["images"][kind] = {"note": "no reference_dir recorded"}
        return out
    rdir = Path(rdir)
    meta = rdir / "reference.json"
    if meta.is_file():
        try:
            data = json.loads(meta.read_text())
            out["info"] = {k: v for k, v in data.items() if isinstance(v, (str, int, float, bool))}
        except (OSError, ValueError):
            out["info"] = {"reference.json": "unreadable"}
    for kind in IMAGE_KINDS:
        src = rdir / f"{kind}.exr"
        try:
            layers = images.read_exr(src)
        except InputError as exc:
            out["images"][kind] = {"note": str(exc)}
            continue
        rgb = layers["rgb"]
        exposure = images.auto_exposure(rgb)
        png = img_dir / f"{tag}_{kind}.png"
        images.write_png(png, rgb, exposure)
        exr = _place(src, exr_dir / f"{tag}_{kind}.exr")
        out["rgb"][kind], out["exposure"][kind] = rgb, exposure
        out["png"][kind], out["exr"][kind] = f"img/{png.name}", f"exr/{exr.name}"
        out["images"][kind] = {"png": f"img/{png.name}", "exr": f"exr/{exr.name}", "exposure": exposure}
        if out["mask"] is None and "mask" in layers:
            out["mask"] = comparison_mask(layers["mask"])
    if out["mask"] is None and (rdir / "mask.exr").is_file():
        try:
            m = images.read_exr(rdir / "mask.exr")
            out["mask"] = comparison_mask(m["mask"] if "mask" in m else m["rgb"][..., 0])
        except InputError:
            pass
    return out


def _views(c, kind, ref, img_dir, exr_dir, flip_compute, notes, memo):
    """PNGs, EXR and error maps of one image kind of one configuration."""
    v = {"ref_png": ref["png"].get(kind), "ref_exr": ref["exr"].get(kind)}
    if c["render_dir"] is None:
        v["note"] = "no render_dir recorded"
        return v
    src = Path(c["render_dir"]) / f"{kind}.exr"
    try:
        test = images.read_exr(src)["rgb"]
    except InputError as exc:
        v["note"] = str(exc)
        return v
    tag = f"c{c['id']}_{kind}"
    yref = ref["rgb"].get(kind)
    exposure = ref["exposure"].get(kind, images.auto_exposure(test))
    png = img_dir / f"{tag}.png"
    v["test_png"], v["test_exr"] = f"img/{png.name}", f"exr/{_place(src, exr_dir / f'{tag}.exr').name}"
    if yref is None:
        images.write_png(png, test, exposure)
        v["note"] = "no reference image to compare with"
        return v
    if yref.shape != test.shape:
        images.write_png(png, test, exposure)
        v["note"] = f"size {test.shape[1]}x{test.shape[0]} differs from the reference's {yref.shape[1]}x{yref.shape[0]}"
        return v
    mask = ref["mask"] if ref["mask"] is not None and ref["mask"].shape == test.shape[:2] else None
    # The three pictures are a pure function of these inputs (harness.report.memo): an unchanged
    # configuration's are copied from the memo instead of drawn (FLIP's map dominates a report's time).
    outs = [png, img_dir / f"{tag}_relerr.png"] + ([img_dir / f"{tag}_flip.png"] if flip_compute is not None else [])
    key = memo.key("views", test.tobytes(), yref.tobytes(), b"" if mask is None else mask.tobytes(), exposure,
                   RELERR, FLIPMAP, flip_compute is not None)
    memo.produce(key, outs, lambda: _draw_views(c, test, yref, mask, exposure, tag, img_dir, flip_compute, notes))
    v["relerr_png"] = f"img/{outs[1].name}"
    if len(outs) > 2 and outs[2].is_file():
        v["flip_png"] = f"img/{outs[2].name}"
    return v


def _draw_views(c, test, yref, mask, exposure, tag, img_dir, flip_compute, notes):
    """Draw a configuration's PNG, its relative-error map and its FLIP map (see :func:`_views`)."""
    images.write_png(img_dir / f"{tag}.png", test, exposure)
    sel = yref[mask] if mask is not None else yref.reshape(-1, 3)
    eps = RELERR["eps_fraction"] * max(float(np.mean(sel)) if sel.size else 0.0, 1e-12)
    rel = (np.abs(test - yref) / (np.abs(yref) + eps)).mean(axis=-1)
    if mask is not None:
        rel = np.where(mask, rel, 0.0)
    p = img_dir / f"{tag}_relerr.png"
    images.write_png_uint8(p, plots.false_colour(rel, RELERR["cmap"], RELERR["vmin"], RELERR["vmax"]))
    if flip_compute is not None:
        try:
            fmap = flip_compute("flip", test, yref, mask).error_map
        except Exception as exc:  # noqa: BLE001 - one bad map must not stop the report
            notes.append(f"FLIP map of configuration {c['id']} ({tag}) failed: {type(exc).__name__}: {exc}")
            fmap = None
        if fmap is not None:
            p = img_dir / f"{tag}_flip.png"
            images.write_png_uint8(p, plots.false_colour(fmap, FLIPMAP["cmap"], FLIPMAP["vmin"], FLIPMAP["vmax"]))
