"""Matplotlib (Agg) plots and false-colour maps for the report.

Every plot takes the configuration dicts of :meth:`harness.store.Store.configs`
for ONE scene and writes one PNG. Configurations are split into *facets*:
one panel per value of the parameters other than ``grid`` and ``steps`` that
vary within the scene (``mapping``, ...), so that lines never mix settings.
"""

import math
from collections import defaultdict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from harness.io.atomic import atomic_write  # noqa: E402

#: Paper Fig. 8 (Borlum et al. 2011): the subsurface part was scaled by these
#: factors at 8, 16 and 32 propagation steps to compensate lost energy.
PAPER_COMPENSATION = {8: 3.0, 16: 2.0, 32: 1.2}

#: Parameters that are plotted on axes; every other varying one makes facets.
#: The grid resolution is ``N`` in :class:`sslpv_gl.params.SSLPVParams` (``grid`` is accepted too).
AXIS_PARAMS = ("N", "grid", "steps")
GRID_KEYS = ("N", "grid")

DPI = 96


# ------------------------------------------------------------------ data access

def num(v):
    """A parameter as one number for an axis: lists (a per-axis grid) give their maximum."""
    if isinstance(v, (list, tuple)):
        vals = [num(x) for x in v]
        vals = [x for x in vals if x is not None]
        return max(vals) if vals else None
    if isinstance(v, bool) or v is None:
        return None
    try:
        return float(v)
    except (TypeError, ValueError):
        return None


def value(c, image, metric):
    """The metric's value for configuration ``c``, or None."""
    m = c["metrics"].get(image, {}).get(metric)
    return None if m is None else m["value"]


def floor(c, image, metric):
    m = c["metrics"].get(image, {}).get(metric)
    return None if m is None else m["noise_floor"]


def varying_params(configs):
    """Names of the parameters whose values differ between ``configs``: grid, steps, then the rest sorted."""
    keys = sorted({k for c in configs for k in c["params"]}, key=_param_order)
    out = []
    for k in keys:
        seen = {repr(c["params"].get(k)) for c in configs}
        if len(seen) > 1:
            out.append(k)
    return out


def _param_order(k):
    return (0, AXIS_PARAMS.index(k), "") if k in AXIS_PARAMS else (1, 0, k)


def facets(configs):
    """``{label: [configs]}``: one facet per combination of the varying non-axis parameters."""
    keys = [k for k in varying_params(configs) if k not in AXIS_PARAMS]
    out = defaultdict(list)
    for c in configs:
        label = ", ".join(f"{k}={c['params'].get(k)}" for k in keys) or "all"
        out[label].append(c)
    return dict(sorted(out.items()))


def _line_value(v):
    """A line's key: a number, or a word such as ``steady`` or ``auto`` for ``steps`` (its own line)."""
    n = num(v)
    return v if n is None and isinstance(v, str) else n


def steps_key(k):
    """Sort key of step counts and modes together: counts first, in order, then the named modes
    (``auto``, ``steady``); a list may mix int and str."""
    return (isinstance(k, str), k if isinstance(k, str) else float(k))


def _series(configs, x_param, line_param, image, metric):
    """``{line value: sorted [(x, y)]}``, numeric lines first, then named ones (``steps = steady``);
    configurations lacking either parameter are left out."""
    lines = defaultdict(list)
    for c in configs:
        x, ln, y = num(c["params"].get(x_param)), _line_value(c["params"].get(line_param)), value(c, image, metric)
        if x is None or ln is None or y is None:
            continue
        lines[ln].append((x, y))
    order = sorted(lines, key=steps_key)
    return {k: sorted(lines[k]) for k in order}


def grid_key(configs):
    """The name of the grid-resolution parameter in ``configs`` (``N`` or ``grid``)."""
    for k in GRID_KEYS:
        if any(k in c["params"] for c in configs):
            return k
    return GRID_KEYS[0]


def has_axes(configs, *params):
    return any(all(num(c["params"].get(p)) is not None for p in params) for c in configs)


