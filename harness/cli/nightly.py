"""``sslpv-harness nightly``: the standard matrix, its verdict, the report and the trends."""

from pathlib import Path

from harness import paths
from harness.cli.options import add_cluster, add_no_cache, add_out, add_progress, add_size, add_store

HELP = "run the standard matrix, append to the store, write the nightly report"


def configure(sp):
    sp.add_argument("--matrix", type=Path, default=paths.REPO / "harness" / "regression" / "nightly_matrix.toml",
                    metavar="TOML", help="the standard matrix file (default: harness/regression/nightly_matrix.toml)")
    add_store(sp, "the nights' results, read by the trends", default="reports/nightly.sqlite")
    sp.set_defaults(store=paths.REPO / "reports" / "nightly.sqlite")
    add_out(sp, "the nights' reports (DATE/ and index.html)", default="reports/nightly")
    sp.set_defaults(out=paths.REPO / "reports" / "nightly")
    sp.add_argument("--date", metavar="YYYY-MM-DD", help="the night's date (default: today)")
    add_cluster(sp)
    sp.add_argument("--method", metavar="M,...", help="comma-separated methods: run only the matrix's products of "
                    "these (sslpv | dipole | dirpole; default: every product of the matrix)")
    add_size(sp, ("small", "own", "WxH"), default="the matrix's size")
    add_progress(sp)
    add_no_cache(sp)


def run(args):
    """Exit 1 on a regression, and on a night whose sweep is incomplete (one line says how to resume)."""
    import sys

    from harness.errors import InputError
    from harness.regression.nightly import run_nightly_cli

    result = run_nightly_cli(args)
    if result.get("status", "finished") != "finished":
        why = result.get("error") or f"{result['failed']} of {result['configurations']} configurations failed"
        line = InputError(result["night_dir"], f"run {result['run_id']}", f"is incomplete: {why}",
                          "run the same nightly command again to render what is missing")
        print(f"error: {line}", file=sys.stderr)
        return result, None, 1
    return result, None, 1 if result.get("verdict") == "regression" else 0
