"""Where SSLPV's light goes, and how the error behaves as the grid is refined.

Five parts, each printing a table and writing ``OUT/<part>.json`` (and a plot for ``refine``):

``outside``
    Per suite scene, mapping and outside mode (``sslpv_gl.boundary``), at N = 32: the share of the
    accumulated energy (sum of |c00| of the accumulation grid) that sits in cells outside the mesh,
    and the fraction of the injected flux still propagating, after K = 64 steps and at convergence
    (``steps = auto``, tolerance 1e-3).
``gap``
    How far SSLPV at the paper's budgets (K = 8, 16, 32, 64) stays from its own converged result:
    the factor E(converged) / E(K) on the subsurface image's energy, per scene and mapping, beside
    the factors 3, 2 and 1.2 the paper's Fig. 8 applies by hand at 8, 16 and 32 steps.
``refine``
    Subsurface relMSE and energy ratio against the committed small references (64x64; wide_slab
    60x36), at N = 16, 32, 64 (``--grids``)
    at the converged accumulation (``steps = steady``), for every index-matched suite scene, every
    mapping and the outside modes ``vacuum``, ``extrapolated`` and ``absorb``. The noise floor is
    the same metric between the reference's two halves.
``bypass``
    Light that bypasses the object. The lattice is linear, and ``outside = vacuum`` (the paper's
    treatment) differs from ``outside = interior`` (:mod:`sslpv_gl.boundary`) only in the transfers
    between two empty cells, which ``interior`` cuts; so, exactly, per pixel and at any K,
    image(vacuum) = image(interior) [light that stayed in the medium] + [image(vacuum) -
    image(interior)] [light that crossed empty cells]. Per scene at N = ``--grid`` and K =
    ``--steps`` (one propagation per mode, ``render_steps``): the subsurface energy of each part
    against the committed small reference (absolute where a scene has none), the bypass share
    ``1 - E(interior) / E(vacuum)``, and ``absorb`` (every empty cell a sink) beside them; mapping
    ``--mapping``. Limit: at a curved surface the outside-centred cells that hold surface points
    form a shell; a hop between two neighbouring shell cells counts as bypass although part of each
    holds medium, so the share bounds the around-the-object light from above.
``backlit``
    The back-lit deficit: back-lit, index-matched scenes (default ``backlit_slab`` and ``backlit_sphere``) at N = ``--grid``,
    ``steps = steady``, ``skip = 0``, for each mapping and outside mode, with the injection at the
    surface (the paper) and one reduced mean free path inwards (``inject_depth = 1``: ``1 / sigma_t'`` of each
    texel's cell, the mean over colours, ``sslpv_gl.inject`` Eq. (J1); the dipole's source depth): E(SSLPV) /
    E(reference) per colour
    channel over the pixels both cover. ``benchmarks/diffusion_bounded.py`` prints the same terms on
    a slab lattice.

Run: ``.venv/bin/python benchmarks/sslpv_light_budget.py --part outside --out reports/light_budget``
(``--part all`` runs outside, gap and refine; ``--scenes a,b``, and for ``refine`` ``--grids 16,32``, ``--outsides vacuum``
and ``--mappings diffusion``, narrow them). ``--merge A/refine.json B/refine.json --out DIR`` renders
nothing: it joins the rows of several refine runs (each N from the last file that has it), prints them as
one Markdown table and writes ``DIR/refine.json`` and ``DIR/refine.png``.
"""

import argparse
import itertools
import json
import sys
import time
from pathlib import Path

from harness.errors import InputError


MAPPINGS = ("literal", "collision", "diffusion")
PAPER_FACTORS = {8: 3.0, 16: 2.0, 32: 1.2, 64: 1.0}


def _setup(p, scene):
    """Each mapping's own recommended setup for an absolute image: diffusion with skip 0."""
    return dict(skip=0) if p == "diffusion" else {}


