"""The nightly's trend figures: each headline metric of each scene over the nights, one line per configuration.

A night draws one figure per (scene, headline metric), each with one panel per SSLPV mapping
(and one per rival method), one line per configuration: colour is the grid resolution N
(viridis), the dash pattern the step count K, a rival's line black. The y axis is the metric's
*badness* (:func:`harness.regression.verdict.badness`: its distance from the ideal, so
``|x - 1|`` for the energy ratio) on a log scale with one gridline per decade; the x axis
the nights, oldest left, at most six of them labelled.

The figures are SVG written directly from the numbers (no plotting library): a night of
the standard matrix has 56 of them with up to 60 nights each, which matplotlib took a
quarter of a second apiece to lay out and rasterise, every night, for figures that a
browser draws anyway. Every line is a ``<polyline>`` whose ``data-line`` attribute names its
configuration and whose ``<title>`` shows it on hover; each point maps back to its value
through the axis (``y = top + (hi - log10 v) / (hi - lo) x height``, with ``lo`` and ``hi``
the decades written as the axis labels), which ``tests/test_nightly.py`` checks against the
store.

Limits: values below 1e-6 are drawn at 1e-6 (a badness of exactly zero has no logarithm);
lines of one colour and dash pattern that coincide hide each other (the hover title names
the top one); the dash patterns cycle after four step counts.
"""

from __future__ import annotations

import math
from html import escape
from pathlib import Path

from harness.io.atomic import atomic_write
from harness.methods import config_label as method_label, get_method
from harness.regression.verdict import HEADLINE

#: The nights a trend figure shows, newest last (the store keeps them all).
TREND_NIGHTS = 60
#: The legend shared by a night's trend figures.
TREND_LEGEND = "trend_legend.svg"
#: Values are drawn at no less than this (the log axis).
FLOOR = 1e-6
#: Panel size and margins in pixels.
PANEL_W, PANEL_H, GAP = 300, 190, 14
LEFT, RIGHT, TOP, BOTTOM = 58, 10, 46, 58
#: Dash patterns by step count (SVG ``stroke-dasharray``): solid, dashed, dotted, dash-dot.
DASHES = ("", "6 3", "1.5 2.5", "6 2 1.5 2")


def trend_series(store, night_run_ids):
    """``{(scene, metric): {line: [(night, badness)]}}``: one line per configuration over the nights.

    An SSLPV line is ``(mapping, N, steps, settings)``, where ``settings`` is the label's non-default
    part (``skip=0``), so that two configurations of one mapping stay two lines; another method's
    is ``("method M", 0, its label, "")``.
    """
    from harness.regression.verdict import badness

    series = {}
    for rid, night in night_run_ids:
        for c in store.configs(run_id=rid):
            if c["status"] != "ok":
                continue
            p = c["params"]
            method = c.get("method", "sslpv")
            for metric in HEADLINE:
                m = c["metrics"].get("subsurface", {}).get(metric)
                if m is not None:
                    key = (c["scene"], metric)
                    line = (p.get("mapping"), p.get("N"), p.get("steps"), get_method("sslpv").settings_label(p)) \
                        if method == "sslpv" else (f"method {method}", 0, method_label(method, p), "")
                    series.setdefault(key, {}).setdefault(line, []).append((night, badness(metric, m["value"])))
    return series


def trend_plots(store, night_run_ids, out_dir):
    """Per scene and headline metric, the figure of the last :data:`TREND_NIGHTS` nights (see the module
    docstring), and one legend (:data:`TREND_LEGEND`) for all of them -> ``[{scene, metric, file}]``."""
    night_run_ids = list(night_run_ids)[-TREND_NIGHTS:]
    series = sorted(trend_series(store, night_run_ids).items())
    nights = [night for _, night in night_run_ids]
    lines = sorted({line for _, ls in series for line in ls}, key=line_order)
    style = trend_styles(lines)
    out = []
    for (scene, metric), ls in series:
        name = f"trend_{scene}_{metric}.svg"
        with atomic_write(Path(out_dir) / name) as tmp:
            tmp.write_text(trend_svg(scene, metric, ls, nights, style))
        out.append({"scene": scene, "metric": metric, "file": name})
    if series:
        with atomic_write(Path(out_dir) / TREND_LEGEND) as tmp:
            tmp.write_text(legend_svg(lines, style))
    return out


