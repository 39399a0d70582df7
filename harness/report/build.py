"""Build the static HTML report of one run of a results store.

Site layout (all links relative, so it opens from the file system)::

    index.html                 run, best configuration per scene under the budget, worst cases
    static/report.css, .js     styles; sortable tables, compare sliders, page self-check
    static/cbar_*.png          colour bars of the error maps
    scenes/<scene>/index.html  reference, plots, metric tables, one card per configuration
    scenes/<scene>/img/        tone-mapped PNGs and false-colour maps
    scenes/<scene>/exr/        the EXRs (hard links where possible, else copies)
    scenes/<scene>/plots/      matplotlib plots

Tone mapping: the reference and every SSLPV image of one kind (subsurface or
full) share one exposure, :func:`harness.io.images.auto_exposure` of the
reference. The relative error map is ``mean_c |x - y| / (y + eps)`` with
``eps`` = 1% of the reference's mean (over the mask), shown on [0, 1];
FLIP maps come from ``harness.metrics.compute("flip", ...)``.
"""

import json
import math
import os
import re
import shutil
import statistics
from datetime import datetime, timezone
from pathlib import Path

import jinja2
import numpy as np
from markupsafe import Markup, escape

from harness.io import images
from harness.io.atomic import atomic_dir
from harness.io.outputs import check_replaceable, check_writable
from harness.errors import InputError
from harness.metrics.coverage import comparison_mask
from harness.store import STAGES, Store
from . import plots
from .memo import Memo, configs_digest, default_memo_dir

HERE = Path(__file__).resolve().parent
IMAGE_KINDS = ("subsurface", "full")
#: Metrics in table order (those present in the store but not listed follow).
METRIC_ORDER = ("relmse", "si_relmse", "rmse", "mae", "smape", "energy_ratio", "ssim", "flip",
                "ciede2000_mean", "ciede2000_p95")
#: (image, metric) pairs that get the error-vs-steps/grid/cost plots and the heat map.
PLOT_METRICS = (("subsurface", "relmse"), ("subsurface", "flip"), ("full", "relmse"))
#: Columns of the index's worst-cases table.
HEADLINE = (("subsurface", "relmse"), ("subsurface", "si_relmse"), ("subsurface", "energy_ratio"),
            ("subsurface", "flip"), ("full", "relmse"), ("full", "flip"))
WORST_CASES = 15
RELERR = {"cmap": "viridis", "vmin": 0.0, "vmax": 1.0, "eps_fraction": 0.01}
FLIPMAP = {"cmap": "magma", "vmin": 0.0, "vmax": 1.0}


