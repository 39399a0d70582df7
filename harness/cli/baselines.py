"""``sslpv-harness baselines update|show|regenerate-references``: the committed accuracy baselines."""

from pathlib import Path

from harness.cli.options import positive_int

HELP = "manage the committed accuracy baselines"


def configure(sp):
    sp.add_argument("action", choices=["update", "show", "regenerate-references"])
    sp.add_argument("--scene", help="only this scene")
    sp.add_argument("--store", type=Path, help="store holding the new values (update)")
    sp.add_argument("--into", type=Path, help="regenerate-references: write the checked new reference here "
                    "instead of replacing the committed one")
    sp.add_argument("--scheduler", help="regenerate-references: an existing Dask scheduler (default: a LocalCluster)")
    sp.add_argument("--workers", type=positive_int, help="regenerate-references: LocalCluster workers (default: cores)")
    sp.add_argument("--serial", action="store_true", help="regenerate-references: render in this process")


def run(args):
    from harness.regression.baselines import run_baselines_cli

    result, text = run_baselines_cli(args)
    return result, text, 0
