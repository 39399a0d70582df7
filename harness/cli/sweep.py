"""``sslpv-harness sweep``: every SSLPV configuration of a sweep, on Dask, into a store."""

from pathlib import Path

from harness.cli.options import add_sslpv_args, positive_int

HELP = "render every SSLPV configuration of a sweep and store its metrics"


def configure(sp):
    sp.add_argument("--scenes", help="comma-separated scene names (default: the whole suite)")
    sp.add_argument("--config", type=Path, help="re-run a sweep from the sweep.json it wrote")
    sp.add_argument("--out", type=Path, help="output folder (holds store.sqlite, renders/, sweep.json)")
    sp.add_argument("--store", type=Path, help="results store (default: OUT/store.sqlite)")
    sp.add_argument("--scheduler", help="address of an existing Dask scheduler (default: a LocalCluster)")
    sp.add_argument("--workers", type=positive_int, help="LocalCluster workers (default: CPU cores)")
    sp.add_argument("--size", help="image size WxH for SSLPV and reference (default: the scene's)")
    sp.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    add_sslpv_args(sp, multi=True)


def run(args):
    from harness.runs.sweep import run_sweep_cli

    return run_sweep_cli(args), None, 0
