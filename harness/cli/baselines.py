"""``sslpv-harness baselines update|show|regenerate-references``: the committed accuracy baselines."""

from pathlib import Path

HELP = "manage the committed accuracy baselines"


def configure(sp):
    sp.add_argument("action", choices=["update", "show", "regenerate-references"])
    sp.add_argument("--scene", help="only this scene")
    sp.add_argument("--store", type=Path, help="store holding the new values (update)")
    sp.add_argument("--into", type=Path, help="regenerate-references: write the checked new reference here "
                    "instead of replacing the committed one")


def run(args):
    from harness.regression.baselines import run_baselines_cli

    result, text = run_baselines_cli(args)
    return result, text, 0