def part_outside(renderer, scenes, out):
    from harness.scene import load_scene
    from sslpv_gl.boundary import OUTSIDE_MODES
    from sslpv_gl.params import SSLPVParams

    rows = []
    print(f"{'scene':<20} {'mapping':<10} {'outside':<13} {'share@64':>9} {'left@64':>8} {'K conv':>7} "
          f"{'share conv':>10}")
    for name in scenes:
        scene = load_scene(name).with_resolution(64, 64)
        for m in MAPPINGS:
            for mode in OUTSIDE_MODES:
                p = SSLPVParams(N=32, steps=64, mapping=m, outside=mode, **_setup(m, scene))
                k64 = renderer.render(scene, p, diagnostics=True).diagnostics
                conv = renderer.render(scene, p.replace(steps="auto", max_steps=2048)).diagnostics
                row = {"scene": name, "mapping": m, "outside": mode, "share_64": k64["outside_share"],
                       "remaining_64": k64["remaining_fraction"], "steps_converged": conv["steps_used"],
                       "share_converged": conv["outside_share"], "remaining_converged": conv["remaining_fraction"]}
                rows.append(row)
                print(f"{name:<20} {m:<10} {mode:<13} {row['share_64']:9.3f} {row['remaining_64']:8.3f} "
                      f"{row['steps_converged']:7d} {row['share_converged']:10.3f}")
    return rows


def part_gap(renderer, scenes, out, outside_modes=("vacuum", "absorb")):
    from harness.scene import load_scene
    from sslpv_gl.params import SSLPVParams

    rows = []
    print(f"{'scene':<20} {'mapping':<10} {'outside':<8} " + " ".join(f"{'x@' + str(k):>7}" for k in PAPER_FACTORS)
          + f" {'K conv':>7}")
    print(f"{'paper Fig. 8':<40} " + " ".join(f"{v:7.2f}" for v in PAPER_FACTORS.values()))
    for name in scenes:
        scene = load_scene(name).with_resolution(64, 64)
        for m in MAPPINGS:
            for mode in outside_modes:
                base = SSLPVParams(N=32, mapping=m, outside=mode, **_setup(m, scene))
                conv = renderer.render(scene, base.replace(steps="auto", max_steps=2048))
                e_conv = float(conv.subsurface[conv.mask].sum())
                group = renderer.render_steps(scene, base, list(PAPER_FACTORS))
                factors = {k: e_conv / max(float(r.subsurface[r.mask].sum()), 1e-30)
                           for k, r in zip(PAPER_FACTORS, group)}
                rows.append({"scene": name, "mapping": m, "outside": mode, "factors": factors,
                             "steps_converged": conv.steps_used})
                print(f"{name:<20} {m:<10} {mode:<8} " + " ".join(f"{factors[k]:7.2f}" for k in PAPER_FACTORS)
                      + f" {conv.steps_used:7d}")
    return rows


def part_refine(renderer, scenes, out, grids=(16, 32, 64), outsides=("vacuum", "extrapolated", "absorb"),
                mappings=MAPPINGS):
    from harness.metrics import compute
    from harness.regression.accuracy import load_case_reference, small_scene
    from sslpv_gl.params import SSLPVParams

    rows = []
    print(f"{'scene':<20} {'mapping':<10} {'outside':<13} " + " ".join(f"{'relMSE N' + str(n):>13}" for n in grids)
          + " " + " ".join(f"{'E/E N' + str(n):>9}" for n in grids) + f" {'floor':>8} {'wall':>8}")
    for name in scenes:
        scene = small_scene(name)          # the committed reference's own size (wide_slab keeps its aspect)
        if scene.boundary.kind != "index-matched":
            continue
        ref, floors = load_case_reference(scene)
        floor = floors["subsurface"]["relmse"]
        for m, outside in itertools.product(mappings, outsides):
            rel, er = {}, {}
            t0 = time.perf_counter()
            for n in grids:
                p = SSLPVParams(N=n, steps="steady", mapping=m, outside=outside, **_setup(m, scene))
                res = renderer.render(scene, p)
                rel[n] = float(compute("relmse", res.subsurface, ref["subsurface"], ref["mask"]).value)
                er[n] = float(compute("energy_ratio", res.subsurface, ref["subsurface"], ref["mask"]).value)
            wall = time.perf_counter() - t0
            rows.append({"scene": name, "mapping": m, "outside": outside, "relmse": rel, "energy_ratio": er,
                         "noise_floor_relmse": floor, "wall_s": wall})
            print(f"{name:<20} {m:<10} {outside:<13} " + " ".join(f"{rel[n]:13.4g}" for n in grids) + " "
                  + " ".join(f"{er[n]:9.3f}" for n in grids) + f" {floor:8.2g} {wall:6.0f} s", flush=True)
    _plot_refine(rows, grids, out / "refine.png")
    return rows


