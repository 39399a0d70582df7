"""``sslpv-harness sweep``: every SSLPV configuration of a sweep, on Dask, into a store."""

from pathlib import Path

from harness.cli.options import add_method_args, add_sslpv_args, positive_int

HELP = "render every SSLPV configuration of a sweep and store its metrics"


def configure(sp):
    sp.add_argument("--scenes", help="comma-separated scene names (default: the whole suite)")
    sp.add_argument("--config", type=Path, help="re-run a sweep from the sweep.json it wrote")
    sp.add_argument("--out", type=Path, help="output folder (holds store.sqlite, renders/, sweep.json)")
    sp.add_argument("--store", type=Path, help="results store (default: OUT/store.sqlite)")
    sp.add_argument("--scheduler", help="address of an existing Dask scheduler (default: a LocalCluster)")
    sp.add_argument("--workers", type=positive_int, help="LocalCluster workers (default: CPU cores)")
    sp.add_argument("--size", help="image size WxH for SSLPV and reference, or small (each scene at its committed "
                    "small size, same aspect); default: the scene's")
    sp.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    sp.add_argument("--no-cache", action="store_true", help="render every configuration afresh instead of serving "
                    "it from the result cache (cache/results; harness.runs.cache)")
    add_sslpv_args(sp, multi=True)
    add_method_args(sp, multi=True)


def run(args):
    """Exit 0 for a finished run; 1, with one line on stderr saying how to resume, for an incomplete one."""
    import sys

    from harness.errors import InputError
    from harness.runs.sweep import run_sweep_cli

    summary = run_sweep_cli(args)
    if summary.get("status") == "finished":
        return summary, None, 0
    why = summary.get("error") or (f"{summary['failed']} of {summary['configurations']} configurations failed "
                                   f"(the first: {summary.get('first_error', '?')})")
    line = InputError(summary["sweep_json"], f"run {summary['run_id']}", f"is incomplete: {why}",
                      f"run the same command again, or `{summary['resume']}`, to render what is missing")
    print(f"error: {line}", file=sys.stderr)
    return summary, None, 1
