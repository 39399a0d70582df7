"""The calibration's report page: ``index.html`` beside ``calibrated.toml``, opened from the file system.

Per budget it shows the fitted values with their standard errors, the loss, the issue's
two targets with their verdicts, what stops a missed target (measured: the scene's oracle
against its held-out result), a table per scene of the subsurface error under
``literal``, ``collision``, ``diffusion``, the calibrated mapping in-sample and held out,
and the scene's oracle, beside the reference's noise; plots of the loss over the scanned
``sigma_scale``; and images (reference, held-out, oracle) per scene. Everything on it
comes from ``calibration.json`` and the scan's own renders.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from harness.calibration.fit import best_scale
from harness.calibration.scan import budget_label

TEMPLATES = Path(__file__).resolve().parent / "templates"
COLUMNS = ("literal", "collision", "diffusion", "in_sample", "held_out", "oracle")
HEADS = {"literal": "literal", "collision": "collision", "diffusion": "diffusion", "in_sample": "calibrated, in-sample",
         "held_out": "calibrated, held out", "oracle": "oracle (scene alone)"}


def _fmt(v, spec=".3g"):
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    return format(v, spec)


def scene_result(res, col, name):
    """One budget's result (``calibration.json``'s ``results[budget]``) for column ``col`` of
    :data:`COLUMNS` and scene ``name``: ``{"relmse", "energy_ratio", ...}`` (the uncalibrated mappings
    are under ``compared``)."""
    return res["compared"][col][name] if col in res["compared"] else res[col][name]


def _rows(res, names, noise):
    rows = []
    for n in names:
        cells = {}
        for col in COLUMNS:
            v = scene_result(res, col, n)
            cells[col] = {"relmse": _fmt(v.get("relmse")), "energy": _fmt(v.get("energy_ratio"), ".3f"),
                          "failed": v.get("failed")}
        rows.append({"scene": n, "cells": cells, "floor": _fmt(noise[n].get("floor_halves")),
                     "from_se": _fmt(noise[n].get("from_se"))})
    return rows


def _loss_plot(path, scanner, budget, res, names):
    """ln relMSE of each scene (at the fitted radiance scale) and the loss, over the scanned sigma_scale."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from harness.io.atomic import atomic_write

    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    r = res["radiance_scale"]
    mean = None
    for n in names:
        smp = scanner.samples[(budget, n)]
        us = sorted(smp.u)
        vals = []
        for u in us:
            A, B, C = smp.coefficients(u)
            vals.append(math.log(max(A * r * r - 2 * B * r + C, 1e-300)))
        ax.plot(np.exp(us), vals, "-", lw=0.8, alpha=0.7, label=n)
    grid = sorted(set.intersection(*(set(round(u, 12) for u in scanner.samples[(budget, n)].u) for n in names)))
    mean = [best_scale([scanner.samples[(budget, n)].coefficients(u) for n in names])[1] for u in grid]
    ax.plot(np.exp(grid), mean, "k-o", ms=3, lw=2, label="loss (best radiance scale)")
    ax.axvline(res["sigma_scale"], color="k", ls=":", lw=1)
    for n, h in res["held_out"].items():
        ax.axvline(h["s"], color="grey", ls="-", lw=0.4)
    ax.set_xscale("log")
    ax.set_xlabel("sigma_scale")
    ax.set_ylabel("ln relMSE (subsurface)")
    ax.set_title(f"{budget_label(*budget)}: fitted {res['sigma_scale']:.3g} (dotted), leave-one-out fits (grey)",
                 fontsize=8)
    ax.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    with atomic_write(path) as tmp:
        fig.savefig(tmp, format="png", dpi=100)
    plt.close(fig)


def _images(folder, scanner, budget, res, refs, names):
    """PNG strips per scene: reference | calibrated held out | oracle, at one exposure per scene."""
    from harness.io.images import auto_exposure, write_png

    out = {}
    for n in names:
        ref = np.asarray(refs[n]["subsurface"], np.float64)
        exposure = auto_exposure(ref)
        tiles = {"reference": ref}
        for col in ("held_out", "oracle"):
            v = res[col][n]
            img = scanner.image(budget, n, v["s"])
            if img is not None:
                tiles[col] = img * v["r"]
        names_out = {}
        for label, img in tiles.items():
            rel = f"img/{budget[0]}_{budget[1]}_{n}_{label}.png"
            write_png(folder / rel, img.astype(np.float32), exposure)
            names_out[label] = rel
        out[n] = names_out
    return out


def write_page(folder, info, scanner, refs):
    """Write ``index.html``, ``plots/`` and ``img/`` into ``folder`` (the calibration's temporary output)."""
    import jinja2

    folder = Path(folder)
    (folder / "plots").mkdir(exist_ok=True)
    (folder / "img").mkdir(exist_ok=True)
    names = info["scenes"]
    budgets = []
    for (N, steps) in [tuple(b) for b in info["budgets"]]:
        label = budget_label(N, steps)
        res = info["results"][label]
        plot = f"plots/loss_{N}_{steps}.png"
        _loss_plot(folder / plot, scanner, (N, steps), res, names)
        budgets.append({"label": label, "res": res, "plot": plot, "rows": _rows(res, names, info["noise"]),
                        "images": _images(folder, scanner, (N, steps), res, refs, names),
                        "fmt": _fmt})
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(TEMPLATES)), autoescape=True,
                             undefined=jinja2.StrictUndefined)
    html = env.get_template("calibration.html.j2").render(info=info, budgets=budgets, columns=COLUMNS, heads=HEADS,
                                                          fmt=_fmt)
    (folder / "index.html").write_text(html)
