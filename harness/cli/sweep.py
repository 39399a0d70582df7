"""``sslpv-harness sweep``: every SSLPV configuration of a sweep, on Dask, into a store."""

from pathlib import Path

from harness.cli.options import (add_cluster, add_method_args, add_no_cache, add_out, add_progress, add_scenes,
                                 add_size, add_sslpv_args, add_store)

HELP = "render every configuration of a sweep (SSLPV by default) and store its metrics"


def configure(sp):
    add_scenes(sp)
    sp.add_argument("--config", type=Path, metavar="SWEEP_JSON", help="re-run a sweep from the sweep.json it wrote "
                    "(default: the sweep the options describe)")
    add_out(sp, "store.sqlite, renders/, sweep.json; required unless --config", default="--config's folder")
    add_store(sp, "where the metrics go", default="OUT/store.sqlite")
    add_cluster(sp)
    add_size(sp, ("WxH", "small"), default="each scene's own size")
    add_progress(sp)
    add_no_cache(sp)
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
