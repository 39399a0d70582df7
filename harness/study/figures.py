"""The study's figures, each as SVG and PNG (ready to cite), drawn from the results table.

* ``pareto``: per scene, the subsurface error (the study's first metric) against the frame's cost
  in ms on this device (the work counts are in the table; ``steady`` has none), every row as a point coloured
  by family, the Pareto front of all methods as a line, the reference's noise floor dashed;
* ``refine_k``: per scene, the error against K at the budget's N for each SSLPV family
  (``steady`` drawn at the right, apart);
* ``refine_n``: per scene, the error against N at one K (the largest integer K of the budget that
  the study rendered at more than one N) for each SSLPV family;
* ``images_<scene>``: the reference and the headline's best setting of each family side by side,
  over their per-pixel relative squared error (the relMSE's map, same colour scale).

Limits: log axes need positive values (a zero error is drawn at the axis' floor); the images are
tone-mapped with one exposure per scene (the reference's 99th percentile).
"""

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402
import numpy as np  # noqa: E402

from harness.io.atomic import atomic_write  # noqa: E402
from harness.io.images import read_exr  # noqa: E402
from harness.report.plots import pareto_front  # noqa: E402

DPI = 110


def _save(fig, folder, name):
    """``name.svg`` and ``name.png`` in ``folder``; returns the names."""
    out = []
    for ext in ("svg", "png"):
        with atomic_write(folder / f"{name}.{ext}") as tmp:
            fig.savefig(tmp, format=ext, dpi=DPI, bbox_inches="tight",
                        metadata={"Date": None} if ext == "svg" else None)
        out.append(f"{name}.{ext}")
    plt.close(fig)
    return out


def _grid(n, w=3.2, h=2.6, cols=4):
    cols = min(cols, n)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(w * cols + 1.8, h * rows), squeeze=False)
    flat = list(axes.flat)
    for ax in flat[n:]:
        ax.set_visible(False)
    return fig, flat[:n]


def _colours(families):
    cmap = plt.get_cmap("tab10")
    return {f: cmap(i % 10) for i, f in enumerate(families)}


def _val(r, metric):
    v = r.get(f"subsurface_{metric}")
    if v is None:
        return None
    return max(abs(v - 1.0) if metric == "energy_ratio" else v, 1e-6)


def _axis_name(metric):
    return "|energy ratio - 1|" if metric == "energy_ratio" else metric


def pareto(rows, scenes, families, metric, folder):
    """Error against work count per scene; returns the file names."""
    col = _colours(families)
    fig, axes = _grid(len(scenes))
    for ax, scene in zip(axes, scenes):
        rs = [r for r in rows if r["scene"] == scene and r["frame_ms"] and _val(r, metric) is not None]
        for fam in families:
            pts = [(r["frame_ms"], _val(r, metric)) for r in rs if r["family"] == fam]
            if pts:
                ax.scatter(*zip(*pts), s=10, color=col[fam], label=fam, marker="o" if rs and fam in
                           {r["family"] for r in rs if r["method"] == "sslpv"} else "s")
        pts = [(r["frame_ms"], _val(r, metric)) for r in rs]
        front = pareto_front(pts)
        if front:
            ax.plot([pts[i][0] for i in front], [pts[i][1] for i in front], color="k", lw=0.8)
        fl = [r.get(f"subsurface_{metric}_floor") for r in rs if r.get(f"subsurface_{metric}_floor") is not None]
        if fl and metric != "energy_ratio":
            ax.axhline(float(np.median(fl)), color="0.5", ls="--", lw=0.8)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_title(scene, fontsize=8)
        ax.tick_params(labelsize=6)
    axes[0].set_ylabel(f"{_axis_name(metric)} (subsurface)", fontsize=7)
    axes[-1].set_xlabel("frame ms on this device", fontsize=7)
    handles = {f: plt.Line2D([], [], color=col[f], marker="o", ls="") for f in families}
    fig.legend(handles.values(), handles.keys(), fontsize=7, loc="upper right")
    fig.suptitle("Error against cost (black: Pareto front; dashed: the reference's noise floor)", fontsize=9)
    fig.tight_layout(rect=(0, 0, 0.86, 0.96))
    return _save(fig, folder, "pareto")


def _k_pos(k, ints):
    return len(ints) if k == "steady" else ints.index(int(k))