def pareto_front(points):
    """Indices of the points (cost, error) that no other point beats in both (lower is better),
    ordered by cost."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], math.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


# ------------------------------------------------------------------ figure helpers

def _label(image, metric):
    return f"{metric} ({image})"


def _logy(ax, ys):
    ys = [y for y in ys if y is not None and y > 0]
    if ys and max(ys) / min(ys) > 30:
        ax.set_yscale("log")


def _save(fig, path):
    with atomic_write(path) as tmp:
        fig.savefig(tmp, format="png", dpi=DPI, bbox_inches="tight")
    plt.close(fig)


def _panels(n, width=4.2, height=3.2):
    fig, axes = plt.subplots(1, n, figsize=(width * n, height), squeeze=False, sharey=True)
    return fig, axes[0]


def _floor_line(ax, configs, image, metric):
    fl = [f for f in (floor(c, image, metric) for c in configs) if f is not None]
    if fl:
        ax.axhline(float(np.median(fl)), color="0.5", ls=":", lw=1, label="noise floor (median)")


# ------------------------------------------------------------------ plots

def error_vs_param(configs, image, metric, path, x_param="steps", line_param="N"):
    """Metric vs ``x_param``, one line per ``line_param`` value, one panel per facet."""
    groups = facets(configs)
    fig, axes = _panels(len(groups))
    ys = []
    for ax, (label, cs) in zip(axes, groups.items()):
        for ln, pts in _series(cs, x_param, line_param, image, metric).items():
            xs, yv = zip(*pts)
            ys += yv
            ax.plot(xs, yv, "o-", label=f"{line_param} {ln if isinstance(ln, str) else format(ln, 'g')}")
        _floor_line(ax, cs, image, metric)
        ax.set_title(label, fontsize=9)
        ax.set_xlabel(x_param)
        if x_param in AXIS_PARAMS:
            ax.set_xscale("log", base=2)
            ax.xaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    axes[0].set_ylabel(_label(image, metric))
    _logy(axes[0], ys)
    fig.suptitle(f"{_label(image, metric)} vs {x_param}", fontsize=10)
    _save(fig, path)


def heatmap(configs, image, metric, path):
    """Metric over grid resolution x propagation steps, one panel per facet (annotated cells)."""
    groups = facets(configs)
    fig, axes = plt.subplots(1, len(groups), figsize=(4.4 * len(groups), 3.6), squeeze=False)
    allv = [v for v in (value(c, image, metric) for c in configs) if v is not None]
    use_log = bool(allv) and min(allv) > 0 and max(allv) / min(allv) > 30
    norm = (matplotlib.colors.LogNorm(min(allv), max(allv)) if use_log
            else matplotlib.colors.Normalize(min(allv, default=0), max(allv, default=1)))
    im, gk = None, grid_key(configs)
    for n, (ax, (label, cs)) in enumerate(zip(axes[0], groups.items())):
        grids = sorted({num(c["params"].get(gk)) for c in cs} - {None})
        steps = sorted({num(c["params"].get("steps")) for c in cs} - {None})
        z = np.full((len(grids), len(steps)), np.nan)
        for c in cs:
            g, s, v = num(c["params"].get(gk)), num(c["params"].get("steps")), value(c, image, metric)
            if g is not None and s is not None and v is not None:
                z[grids.index(g), steps.index(s)] = v
        im = ax.imshow(np.ma.masked_invalid(z), cmap="magma", norm=norm, origin="lower", aspect="auto")
        ax.set_xticks(range(len(steps)), [f"{s:g}" for s in steps])
        ax.set_yticks(range(len(grids)), [f"{g:g}" for g in grids])
        ax.set_xlabel("steps")
        if n == 0:
            ax.set_ylabel(f"grid {gk}")
        ax.set_title(label, fontsize=9)
        for (i, j), v in np.ndenumerate(z):
            if np.isfinite(v):
                bright = norm(v) > 0.6
                ax.text(j, i, f"{v:.3g}", ha="center", va="center", fontsize=7,
                        color="black" if bright else "white")
    if im is not None:
        fig.colorbar(im, ax=axes[0].tolist(), label=_label(image, metric))
    fig.suptitle(f"{_label(image, metric)} over grid {gk} x steps", fontsize=10)
    _save(fig, path)


def error_vs_cost(configs, image, metric, path, budget_ms=None):
    """Metric vs SSLPV cost (total ms), facets as colours, Pareto front highlighted."""
    fig, ax = plt.subplots(figsize=(6.0, 4.0))
    pts, labels = [], []
    for k, (label, cs) in enumerate(facets(configs).items()):
        mine = [(c["cost_ms"], value(c, image, metric)) for c in cs]
        mine = [p for p in mine if p[0] is not None and p[1] is not None]
        if mine:
            xs, ys = zip(*mine)
            ax.scatter(xs, ys, s=22, color=f"C{k}", label=label, zorder=2)
        pts += mine
        labels += [label] * len(mine)
    if pts:
        front = [pts[i] for i in pareto_front(pts)]
        fx, fy = zip(*front)
        ax.step(fx, fy, where="post", color="black", lw=1.2, zorder=1)
        ax.scatter(fx, fy, s=70, facecolors="none", edgecolors="black", lw=1.3, label="Pareto front", zorder=3)
        _logy(ax, [p[1] for p in pts])
        if all(p[0] > 0 for p in pts) and max(p[0] for p in pts) / min(p[0] for p in pts) > 30:
            ax.set_xscale("log")
    if budget_ms is not None:
        ax.axvline(budget_ms, color="C3", ls="--", lw=1, label=f"budget {budget_ms:.3g} ms")
    _floor_line(ax, configs, image, metric)
    ax.set_xlabel("SSLPV cost (ms, total)")
    ax.set_ylabel(_label(image, metric))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    ax.set_title(f"{_label(image, metric)} vs cost", fontsize=10)
    _save(fig, path)


def optimal_scale(c, image="subsurface"):
    """The per-step scale the data asks for: si_relmse's optimal scale averaged over channels,
    else 1/energy_ratio; None when neither is stored."""
    m = c["metrics"].get(image, {})
    scales = (m.get("si_relmse") or {}).get("params", {}) or {}
    scales = scales.get("scales")
    if scales:
        return float(np.mean(scales))
    er = (m.get("energy_ratio") or {}).get("value")
    return 1.0 / er if er else None


def energy_vs_steps(configs, path, image="subsurface"):
    """Left: energy ratio vs steps (lines per grid) with the paper's implied ratios 1/c.
    Right: the compensation factor the data gives vs the paper's (Fig. 8)."""
    groups = facets(configs)
    fig, axes = plt.subplots(1, 2, figsize=(10.0, 3.8), squeeze=False)
    left, right = axes[0]
    ps, pc = sorted(PAPER_COMPENSATION), [PAPER_COMPENSATION[s] for s in sorted(PAPER_COMPENSATION)]
    markers, gk = "osD^v<>p*h", grid_key(configs)
    for k, (label, cs) in enumerate(groups.items()):
        for j, (g, pts) in enumerate(_series(cs, "steps", gk, image, "energy_ratio").items()):
            xs, ys = zip(*pts)
            left.plot(xs, ys, marker=markers[j % len(markers)], color=f"C{k}", ls="-", ms=4,
                      label=f"{label}, {gk} {g:g}" if len(groups) > 1 else f"{gk} {g:g}")
            sc = [(num(c["params"].get("steps")), optimal_scale(c, image)) for c in cs
                  if num(c["params"].get(gk)) == g]
            sc = sorted(p for p in sc if p[0] is not None and p[1] is not None)
            if sc:
                sx, sy = zip(*sc)
                right.plot(sx, sy, marker=markers[j % len(markers)], color=f"C{k}", ms=4,
                           label=f"{label}, {gk} {g:g}" if len(groups) > 1 else f"{gk} {g:g}")
    left.plot(ps, [1 / c for c in pc], "k*", ms=11, label="paper 1/c (Fig. 8)")
    left.axhline(1.0, color="0.5", lw=0.8)
    left.set_ylabel(f"energy ratio ({image}), test/ref")
    right.plot(ps, pc, "k*--", ms=11, label="paper c (Fig. 8)")
    right.axhline(1.0, color="0.5", lw=0.8)
    right.set_ylabel("compensation scale")
    right.set_title("optimal scale from data (si_relmse, mean over RGB) vs paper", fontsize=9)
    left.set_title("energy ratio vs steps", fontsize=9)
    for ax in (left, right):
        ax.set_xlabel("steps")
        ax.set_xscale("log", base=2)
        ax.xaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    _save(fig, path)