def build_report(store_path, out_dir, run_id=None, cost_budget_ms=None, title=None, extra_sections=None,
                 *, rank=("subsurface", "relmse"), flip_maps=True, memo=True):
    """Write the report of one run of ``store_path`` to ``out_dir`` (replaced atomically).

    Parameters
    ----------
    store_path : path
        A results store (:class:`harness.store.Store`); it must exist.
    out_dir : path
        The site folder; an existing one is replaced only once the new site is complete.
    run_id : int, optional
        The run to report; default the latest run that has configurations.
    cost_budget_ms : float, optional
        The SSLPV cost (total ms per frame) that the best configuration of a
        scene must not exceed; default the median cost over the run.
    title : str, optional
    extra_sections : list of dict, optional
        ``{"title": str, "html": str}`` (trusted HTML) or ``{"title", "text"}``,
        appended to the index page.
    rank : (image, metric)
        What "best" and "worst" mean (lower is better).
    flip_maps : bool
        Compute FLIP error maps (about a second per image).

    Returns
    -------
    dict
        ``out_dir``, ``index``, ``scene_pages`` ({scene: path}), ``run_id``,
        ``budget_ms``, ``budget_rule``, ``n_configs``, ``n_failed``, ``notes``.
    """
    store_path = Path(store_path)
    out_dir = Path(out_dir)
    if not store_path.is_file():
        raise InputError(store_path, "file", "does not exist", "pass the results store that a sweep wrote")
    if cost_budget_ms is not None and not (math.isfinite(float(cost_budget_ms)) and float(cost_budget_ms) > 0):
        raise InputError("--budget-ms", "budget_ms", f"must be a finite number > 0, got {cost_budget_ms!r}",
                         "give the SSLPV cost budget in ms, e.g. 250")
    check_replaceable(out_dir)
    check_writable(out_dir, "--out")
    with Store(store_path, readonly=True) as st:
        runs = st.runs()
        if not runs:
            raise InputError(store_path, "runs", "the store has no runs", "run a sweep first")
        if run_id is None:
            with_configs = [r for r in runs if r["n_configs"] > 0]
            run = (with_configs or runs)[-1]
        else:
            run = st.run(run_id)
        configs = st.configs(run["id"])

    rank = tuple(rank)
    rank_label = f"{rank[1]} ({rank[0]})"
    notes = []
    ok = [c for c in configs if c["status"] == "ok"]
    failed = [c for c in configs if c["status"] != "ok"]
    for c in configs:
        c["rank"] = c["metrics"].get(rank[0], {}).get(rank[1])

    costs = [c["cost_ms"] for c in ok if c["cost_ms"] is not None]
    if cost_budget_ms is not None:
        budget, rule = float(cost_budget_ms), "given"
        budget_text = f"Budget: {budget:.4g} ms (given)."
    elif costs:
        budget, rule = float(statistics.median(costs)), "median"
        budget_text = (f"Budget: {budget:.4g} ms, the median cost of the {len(costs)} successful "
                       f"configurations of this run (pass cost_budget_ms to change it).")
    else:
        budget, rule = None, "none"
        budget_text = "No timings were recorded, so there is no budget: best = lowest error."

    flip_compute, flip_note = None, ""
    if flip_maps:
        try:
            from harness.metrics import compute as flip_compute
        except Exception as exc:  # noqa: BLE001 - the report works without the metrics module
            flip_note = f"harness.metrics could not be imported ({type(exc).__name__}: {exc})."
            notes.append("FLIP maps skipped: " + flip_note)
    else:
        flip_note = "disabled (flip_maps=False)."

    memo = Memo(default_memo_dir()) if memo is True else (memo or Memo(None))
    env = _environment()
    title = title or f"SSLPV vs Mitsuba 3 \u2014 run {run['id']} ({run['kind']}, {run['date']})"
    common = {"title": title, "run": run, "generated_at": datetime.now(timezone.utc).isoformat(timespec="seconds"),
              "store_name": store_path.name, "rank_label": rank_label, "budget_text": budget_text}

    by_scene = {}
    for c in configs:
        by_scene.setdefault(c["scene"], []).append(c)
    slugs = _slugs(by_scene)
    methods = _methods(configs)                    # more than one: the methods view and table

    scene_rows, worst_all, pages = [], [], {}
    with atomic_dir(out_dir) as site:
        static = site / "static"
        shutil.copytree(HERE / "static", static)
        plots.colour_bar(static / "cbar_relerr.png", RELERR["cmap"], RELERR["vmin"], RELERR["vmax"],
                         "relative error |test \u2212 ref| / (ref + \u03b5)")
        plots.colour_bar(static / "cbar_flip.png", FLIPMAP["cmap"], FLIPMAP["vmin"], FLIPMAP["vmax"],
                         "FLIP error", extend="neither")
        jobs = [(common, site / "scenes" / slugs[scene], scene, cs, budget, flip_compute is not None, flip_note,
                 methods, memo.root) for scene, cs in by_scene.items()]
        for (scene, _), (info, page_notes, cs, counts) in zip(by_scene.items(), _pages(jobs)):
            notes += page_notes
            memo.hits, memo.misses = memo.hits + counts[0], memo.misses + counts[1]
            slug = slugs[scene]
            href = f"scenes/{slug}/index.html"
            pages[scene] = out_dir / href
            for c in (info["best"], info["worst"]):
                if c is not None:
                    c["href"] = f"{href}#c{c['id']}"
            thumbs = [{"src": f"scenes/{slug}/{t['src']}", "alt": t["alt"]} for t in info["thumbs"]]
            for b in info["method_best"].values():
                if b.get("config") is not None:
                    b["href"] = f"{href}#c{b['config']['id']}"
            scene_rows.append({"name": scene, "href": href, "n_ok": info["n_ok"], "n_failed": info["n_failed"],
                               "thumbs": thumbs, "method_best": info["method_best"],
                               "best": info["best"], "best_note": info["best_note"], "worst": info["worst"],
                               "param_keys": info["keys"]})
            for c in cs:
                if c["status"] == "ok" and c["rank"] is not None:
                    worst_all.append({**c, "href": f"{href}#c{c['id']}", "scene_href": href,
                                      "param_keys": info["keys"]})
        scene_rows.sort(key=lambda s: -(s["worst"]["rank"]["value"] if s["worst"] else -np.inf))
        worst_all.sort(key=lambda c: -c["rank"]["value"])
        if configs and not any(c["rank"] is not None for c in configs):
            notes.append(f"No configuration has {rank_label}; best/worst cannot be ranked.")
        html = env.get_template("index.html.j2").render(
            **common, root="", scenes=scene_rows, worst_cases=worst_all[:WORST_CASES], headline=HEADLINE,
            methods=methods, method_metrics=METHOD_METRICS,
            n_ok=len(ok), n_failed=len(failed), extra_sections=_extra(extra_sections), notes=notes)
        (site / "index.html").write_text(html, encoding="utf-8")

    return {"out_dir": out_dir, "index": out_dir / "index.html", "scene_pages": pages, "run_id": run["id"],
            "budget_ms": budget, "budget_rule": rule, "n_configs": len(configs), "n_failed": len(failed),
            "notes": notes, "pictures": {"kept": memo.hits, "drawn": memo.misses}}


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