def _plot_refine(rows, grids, path):
    """relMSE against N, one panel per scene, one line per (mapping, outside) over the grids it has."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from harness.io.atomic import atomic_write

    scenes = sorted({r["scene"] for r in rows})
    # one colour per (mapping, outside) on every panel, so that the panels read alike
    lines = list(dict.fromkeys((r["mapping"], r["outside"]) for r in rows))
    colour = {ln: f"C{i % 10}" for i, ln in enumerate(lines)}
    ncols = min(max(len(scenes), 1), 4)
    nrows = -(-max(len(scenes), 1) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(3.2 * ncols, 2.8 * nrows), squeeze=False)
    for ax in axes.flat[len(scenes):]:
        ax.axis("off")
    for ax, s in zip(axes.flat, scenes):
        for r in rows:
            if r["scene"] == s:
                ns = sorted(int(n) for n in r["relmse"])
                ax.loglog(ns, [_at(r["relmse"], n) for n in ns], "o-", color=colour[(r["mapping"], r["outside"])],
                          label=f"{r['mapping']}/{r['outside']}")
                floor = r["noise_floor_relmse"]
        ax.axhline(floor, color="grey", ls=":", label="noise floor")
        ax.set_title(s, fontsize=9)
        ax.set_xlabel("N", fontsize=8)
        ax.set_xticks(grids, [str(n) for n in grids])
        ax.minorticks_off()
    for row in axes:
        row[0].set_ylabel("subsurface relMSE\n(converged)", fontsize=8)
    handles = [plt.Line2D([], [], color=colour[ln], marker="o", label=f"{ln[0]}/{ln[1]}") for ln in lines]
    handles.append(plt.Line2D([], [], color="grey", ls=":", label="noise floor"))
    fig.legend(handles=handles, loc="lower right", fontsize=8, frameon=False)
    fig.tight_layout()
    with atomic_write(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)


def _at(per_n, n):
    """``per_n[n]`` whether the keys are ints (a run) or strings (its refine.json)."""
    return per_n[n] if n in per_n else per_n[str(n)]


ROW_KEYS = ("scene", "mapping", "outside", "relmse", "energy_ratio", "noise_floor_relmse")


def merge_refine(paths):
    """The rows of several ``refine.json`` files as one: per (scene, mapping, outside), each N's figures
    from the last file that has that N. Returns ``(rows, grids)``; a missing or malformed file is an
    InputError naming it."""
    merged = {}
    for path in paths:
        try:
            rows = json.loads(Path(path).read_text())
        except OSError as exc:
            raise InputError(path, "file", f"cannot be read ({exc.strerror or exc})",
                             "pass a refine.json written by --part refine") from None
        except ValueError as exc:
            raise InputError(path, "file", f"is not JSON ({exc})", "pass a refine.json written by --part refine") \
                from None
        if not isinstance(rows, list):
            raise InputError(path, "rows", "must be a list of rows", "pass a refine.json written by --part refine")
        for i, r in enumerate(rows):
            missing = [k for k in ROW_KEYS if not isinstance(r, dict) or k not in r]
            if missing:
                raise InputError(path, f"row {i}", f"lacks {', '.join(missing)}",
                                 "pass a refine.json written by --part refine")
            try:
                rel = {int(n): float(v) for n, v in r["relmse"].items()}
                er = {int(n): float(v) for n, v in r["energy_ratio"].items()}
            except (AttributeError, TypeError, ValueError):
                raise InputError(path, f"row {i}", "relmse and energy_ratio must map N to a number",
                                 "pass a refine.json written by --part refine") from None
            m = merged.setdefault((r["scene"], r["mapping"], r["outside"]),
                                  {"scene": r["scene"], "mapping": r["mapping"], "outside": r["outside"],
                                   "relmse": {}, "energy_ratio": {}, "wall_s": {}})
            m["relmse"].update(rel)
            m["energy_ratio"].update(er)
            m["noise_floor_relmse"] = float(r["noise_floor_relmse"])
            m["wall_s"][str(path)] = r.get("wall_s")
    order = {m: i for i, m in enumerate(MAPPINGS)}
    rows = sorted(merged.values(), key=lambda r: (r["scene"], order.get(r["mapping"], len(order)), r["mapping"],
                                                   r["outside"]))
    for r in rows:
        r["relmse"] = dict(sorted(r["relmse"].items()))
        r["energy_ratio"] = dict(sorted(r["energy_ratio"].items()))
    return rows, sorted({n for r in rows for n in r["relmse"]})


def refine_table(rows):
    """Markdown: one line per scene, one column per (mapping, outside): ``E/E at each N (relMSE at each N)``."""
    cols = list(dict.fromkeys((r["mapping"], r["outside"]) for r in rows))
    by = {(r["scene"], r["mapping"], r["outside"]): r for r in rows}
    head = ["scene"] + [f"`{m}`, {o}: E/E, N = " + " / ".join(str(n) for n in _grids_of(rows, m, o)) + " (relMSE)"
                        for m, o in cols]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for s in sorted({r["scene"] for r in rows}):
        cells = [s]
        for m, o in cols:
            r = by.get((s, m, o))
            if r is None:
                cells.append("--")
                continue
            ns = _grids_of(rows, m, o)
            cells.append(" / ".join(f"{r['energy_ratio'][n]:.2f}" if n in r["energy_ratio"] else "--" for n in ns)
                         + " (" + " / ".join(f"{r['relmse'][n]:.2g}" if n in r["relmse"] else "--" for n in ns)
                         + ")")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def refine_summary(rows):
    """One line per (mapping, outside): the energy ratio's range over scenes at each N, and the range over
    scenes of the relMSE's growth factor per doubling of N (``relMSE(2N) / relMSE(N)``)."""
    out = []
    for m, o in dict.fromkeys((r["mapping"], r["outside"]) for r in rows):
        rs = [r for r in rows if (r["mapping"], r["outside"]) == (m, o)]
        ns = _grids_of(rows, m, o)
        er = [f"N = {n}: {min(r['energy_ratio'][n] for r in rs if n in r['energy_ratio']):.2f}-"
              f"{max(r['energy_ratio'][n] for r in rs if n in r['energy_ratio']):.2f}" for n in ns]
        growth = []
        for a, b in zip(ns, ns[1:]):
            f = [r["relmse"][b] / r["relmse"][a] for r in rs if a in r["relmse"] and b in r["relmse"]
                 and r["relmse"][a] > 0]
            if f:
                growth.append(f"{a}->{b}: {min(f):.2f}-{max(f):.2f}x ({sum(x > 1 for x in f)}/{len(f)} grow)")
        out.append(f"{m}/{o} over {len(rs)} scenes: E/E " + ", ".join(er)
                   + ("; relMSE per doubling " + ", ".join(growth) if growth else ""))
    return "\n".join(out)