def line_order(line):
    from harness.report.plots import steps_key

    mapping, n, k, extra = line
    return (str(mapping), n, steps_key(k), extra)


def line_label(line):
    mapping, n, k, extra = line
    return (f"N{n} K{k}" + (f" {extra}" if extra else "")) if n else str(k)


def trend_styles(lines):
    """``{label: (colour "#rrggbb", dash index)}``: colour is N (viridis), dashes the step count; a rival's black."""
    import matplotlib

    from harness.report.plots import steps_key

    grids = sorted({line[1] for line in lines if line[1]})
    steps = sorted({line[2] for line in lines if line[1]}, key=steps_key)
    rivals = sorted({line[2] for line in lines if not line[1]})
    out = {}
    for line in lines:
        _, n, k, _ = line
        if n:
            rgb = matplotlib.colormaps["viridis"](grids.index(n) / max(len(grids) - 1, 1))[:3]
            out[line_label(line)] = ("#" + "".join(f"{round(255 * c):02x}" for c in rgb), steps.index(k) % len(DASHES))
        else:
            out[line_label(line)] = ("#000000", rivals.index(k) % len(DASHES))
    return out


def decades(values):
    """``(lo, hi)``: the whole decades (log10) that enclose ``values`` (floored at :data:`FLOOR`), hi > lo."""
    logs = [math.log10(max(v, FLOOR)) for v in values if math.isfinite(v)] or [0.0]
    lo, hi = math.floor(min(logs)), math.ceil(max(logs))
    return lo, max(hi, lo + 1)


