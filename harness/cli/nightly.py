"""``sslpv-harness nightly``: the standard matrix, its verdict, the report and the trends."""

from pathlib import Path

from harness import paths

HELP = "run the standard matrix, append to the store, write the nightly report"


def configure(sp):
    sp.add_argument("--matrix", type=Path, default=paths.REPO / "harness" / "regression" / "nightly_matrix.toml",
                    help="the standard matrix file")
    sp.add_argument("--store", type=Path, default=paths.REPO / "reports" / "nightly.sqlite", help="results store")
    sp.add_argument("--out", type=Path, default=paths.REPO / "reports" / "nightly", help="reports folder")
    sp.add_argument("--date", help="night's date, YYYY-MM-DD (default: today)")
    sp.add_argument("--scheduler", help="address of an existing Dask scheduler")
    sp.add_argument("--method", help="comma-separated methods: run only the matrix's products of these "
                                     "(sslpv | dipole | dirpole; default: every product of the matrix)")
    sp.add_argument("--size", help="image size of the night: small (each scene at its committed small size, "
                    "judged against the committed references and baselines), own (each scene's own size, its "
                    "Mitsuba reference rendered into cache/references first) or WxH; default: the matrix's size")
    sp.add_argument("--no-cache", action="store_true", help="render every configuration afresh instead of serving "
                    "unchanged ones from the result cache (cache/results)")


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
