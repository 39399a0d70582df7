"""``sslpv-harness calibrate-best --from DIR... --out DIR``: name the best calibrated mapping.

Runs :func:`harness.calibration.select.write_best`: ranks calibrations by their own held-out
validation at one grid (Eq. S1) and writes the winner's ``calibrated.toml``, under a header that
names the selection, with ``selection.json`` beside it.
"""

from harness.cli.options import add_out, positive_int

HELP = "name the best of several calibrated mappings by their held-out relMSE at one grid"


def configure(sp):
    sp.add_argument("--from", dest="source", nargs="+", required=True, metavar="DIR",
                    help="sslpv-harness calibrate or calibrate-form --out folders, validated on the same scenes")
    add_out(sp, "calibrated.toml (the winner's, with a header) and selection.json; new, empty, or written by "
                "calibrate-best before", required=True)
    sp.add_argument("--grid", type=positive_int, default=32, metavar="N",
                    help="the grid N whose budgets are compared (default: 32, the study's)")


def run(args):
    from harness.calibration.select import write_best

    sel = write_best(args.source, args.out, args.grid,
                     command="sslpv-harness " + " ".join(a for a in args.argv if a != "--json"))
    lines = [f"best at N = {sel['grid']} over {', '.join(sel['budgets'])}: {sel['winner']}"]
    lines += [f"  {c['score']:.4g}  {c['folder']}" for c in sel["candidates"]]
    summary = {"out": str(args.out), "winner": sel["winner"], "grid": sel["grid"],
               "scores": {c["folder"]: c["score"] for c in sel["candidates"]}}
    return summary, None if args.json else "\n".join(lines), 0
