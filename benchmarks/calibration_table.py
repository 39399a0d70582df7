"""Print the per-scene tables of a calibration (``sslpv-harness calibrate --out DIR``) as Markdown.

Reads ``DIR/calibration.json`` (written by :mod:`harness.calibration.run`) and prints, for one
budget (default: the steady state, i.e. converged steps):

* per scene, the subsurface energy ratio and relMSE of every mapping the page compares:
  ``literal``, ``collision``, ``diffusion`` (no fitted factor), calibrated in-sample, calibrated
  held out (leave-one-scene-out) and the per-scene oracle (the scene fitted on itself);
* the targets of docs/calibration.md (energy ratio within [0.8, 1.25] on every scene with the
  held-out fit; median held-out relMSE at most half the better of literal and collision) and,
  per scene that misses the energy range, what the calibration says stops it;
* the fitted values of every budget with their standard errors.

It computes nothing: every figure is the calibration's own. ``--write`` puts the tables on the page
``docs/benchmarks/calibration_<family>.md`` (``benchmarks/page.py``; :func:`page_name`: a calibration with other
settings or grids than its family's own has a page of its own).

Run: ``.venv/bin/python benchmarks/calibration_table.py DIR [--budget "N=32 steps=steady"] [--write]``
"""

import argparse
import json
import sys
from pathlib import Path

from harness.calibration.page import COLUMNS, HEADS, scene_result


def _cell(row):
    return f"{row['energy_ratio']:.3g} / {row['relmse']:.3g}" if row else ""


#: The renderer settings a calibration is named after where they are not its family's own.
NAMED_SETTINGS = ("outside", "phase_scaling", "boundary_reflect", "exitance", "inject_depth", "shade_depth", "lookup")


def _name_part(key, value):
    """A setting's part of a page name: its value (``extrapolated``), or for a number the setting too (``depth1``,
    ``shade1``)."""
    short = {"inject_depth": "depth", "shade_depth": "shade"}
    if key in short:
        return f"{short[key]}{value:g}".replace(".", "p")
    return str(value).replace("-", "_")


def settings_suffix(cal):
    """``(name suffix, title suffix)``: each setting of :data:`NAMED_SETTINGS` of a calibration (scalar or form)
    where it is not its family's own (:func:`harness.calibration.families.fit_extensions`; a family calibrated
    with another outside treatment, phase scaling, exitance read or lookup is another calibration):
    ``("_extrapolated", " with outside = extrapolated")``."""
    from harness.calibration.families import fit_extensions

    ext = fit_extensions(cal["family"], cal.get("settings", {}))
    extras = [(k, ext[k]) for k in NAMED_SETTINGS if k in ext]
    return ("".join("_" + _name_part(k, v) for k, v in extras),
            " with " + ", ".join(f"{k} = {v:g}" if isinstance(v, float) else f"{k} = {v}" for k, v in extras)
            if extras else "")


def page_name(cal):
    """``(page name, title)`` of a calibration: one page per calibration, named after its family, after its
    settings that are not the family's own (:func:`settings_suffix`), and after its grids where they are not
    N = 32."""
    suffix, with_ = settings_suffix(cal)
    grids = sorted({int(v["N"]) for v in cal["results"].values()})
    name = f"calibration_{cal['family']}" + suffix
    title = f"The calibration of the {cal['family']} family" + with_
    if grids != [32]:
        name += "".join(f"_n{n}" for n in grids)
        title += " at N = " + ", ".join(map(str, grids))
    return name, title


def main(argv=None):
    from page import Page

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dir", type=Path, help="a calibrate --out folder")
    ap.add_argument("--budget", default=None, help='e.g. "N=32 steps=steady" (default: the steady one, else the last)')
    ap.add_argument("--write", action="store_true", help="write docs/benchmarks/calibration_<family>[_<setting>...][_n<N>].md")
    args = ap.parse_args(argv)
    path = args.dir / "calibration.json"
    if not path.is_file():
        print(f"error: {path}: file: not found; give the --out folder of sslpv-harness calibrate", file=sys.stderr)
        return 2
    cal = json.loads(path.read_text())
    results = cal["results"]
    budget = args.budget or next((k for k in results if k.endswith("steps=steady")), list(results)[-1])
    if budget not in results:
        print(f"error: --budget: budget: {budget!r} is not in {path}; use one of: {', '.join(results)}",
              file=sys.stderr)
        return 2
    r = results[budget]
    name, title = page_name(cal)
    page = Page(name, title)
    with page.capture(markdown=True):
        _tables(cal, r, budget, results)
    page.finish(args.write)
    return 0


def _tables(cal, r, budget, results):
    print(f"calibration of the {cal['family']} family on {len(cal['scenes'])} scenes, budget {budget} "
          f"({cal['command']}; {cal['renders']} renders, {cal['time']['wall_s']:.0f} s)")
    print()
    print("energy ratio / relMSE (subsurface):")
    print()
    print("| scene | " + " | ".join(HEADS[col] for col in COLUMNS) + " |")
    print("|---|" + "---|" * len(COLUMNS))
    for scene in cal["scenes"]:
        print(f"| {scene} | " + " | ".join(_cell(scene_result(r, col, scene)) for col in COLUMNS) + " |")
    t = r["targets"]
    print()
    print(f"targets: energy ratio in {t['energy_range']} on every scene (held out): "
          f"{'met' if t['energy_met'] else 'NOT met'}"
          + ("" if t["energy_met"] else " (outside: " + ", ".join(f"{k} {v:.3g}" for k, v in
                                                                   t["energy_outside"].items()) + ")"))
    print(f"median held-out relMSE {t['median_held_out_relmse']:.4g} against {t['relmse_factor']} x "
          f"min(literal {t['median_relmse_literal']:.4g}, collision {t['median_relmse_collision']:.4g}): "
          f"{'met' if t['relmse_met'] else 'NOT met'}")
    lim = r.get("limits") or {}
    for s in lim.get("scenes", []):
        print(f"  {s['scene']}: held-out energy {s['held_out_energy']:.3g}, oracle {s['oracle_energy']:.3g}: {s['why']}")
    if "median_oracle_relmse" in lim:
        print(f"  median oracle relMSE {lim['median_oracle_relmse']:.4g} "
              f"(the relMSE target {'would be met' if lim.get('oracle_relmse_met') else 'is missed'} even by the oracle)")
    print()
    print("| budget | sigma_scale | radiance_scale | median held-out relMSE | energy target | relMSE target |")
    print("|---|---|---|---|---|---|")
    for name, b in results.items():
        tb = b["targets"]
        print(f"| {name} | {b['sigma_scale']:.4g} ± {b['sigma_scale_se']:.2g} | {b['radiance_scale']:.4g} ± "
              f"{b['radiance_scale_se']:.2g} | {tb['median_held_out_relmse']:.4g} | "
              f"{'met' if tb['energy_met'] else 'not met'} | {'met' if tb['relmse_met'] else 'not met'} |")


if __name__ == "__main__":
    sys.exit(main())
