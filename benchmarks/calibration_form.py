"""Print the per-scene tables of a calibration form (``python -m harness.calibration.form --out DIR``) as Markdown.

Reads ``DIR/calibration.json`` (written by :mod:`harness.calibration.form`) and prints, for every budget:

* per scene, the subsurface energy ratio and relMSE of the form in-sample (fitted on every scene),
  held out (fitted without the scene, rendered with it), the source family's scalar calibration held
  out, and the scene's oracle (the family fitted on the scene alone), every one from renders;
* the targets of docs/calibration.md for the form: energy ratio within [0.8, 1.25] on every scene held
  out; median held-out relMSE at most half the best calibrated family's at the budget;
* the fitted coefficients of (F1) with the ridge penalty (Eq. F5) chosen for them.

For a form fitted on the loss (F8, F9) it prints the leave-one-out loss of the fit's own diagnostic beside the
mean ln relMSE of the held-out renders (the only mean it computes, from the figures in the report).

Otherwise it computes nothing: every figure is the form's own (the scalar family's as the form's report copied them). ``--write`` puts the tables on the
page ``docs/benchmarks/calibration_form_<family>.md``, the family followed by the settings that are not its own
(``calibration_form_collision_extrapolated_loss.md``; ``calibration_table.settings_suffix``) (``..._radiance.md`` for a form fitted with
``--slopes radiance``, Eq. F7, ``..._loss.md`` for ``--slopes loss``, Eq. F8, ``..._channels.md`` for ``--slopes
channels``, Eq. F9; ``benchmarks/page.py``).

Run: ``.venv/bin/python benchmarks/calibration_form.py DIR [--write]``
"""

import argparse
import json
import math
import sys
from pathlib import Path

HEADS = ("form, in-sample", "form, held out", "scalar family, held out", "oracle (scene alone)")


def _cell(row):
    return "" if not row or row.get("relmse") is None else f"{row['energy_ratio']:.3g} / {row['relmse']:.3g}"


def page_name(form):
    """``(page name, title)`` of a form's page (module docstring)."""
    from calibration_table import settings_suffix

    slopes = form.get("slopes", "both")
    suffix, with_ = settings_suffix(form)
    return (f"calibration_form_{form['family']}" + suffix + ("" if slopes == "both" else f"_{slopes}"),
            f"The calibration of the {form['family']} family{with_} as a form of the material"
            + {"both": "", "radiance": ": sigma_scale the scalar fit's, radiance_scale per cell (Eq. F7)",
               "loss": ": both scales per cell, fitted on the render loss (Eq. F8)",
               "channels": ": both scales per cell, fitted on the render loss channel by channel (Eq. F9)"}[slopes])


def main(argv=None):
    from page import Page

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dir", type=Path, help="a python -m harness.calibration.form --out folder")
    ap.add_argument("--write", action="store_true", help="write docs/benchmarks/calibration_form_<family>[_radiance].md")
    args = ap.parse_args(argv)
    path = args.dir / "calibration.json"
    if not path.is_file():
        print(f"error: {path}: file: not found; give the --out folder of python -m harness.calibration.form",
              file=sys.stderr)
        return 2
    form = json.loads(path.read_text())
    page = Page(*page_name(form))
    with page.capture(markdown=True):
        _tables(form)
    page.finish(args.write)
    return 0


def _mean_ln(figures):
    """Mean ln relMSE of a column's scenes (those with an image), as the page prints it."""
    vals = [math.log(v["relmse"]) for v in figures.values() if v.get("relmse")]
    return format(sum(vals) / len(vals), ".3g") if vals else "no image"


def _tables(form):
    print(f"the {form['family']} family's sigma_scale and radiance_scale as a per-cell form of the material "
          f"(sslpv_gl.material_form, Eq. F1) on {len(form['scenes'])} scenes ({form['command']}; "
          f"{form['renders']} renderer calls, a grouped call rendering several step counts; {form['time']['wall_s']:.0f} s); "
          f"fit: {form['loss']}")
    print()
    rows = []
    for label, r in form["results"].items():
        s = r["scalar"]
        t = r["targets"]
        print(f"### {label}")
        print()
        print("energy ratio / relMSE (subsurface):")
        print()
        print("| scene | " + " | ".join(HEADS) + " |")
        print("|---|" + "---|" * len(HEADS))
        for n in form["scenes"]:
            print(f"| {n} | {_cell(r['in_sample'][n])} | {_cell(r['held_out'][n])} | {_cell(s['held_out'][n])} | "
                  f"{_cell(r['oracle'][n])} |")
        print()
        print(f"targets: energy ratio in {t['energy_range']} on every scene (held out): "
              f"{'met' if t['energy_met'] else 'NOT met'}"
              + ("" if t["energy_met"] else " (outside: " + ", ".join(
                  f"{k} {'no image' if v is None else format(v, '.3g')}" for k, v in t["energy_outside"].items())
                  + ")"))
        print(f"median held-out relMSE {t['median_held_out_relmse']:.4g} against {t['relmse_factor']} x the best "
              f"calibrated family's ({t['best_family']} {t['best_family_median']:.4g}): "
              f"{'met' if t['relmse_met'] else 'NOT met'}; "
              f"{'better' if t['better_than_best'] else 'not better'} than that family")
        print()
        c = r["coefficients"]
        print(f"coefficients [const, {', '.join(r['terms'])}] (in-sample, ridge penalty {c['lam']:g}): "
              f"ln s: [{', '.join(f'{x:.4g}' for x in c['sigma'])}]; "
              f"ln r: [{', '.join(f'{x:.4g}' for x in c['radiance'])}]")
        p = r["predictive_power"]
        print(f"how well the terms predict the scenes' own optima (Eq. F5, leave-one-out over all scenes at that "
              f"penalty): ln s spread {p['ln_s']['sd']:.3g}, error {p['ln_s']['loo_rmse']:.3g}; ln r spread "
              f"{p['ln_r']['sd']:.3g}, error {p['ln_r']['loo_rmse']:.3g}")
        if "loss" in p:
            print(f"how much the terms help in the loss itself (Eq. {'F9' if form.get('slopes') == 'channels' else 'F8'}, mean "
                  f"leave-one-out ln relMSE at that penalty): "
                  f"form {p['loss']['form']:.3g}, scalar calibration {p['loss']['scalar']:.3g}; the penalty was chosen on "
                  f"every scene, so this flatters the form; the held-out renders above (each fold's own penalty): "
                  f"form {_mean_ln(r['held_out'])}, scalar family {_mean_ln(s['held_out'])}")
        if "ln_r_at_s" in p:
            print(f"how well the terms predict each scene's best ln r at the scalar sigma_scale (Eq. F7, the targets of "
                  f"this fit): spread {p['ln_r_at_s']['sd']:.3g}, error {p['ln_r_at_s']['loo_rmse']:.3g}")
        print()
        rows.append((label, t))
    print("### every budget")
    print()
    print("| budget | median held-out relMSE, form | best calibrated family, held out | energy target | "
          "relMSE target | better than the best family |")
    print("|---|---|---|---|---|---|")
    for label, t in rows:
        print(f"| {label} | {t['median_held_out_relmse']:.4g} | {t['best_family']} {t['best_family_median']:.4g} | "
              f"{'met' if t['energy_met'] else 'not met'} | {'met' if t['relmse_met'] else 'not met'} | "
              f"{'yes' if t['better_than_best'] else 'no'} |")


if __name__ == "__main__":
    sys.exit(main())
