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

This module builds the index and the site; one scene's page is
:mod:`harness.report.scene_page`, the HTML helpers :mod:`harness.report.html`.
"""

import math
import shutil
import statistics
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from harness.io.atomic import atomic_dir
from harness.io.outputs import check_replaceable, check_writable
from harness.errors import InputError
from harness.store import Store
from . import plots
from .html import HERE, _environment, _extra, _slugs
from .memo import Memo, default_memo_dir
from .scene_page import FLIPMAP, METHOD_METRICS, RELERR, _methods, _pages

#: Columns of the index's worst-cases table.
HEADLINE = (("subsurface", "relmse"), ("subsurface", "si_relmse"), ("subsurface", "energy_ratio"),
            ("subsurface", "flip"), ("full", "relmse"), ("full", "flip"))
WORST_CASES = 15


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