# ------------------------------------------------------------------ helpers

def _plot(memo, draw, configs, *args):
    """``draw(configs, *args)`` (a function of :mod:`harness.report.plots`; its output path among ``args``),
    or its picture from the memo when the same configurations were drawn the same way before."""
    outs = [a for a in args if isinstance(a, Path)]
    key = memo.key("plot", draw.__name__, configs_digest(configs), [a.name if isinstance(a, Path) else a for a in args])
    memo.produce(key, outs, lambda: draw(configs, *args))


def _place(src, dst):
    """Hard-link ``src`` to ``dst`` (a copy when linking is not possible); returns ``dst``.

    A hard link is free and keeps the site self-contained: it survives the
    deletion of the render folder, and an atomic rewrite of the source (a new
    file) does not change the report's snapshot.
    """
    dst = Path(dst)
    if dst.exists():
        dst.unlink()
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)
    return dst


def _rel(path, folder):
    return Path(os.path.relpath(path, folder)).as_posix()


def _slugs(names):
    out, used = {}, set()
    for name in names:
        base = re.sub(r"[^A-Za-z0-9_.-]+", "_", str(name)).strip("._") or "scene"
        slug, i = base, 2
        while slug.lower() in used:
            slug, i = f"{base}_{i}", i + 1
        used.add(slug.lower())
        out[name] = slug
    return out


def _extra(sections):
    out = []
    for s in sections or ():
        if isinstance(s, (tuple, list)):
            s = {"title": s[0], "html": s[1]}
        if "html" in s:
            body = Markup(s["html"])
        else:
            body = Markup("<p>") + escape(s.get("text", "")) + Markup("</p>")
        out.append({"title": s.get("title", ""), "html": body})
    return out


def _fmt(v):
    if v is None:
        return "\u2013"
    if isinstance(v, bool):
        return str(v)
    if isinstance(v, (int, float, np.floating, np.integer)):
        v = float(v)
        if not np.isfinite(v):
            return str(v)
        if v == 0:
            return "0"
        if 1e-3 <= abs(v) < 1e5:
            return f"{v:.4g}"
        return f"{v:.3e}"
    return str(v)


def _sortkey(v):
    """A ``data-sort`` value: numbers as repr, others as text, None as empty."""
    if v is None:
        return ""
    if isinstance(v, bool):
        return str(v)
    n = plots.num(v)
    if n is not None:
        return repr(n)
    return json.dumps(v) if isinstance(v, (list, dict)) else str(v)


def _pv(v):
    """A parameter value for display."""
    if isinstance(v, (list, tuple)):
        return "\u00d7".join(_pv(x) for x in v)
    if isinstance(v, dict):
        return json.dumps(v, sort_keys=True)
    return _fmt(v) if isinstance(v, float) else str(v)


def _environment():
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(HERE / "templates"), autoescape=True,
                             undefined=jinja2.StrictUndefined, trim_blocks=True, lstrip_blocks=True)
    env.filters.update(fmt=_fmt, sortkey=_sortkey, pv=_pv)
    return env