# ------------------------------------------------------------------ false colour

def false_colour(arr, cmap="magma", vmin=0.0, vmax=1.0):
    """A float ``(H, W)`` map -> uint8 RGB through a matplotlib colour map (values clipped)."""
    x = np.clip((np.nan_to_num(np.asarray(arr, dtype=np.float64)) - vmin) / (vmax - vmin), 0.0, 1.0)
    rgba = matplotlib.colormaps[cmap](x)
    return (rgba[..., :3] * 255.0 + 0.5).astype(np.uint8)


def colour_bar(path, cmap, vmin, vmax, label, extend="max"):
    """A horizontal colour bar as its own small PNG (shared by all maps of one kind)."""
    fig = plt.figure(figsize=(4.0, 0.65))
    ax = fig.add_axes([0.04, 0.55, 0.92, 0.3])
    sm = matplotlib.cm.ScalarMappable(norm=matplotlib.colors.Normalize(vmin, vmax), cmap=cmap)
    cb = fig.colorbar(sm, cax=ax, orientation="horizontal", extend=extend)
    cb.set_label(label, fontsize=8)
    cb.ax.tick_params(labelsize=7)
    _save(fig, path)


# ------------------------------------------------------------------ methods (harness.methods)

METHOD_MARKERS = {"sslpv": "o", "dipole": "s", "dirpole": "^"}