def _energy(res, ref):
    """Subsurface energy against the reference's over both masks; the absolute energy without one."""
    from harness.metrics import compute

    if ref is None:
        return float(res.subsurface[res.mask].sum())
    return float(compute("energy_ratio", res.subsurface, ref["subsurface"], ref["mask"]).value)


def part_bypass(renderer, scenes, ks, mapping="collision", grid=32):
    from harness.regression.accuracy import load_case_reference, small_scene
    from sslpv_gl.params import SSLPVParams

    rows = []
    print(f"N = {grid}, mapping {mapping}; E = subsurface energy / reference's (absolute energy where no reference)")
    print(f"{'scene':<24} {'lit':<6} {'K':>3} {'E vacuum':>9} {'E stayed':>9} {'E crossed':>9} {'bypass':>7} "
          f"{'E absorb':>9}")
    for name in scenes:
        scene = small_scene(name)
        try:
            ref, _ = load_case_reference(scene)
        except Exception:                      # a scene without a committed reference: absolute energies
            ref = None
        lit = "back" if "back-lit" in scene.tags else "front"
        e = {}
        for mode in ("vacuum", "interior", "absorb"):
            p = SSLPVParams(N=grid, steps=ks[0], mapping=mapping, outside=mode)
            for k, res in zip(ks, renderer.render_steps(scene, p, ks)):
                e[mode, k] = _energy(res, ref)
        for k in ks:
            v, i, a = e["vacuum", k], e["interior", k], e["absorb", k]
            share = 1.0 - i / v if v > 0 else float("nan")
            rows.append({"scene": name, "lit": lit, "K": k, "vacuum": v, "interior": i, "absorb": a,
                         "bypass_share": share, "absolute": ref is None})
            print(f"{name:<24} {lit:<6} {k:>3} {v:9.4g} {i:9.4g} {v - i:9.4g} {share:7.3f} {a:9.4g}"
                  + ("" if ref is not None else "   (no reference: absolute)"), flush=True)
    return rows


