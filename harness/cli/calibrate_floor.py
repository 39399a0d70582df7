"""``sslpv-harness calibrate-floor --from DIR``: the floor of a calibrated family, each scene at its own best scales.

Runs :func:`harness.calibration.floor.run_floor` (``docs/calibration.md``, the family's floor): from the
``sslpv-harness calibrate`` folder's own scan (served from the result cache where the calibration stored it),
each scene and budget at its best ``(s, r)`` per colour channel (Eq. L1) and with one pair (Eq. L2), written to
``DIR/floor.json``, beside the calibration it belongs to. The study reads it beside its calibration target.
"""

import sys
from pathlib import Path

from harness.cli.options import add_no_cache
from harness.errors import InputError

HELP = "the floor of a calibrated family: each scene at its own best scales per colour channel"


def configure(sp):
    sp.add_argument("--from", dest="source", required=True, metavar="DIR",
                    help="an sslpv-harness calibrate --out folder (its scan, scenes and renderer settings)")
    add_no_cache(sp)


def run(args):
    from harness.calibration.floor import run_floor

    if not (Path(args.source) / "calibration.json").is_file():
        raise InputError("--from", "folder", f"{args.source} holds no calibration.json",
                         "give a folder written by sslpv-harness calibrate")
    info = run_floor(args.source, None, cache=not args.no_cache,
                     argv=[a for a in args.argv if a not in ("calibrate-floor", "--json")],
                     progress=lambda m: print(m, file=sys.stderr, flush=True), command="sslpv-harness calibrate-floor")
    lines = [f"{label}: median floor {b['median']:.4g} per channel, {b['median_scalar']:.4g} with one pair per scene"
             for label, b in info["budgets"].items()]
    summary = {"out": info["out"], "budgets": {k: {"median": v["median"], "median_scalar": v["median_scalar"]}
                                               for k, v in info["budgets"].items()},
               "renders": info["renders"], "served_from_cache": info["served_from_cache"]}
    return summary, None if args.json else "\n".join(lines), 0