def refine_k(rows, scenes, families, metric, budget, folder):
    """Error against K at the budget's N, per scene and SSLPV family."""
    col = _colours(families)
    ks = [str(k) for k in budget["steps"]]
    ints = sorted({int(k) for r in rows if r["method"] == "sslpv" for k in [r["K"]] if str(k).isdigit()})
    fig, axes = _grid(len(scenes))
    for ax, scene in zip(axes, scenes):
        for fam in families:
            rs = [r for r in rows if r["scene"] == scene and r["family"] == fam and r["method"] == "sslpv"
                  and r["N"] == budget["grid"] and r["K"] in ks + [str(i) for i in ints]]
            best = {}
            for r in rs:          # one line per family: its best setting at each K
                v = _val(r, metric)
                if v is not None and (r["K"] not in best or v < best[r["K"]]):
                    best[r["K"]] = v
            pts = sorted((_k_pos(k, ints), v) for k, v in best.items())
            if pts:
                ax.plot(*zip(*pts), marker="o", ms=3, lw=1, color=col[fam], label=fam)
        ax.set_xticks(range(len(ints) + 1), [str(i) for i in ints] + ["steady"], fontsize=6)
        ax.set_yscale("log")
        ax.set_title(scene, fontsize=8)
        ax.tick_params(labelsize=6)
    return _finish_refinement(fig, axes, metric, f"propagation steps K (N = {budget['grid']})",
                              "Error against the propagation steps", folder, "refine_k")


def refine_n(rows, scenes, families, metric, budget, folder):
    """Error against N at one K, per scene and SSLPV family (None when no K has more than one N)."""
    col = _colours(families)
    ns_at = {}
    for r in rows:
        if r["method"] == "sslpv" and str(r["K"]).isdigit():
            ns_at.setdefault(int(r["K"]), set()).add(r["N"])
    ks = [k for k in ns_at if len(ns_at[k]) > 1]
    if not ks:
        return None
    budget_ints = [int(k) for k in budget["steps"] if str(k).isdigit()]
    k = max([x for x in ks if x in budget_ints] or ks)
    fig, axes = _grid(len(scenes))
    for ax, scene in zip(axes, scenes):
        for fam in families:
            best = {}
            for r in rows:
                if (r["scene"] == scene and r["family"] == fam and r["method"] == "sslpv" and r["K"] == str(k)):
                    v = _val(r, metric)
                    if v is not None and (r["N"] not in best or v < best[r["N"]]):
                        best[r["N"]] = v
            if len(best) > 1:
                pts = sorted(best.items())
                ax.plot(*zip(*pts), marker="o", ms=3, lw=1, color=col[fam], label=fam)
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_title(scene, fontsize=8)
        ax.tick_params(labelsize=6)
    return _finish_refinement(fig, axes, metric, f"grid resolution N (K = {k})",
                              "Error against the grid resolution", folder, "refine_n")


def _finish_refinement(fig, axes, metric, xlabel, title, folder, name):
    """Labels, one legend and the title of a refinement figure (one panel per scene); saves it."""
    axes[0].set_ylabel(f"{_axis_name(metric)} (subsurface)", fontsize=7)
    axes[-1].set_xlabel(xlabel, fontsize=7)
    h, lab = axes[0].get_legend_handles_labels()
    fig.legend(h, lab, fontsize=7, loc="upper right")
    fig.suptitle(title, fontsize=9)
    fig.tight_layout(rect=(0, 0, 0.86, 0.96))
    return _save(fig, folder, name)


def _tonemap(rgb, scale):
    return np.clip(np.asarray(rgb, dtype=np.float64) * scale, 0.0, 1.0) ** (1 / 2.2)   # negative radiance: black


def images(scene, cells, families, folder, eps=1e-2):
    """Reference and each family's headline best, over their relative squared error maps."""
    fams = [f for f in families if f in cells]
    if not fams:
        return None
    first = cells[fams[0]]["row"]
    ref = read_exr(f"{first['reference_dir']}/subsurface.exr")["rgb"].astype(np.float64)
    lum = ref.mean(axis=-1)
    scale = 1.0 / max(float(np.percentile(lum[lum > 0], 99)) if np.any(lum > 0) else 1.0, 1e-12)
    fig, axes = plt.subplots(2, len(fams) + 1, figsize=(1.6 * (len(fams) + 1), 3.6), squeeze=False)
    axes[0][0].imshow(_tonemap(ref, scale))
    axes[0][0].set_title("reference", fontsize=6)
    axes[1][0].axis("off")
    im = None
    for j, fam in enumerate(fams, start=1):
        r = cells[fam]["row"]
        x = read_exr(f"{r['render_dir']}/subsurface.exr")["rgb"].astype(np.float64)
        axes[0][j].imshow(_tonemap(x, scale))
        axes[0][j].set_title(f"{fam}\n{r['setting'][:28]}", fontsize=5)
        err = ((x - ref) ** 2 / (ref ** 2 + eps)).mean(axis=-1)
        im = axes[1][j].imshow(err, cmap="magma", vmin=0.0, vmax=1.0)
        axes[1][j].set_title(f"relMSE {r['subsurface_relmse']:.3g}", fontsize=5)
    for ax in np.asarray(axes).flat:
        ax.set_xticks([])
        ax.set_yticks([])
    if im is not None:
        fig.colorbar(im, ax=list(np.asarray(axes)[1]), fraction=0.02, pad=0.01).ax.tick_params(labelsize=5)
    fig.suptitle(f"{scene}: the best setting of each family (top) and its relative squared error "
                 "(bottom; whole image, not only the compared pixels)", fontsize=6)
    return _save(fig, folder, f"images_{scene}")