BACKLIT_CASES = (("diffusion", "vacuum"), ("diffusion", "extrapolated"), ("diffusion", "absorb"),
                 ("diffusion", "interior"), ("collision", "vacuum"), ("collision", "absorb"), ("collision", "interior"))


def part_backlit(renderer, scenes, grid=32):
    import numpy as np

    from harness.regression.accuracy import load_case_reference, small_scene
    from sslpv_gl.params import SSLPVParams

    rows = []
    print(f"N = {grid}, steps = steady, skip = 0")
    print(f"{'scene':<24} {'mapping':<10} {'outside':<13} {'depth':>5}   E / E_ref (R, G, B)")
    for name in scenes:
        scene = small_scene(name)
        ref, _ = load_case_reference(scene)
        for mapping, outside in BACKLIT_CASES:
            for depth in (0.0, 1.0):
                p = SSLPVParams(N=grid, steps="steady", mapping=mapping, outside=outside, skip=0, inject_depth=depth)
                res = renderer.render(scene, p)
                m = np.asarray(ref["mask"], bool) & res.mask
                e = res.subsurface[m].sum(axis=0) / np.asarray(ref["subsurface"])[m].sum(axis=0)
                rows.append({"scene": name, "mapping": mapping, "outside": outside, "inject_depth": depth,
                             "energy_ratio": [float(x) for x in e]})
                print(f"{name:<24} {mapping:<10} {outside:<13} {depth:5g}   " + "  ".join(f"{v:.4f}" for v in e),
                      flush=True)
    return rows


def _grids_of(rows, m, o):
    return sorted({n for r in rows if (r["mapping"], r["outside"]) == (m, o) for n in r["relmse"]})


def _checked(args):
    """``(scenes, grids, outsides, mappings)`` from the command line; an InputError names a bad value."""
    from harness.runs.sweep import resolve_scenes
    from harness.scene import list_scenes
    from sslpv_gl.params import SSLPVParams

    scenes = resolve_scenes(args.scenes) if args.scenes else list_scenes()
    try:
        grids = tuple(int(x) for x in args.grids.split(","))
    except ValueError:
        raise InputError("--grids", "grids", f"{args.grids!r} is not a comma-separated list of integers",
                         "pass e.g. --grids 16,32,64") from None
    outsides, mappings = tuple(args.outsides.split(",")), tuple(args.mappings.split(","))
    for n, outside, m in itertools.product(grids, outsides, mappings):
        SSLPVParams(N=n, steps="steady", mapping=m, outside=outside)     # raises the one-line InputError
    return scenes, grids, outsides, mappings


