"""``sslpv-harness calibrate-form --from DIR... --out DIR``: the per-cell calibration form of a fitted family.

Runs :func:`harness.calibration.form.run_form` (``docs/calibration.md``, the per-cell form): the family's
``sslpv-harness calibrate`` folders give the oracle scales per scene and budget and the scalar pairs the
form is anchored to; it fits the form's coefficients by ridge regression, validates them leaving one
scene out with renders, and writes ``calibrated.toml`` (version 3, usable as ``--mapping
calibrated:DIR/calibrated.toml``) and ``calibration.json``.
"""

import sys
from pathlib import Path

from harness.cli.options import add_no_cache, add_out
from harness.errors import InputError

HELP = "fit the per-cell calibration form (scales as functions of each cell's material) to calibrate's oracle"


def configure(sp):
    sp.add_argument("--from", dest="source", nargs="+", required=True, metavar="DIR",
                    help="sslpv-harness calibrate --out folders of one family (the oracle, the scalar pairs and the "
                         "renderer settings; their budgets together, e.g. one folder per grid)")
    add_out(sp, "calibrated.toml (version 3) and calibration.json; new, empty, or written by calibrate-form before",
            required=True)
    sp.add_argument("--against", nargs="*", default=[], metavar="DIR",
                    help="calibrate --out folders whose held-out medians the relMSE target compares with "
                         "(default: [], the --from folders)")
    sp.add_argument("--free-level", action="store_true",
                    help="fit the form's own level terms instead of anchoring them to the scalar pair (Eq. F6)")
    sp.add_argument("--slopes", choices=("both", "radiance", "loss", "channels"), default="both",
                    help="both: sigma_scale and radiance_scale from the material (Eq. F5, on the oracle); radiance: "
                         "sigma_scale the scalar fit's, radiance_scale from the material (Eq. F7); loss: both, fitted "
                         "on the render loss through the calibration's scan (Eq. F8); channels: as loss, each colour "
                         "channel at its own terms (Eq. F9) (default: both)")
    add_no_cache(sp)


def run(args):
    from harness.calibration.form import run_form

    for d in list(args.source) + list(args.against):
        if not (Path(d) / "calibration.json").is_file():
            raise InputError("--from" if d in args.source else "--against", "folder",
                             f"{d} holds no calibration.json", "give a folder written by sslpv-harness calibrate")
    info = run_form(args.source, args.out, args.against or args.source, anchored=not args.free_level,
                    argv=[a for a in args.argv if a != "calibrate-form"], command="sslpv-harness calibrate-form",
                    progress=lambda m: print(m, file=sys.stderr, flush=True), slopes=args.slopes,
                    cache=not args.no_cache)
    lines = []
    for label, res in info["results"].items():
        t = res["targets"]
        lines.append(f"{label}: median held-out relMSE {t['median_held_out_relmse']:.4g} (best family "
                     f"{t['best_family']} {t['best_family_median']:.4g}); energy {'met' if t['energy_met'] else 'NOT met'}"
                     f", relMSE {'met' if t['relmse_met'] else 'NOT met'}")
    summary = {"out": str(args.out), "results": {k: v["targets"] for k, v in info["results"].items()}}
    return summary, None if args.json else "\n".join(lines), 0