def total_work(c):
    """A configuration's work count: the sum over its frame stages (None when not recorded)."""
    w = c.get("work")
    return float(sum(w.values())) if w else None


def methods_error_vs_cost(configs, image, metric, path, budget_ms=None):
    """Metric vs per-frame cost for every configuration of every method, two panels: the frame
    time (ms on the recorded renderer) and the device-independent work count; the Pareto front
    is taken across all methods in each panel."""
    fig, axes = plt.subplots(1, 2, figsize=(11.0, 4.0))
    methods = sorted({c.get("method", "sslpv") for c in configs}, key=lambda m: (m != "sslpv", m))
    for ax, (xlabel, xof) in zip(axes, (("frame time (ms, recorded renderer)", lambda c: c["cost_ms"]),
                                        ("work count per frame (sum over stages)", total_work))):
        pts = []
        for k, m in enumerate(methods):
            mine = [(xof(c), value(c, image, metric)) for c in configs if c.get("method", "sslpv") == m]
            mine = [p for p in mine if p[0] is not None and p[1] is not None and p[0] > 0]
            if mine:
                xs, ys = zip(*mine)
                ax.scatter(xs, ys, s=26, color=f"C{k}", marker=METHOD_MARKERS.get(m, "D"), label=m, zorder=2)
            pts += mine
        if pts:
            front = [pts[i] for i in pareto_front(pts)]
            fx, fy = zip(*front)
            ax.step(fx, fy, where="post", color="black", lw=1.2, zorder=1)
            ax.scatter(fx, fy, s=80, facecolors="none", edgecolors="black", lw=1.3, label="Pareto front (all methods)",
                       zorder=3)
            _logy(ax, [p[1] for p in pts])
            if max(p[0] for p in pts) / min(p[0] for p in pts) > 30:
                ax.set_xscale("log")
        if budget_ms is not None and xof is not total_work:
            ax.axvline(budget_ms, color="C3", ls="--", lw=1, label=f"budget {budget_ms:.3g} ms")
        _floor_line(ax, configs, image, metric)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(_label(image, metric))
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(f"{_label(image, metric)} vs cost, every method", fontsize=10)
    _save(fig, path)