def _ks(args):
    from sslpv_gl.params import SSLPVParams

    try:
        ks = [int(k) for k in args.steps.split(",")]
    except ValueError:
        raise InputError("--steps", "steps", f"{args.steps!r} is not a comma-separated list of integers",
                         "pass e.g. --steps 8,32") from None
    for k in ks:
        SSLPVParams(N=args.grid, steps=k, mapping=args.mapping)          # raises the one-line InputError
    return ks


def _page_name(argv):
    if "--merge" in argv:
        return "sslpv_light_budget_refine_merged"
    part = argv[argv.index("--part") + 1] if "--part" in argv[:-1] else "all"
    return f"sslpv_light_budget_{part}"


def main(argv=None):
    from harness.io.atomic import atomic_write
    from sslpv_gl.renderer import SSLPVRenderer

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", choices=["outside", "gap", "refine", "bypass", "backlit", "all"], default="all")
    ap.add_argument("--scenes", help="comma-separated scene names (default: the suite; backlit: backlit_slab)")
    ap.add_argument("--steps", default="8,32", help="bypass: propagation step counts K")
    ap.add_argument("--mapping", default="collision", help="bypass: the mapping")
    ap.add_argument("--grid", type=int, default=32, help="bypass and backlit: the grid N")
    ap.add_argument("--grids", default="16,32,64", help="refine: grid resolutions")
    ap.add_argument("--outsides", default="vacuum,extrapolated,absorb", help="refine: outside modes")
    ap.add_argument("--mappings", default=",".join(MAPPINGS), help="refine: mappings")
    ap.add_argument("--out", type=Path, default=Path("reports/light_budget"))
    ap.add_argument("--merge", nargs="+", type=Path, metavar="REFINE_JSON",
                    help="render nothing: merge these refine.json files (per scene, mapping and outside, each N "
                         "from the last file that has it) into one table, refine.json and refine.png in --out")
    args = ap.parse_args(argv)
    if args.merge:
        try:
            rows, grids = merge_refine(args.merge)
        except InputError as exc:
            print(f"error: {exc}", file=sys.stderr)
            raise SystemExit(2) from None
        args.out.mkdir(parents=True, exist_ok=True)
        print(refine_table(rows))
        print()
        print(refine_summary(rows))
        with atomic_write(args.out / "refine.json") as tmp:
            Path(tmp).write_text(json.dumps(rows, indent=1))
        _plot_refine(rows, grids, args.out / "refine.png")
        print(f"({len(rows)} rows from {len(args.merge)} files: {args.out / 'refine.json'}, {args.out / 'refine.png'})")
        return
    try:                                   # every value checked before anything is rendered or written
        scenes, grids, outsides, mappings = _checked(args)
        ks = _ks(args)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    args.out.mkdir(parents=True, exist_ok=True)
    renderer = SSLPVRenderer()
    print(f"GL renderer: {renderer.gl_renderer}")
    parts = ["outside", "gap", "refine"] if args.part == "all" else [args.part]
    for part in parts:
        t0 = time.perf_counter()
        print(f"\n== {part}")
        if part == "refine":
            rows = part_refine(renderer, scenes, args.out, grids, outsides, mappings)
        elif part == "bypass":
            rows = part_bypass(renderer, scenes, ks, args.mapping, args.grid)
        elif part == "backlit":
            rows = part_backlit(renderer, scenes if args.scenes else ["backlit_slab", "backlit_sphere"], args.grid)
        else:
            rows = {"outside": part_outside, "gap": part_gap}[part](renderer, scenes, args.out)
        with atomic_write(args.out / f"{part}.json") as tmp:
            Path(tmp).write_text(json.dumps(rows, indent=1, default=str))
        print(f"({part}: {time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    from page import run

    parts = {"outside": "light in the cells outside the mesh", "gap": "steps not yet converged",
             "refine": "grid refinement", "bypass": "light that bypasses the object",
             "backlit": "the back-lit deficit", "all": "outside, gap and refine"}

    def title(argv):
        part = "refine" if "--merge" in argv else _page_name(argv).removeprefix("sslpv_light_budget_")
        return f"Where SSLPV's light goes: {parts.get(part.removesuffix('_merged'), part)}"

    raise SystemExit(run(main, _page_name, title))
