"""The HTML of the report's site: the Jinja environment and its filters, relative links, slugs, placed files, memoised plots.

Pages are Jinja templates (``templates/``) rendered with autoescaping and strict
undefined names; numbers are shown with four significant digits (:func:`_fmt`), sortable
columns carry a ``data-sort`` key (:func:`_sortkey`). Every link is relative
(:func:`_rel`), so the site opens from the file system; EXRs are hard-linked into it
(:func:`_place`), and a plot is drawn only when its memo entry is missing (:func:`_plot`).
"""

import json
import os
import re
import shutil
from pathlib import Path

import jinja2
import numpy as np
from markupsafe import Markup, escape

from . import plots
from .memo import configs_digest

HERE = Path(__file__).resolve().parent


def _plot(memo, draw, configs, *args):
    """``draw(configs, *args)`` (a function of :mod:`harness.report.plots`; its output path among ``args``),
    or its picture from the memo when the same configurations were drawn the same way before."""
    outs = [a for a in args if isinstance(a, Path)]
    configs = canonical_order(configs)
    key = memo.key("plot", draw.__name__, configs_digest(configs), [a.name if isinstance(a, Path) else a for a in args])
    memo.produce(key, outs, lambda: draw(configs, *args))


def canonical_order(configs):
    """``configs`` sorted by method and parameters. A plot is a function of the set of configurations, not of
    the order the store recorded them in (the order a night's renders finished in; a night served from the
    result cache records them in the plan's): the memo's key and the drawing both see this order."""
    return sorted(configs, key=_config_order)


def _config_order(c):
    return json.dumps([c.get("method"), c.get("params")], sort_keys=True, default=str)


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