def trend_svg(scene, metric, lines, nights, style):
    """The SVG of one figure: ``lines`` ``{line: [(night, badness)]}`` on the x axis ``nights``."""
    mappings = sorted({k[0] for k in lines}, key=str)
    lo, hi = decades([v for pts in lines.values() for _, v in pts])
    width = LEFT + len(mappings) * PANEL_W + (len(mappings) - 1) * GAP + RIGHT
    height = TOP + PANEL_H + BOTTOM
    n = len(nights)
    x_of = {night: i for i, night in enumerate(nights)}
    labelled = sorted({round(i * (n - 1) / 5) for i in range(6)}) if n > 6 else list(range(n))
    ideal = "|x - 1|" if metric == "energy_ratio" else "value"

    def y(v):
        return TOP + (hi - math.log10(max(v, FLOOR))) / (hi - lo) * PANEL_H

    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
           f'viewBox="0 0 {width} {height}" font-family="sans-serif" font-size="10" '
           f'data-scene="{escape(scene)}" data-metric="{escape(metric)}" data-decades="{lo} {hi}">',
           f'<text x="{width / 2:.1f}" y="14" text-anchor="middle" font-size="12">{escape(scene)}: {escape(metric)} '
           f'of the subsurface image per night (lower is better; legend: {TREND_LEGEND})</text>',
           f'<text transform="translate(13 {TOP + PANEL_H / 2:.1f}) rotate(-90)" text-anchor="middle">'
           f'{escape(metric)} ({ideal})</text>']
    for p, mapping in enumerate(mappings):
        x0 = LEFT + p * (PANEL_W + GAP)

        def x(i, x0=x0):
            return x0 + (i + 0.5) / max(n, 1) * PANEL_W

        title = mapping if str(mapping).startswith("method ") else f"mapping={short_mapping(mapping)}"
        out.append(f'<g class="panel" data-mapping="{escape(str(mapping))}">')
        out.append(f'<text x="{x0 + PANEL_W / 2:.1f}" y="{TOP - 8}" text-anchor="middle">{escape(str(title))}</text>')
        out.append(f'<rect x="{x0}" y="{TOP}" width="{PANEL_W}" height="{PANEL_H}" fill="none" stroke="#888"/>')
        for d in range(lo, hi + 1):
            yd = y(10.0 ** d)
            out.append(f'<line x1="{x0}" x2="{x0 + PANEL_W}" y1="{yd:.2f}" y2="{yd:.2f}" stroke="#ddd"/>')
            if p == 0:
                out.append(f'<text class="ytick" x="{x0 - 4}" y="{yd + 3:.2f}" text-anchor="end" '
                           f'data-log10="{d}">1e{d}</text>')
        for i in labelled:
            out.append(f'<text x="{x(i):.2f}" y="{TOP + PANEL_H + 12}" text-anchor="end" font-size="8" '
                       f'transform="rotate(-30 {x(i):.2f} {TOP + PANEL_H + 12})">{escape(str(nights[i]))}</text>')
        for line, pts in sorted(lines.items(), key=lambda kv: line_order(kv[0])):
            if line[0] != mapping:
                continue
            label = line_label(line)
            colour, dash = style[label]
            xy = [(x(x_of[night]), y(v)) for night, v in pts]
            coords = " ".join(f"{a:.2f},{b:.3f}" for a, b in xy)
            dashes = f' stroke-dasharray="{DASHES[dash]}"' if DASHES[dash] else ""
            out.append(f'<g class="line" data-line="{escape(label)}"><title>{escape(label)}</title>'
                       f'<polyline points="{coords}" fill="none" stroke="{colour}" stroke-width="1.2"{dashes}/>'
                       + "".join(f'<circle cx="{a:.2f}" cy="{b:.3f}" r="1.8" fill="{colour}"/>' for a, b in xy)
                       + "</g>")
        out.append("</g>")
    out.append("</svg>")
    return "\n".join(out) + "\n"


def legend_svg(lines, style):
    """The legend of every trend figure: one entry per line label, 12 to a column."""
    from harness.report.plots import steps_key

    # SSLPV's by N, then K; the rivals' after them.
    ordered = sorted(lines, key=lambda ln: (0, ln[1], steps_key(ln[2]), ln[3]) if ln[1] else (1, 0, 0, str(ln[2])))
    labels = list(dict.fromkeys(line_label(line) for line in ordered))
    rows = 12
    col_w = 36 + 6 * max(len(lab) for lab in labels)
    ncol = -(-len(labels) // rows)
    width, height = max(ncol * col_w + 10, 420), 26 + 15 * min(rows, len(labels)) + 6
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
           f'viewBox="0 0 {width} {height}" font-family="sans-serif" font-size="10">',
           '<text x="5" y="13">colour: grid N; dashes: steps K (SSLPV); black: a rival\'s configuration</text>']
    for i, lab in enumerate(labels):
        cx, cy = 5 + (i // rows) * col_w, 30 + (i % rows) * 15
        colour, dash = style[lab]
        dashes = f' stroke-dasharray="{DASHES[dash]}"' if DASHES[dash] else ""
        out.append(f'<line x1="{cx}" x2="{cx + 26}" y1="{cy - 3}" y2="{cy - 3}" stroke="{colour}" stroke-width="1.2"'
                   f'{dashes}/><text x="{cx + 31}" y="{cy}">{escape(lab)}</text>')
    out.append("</svg>")
    return "\n".join(out) + "\n"


def short_mapping(mapping):
    """A panel title: a calibrated mapping by its file's last two path parts, not the whole path."""
    m = str(mapping)
    return "calibrated:" + "/".join(m.split(":", 1)[1].split("/")[-2:]) if m.startswith("calibrated:") else m
