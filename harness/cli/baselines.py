"""``sslpv-harness baselines update | show | regenerate-references``: the committed accuracy baselines.

Each action is a sub-command with its own options:

* ``update --store S [--scenes A,B]`` accepts the values and images of the store's latest run;
* ``show [--store S] [--scenes A,B]`` prints the committed entries as a table or, with ``--store``,
  what ``update`` would change (before and after) without writing anything;
* ``regenerate-references [--scenes A,B] [--into DIR]`` renders the small references again and
  keeps one only where it agrees with the committed one.
"""

from pathlib import Path

from harness.cli.options import add_cluster, add_json, add_progress, add_scenes, add_sms_split, add_store

HELP = "accept, show or regenerate the committed accuracy baselines"
#: This command's actions are sub-commands (each adds its own ``--json``).
SUBCOMMANDS = True


def configure(sp):
    sub = sp.add_subparsers(dest="action", metavar="ACTION", required=True)
    up = sub.add_parser("update", help="accept the store's latest run as the new baselines and print a before/after "
                        "table", description="Replace the baseline entries (values and committed SSLPV images) of "
                        "the configurations in the store's latest run (a `sweep --size small` of "
                        "baselines/accuracy_matrix.toml); print a before/after table.")
    add_json(up)
    add_store(up, "holding the new values", required=True)
    add_scenes(up, default="every scene of the run")

    show = sub.add_parser("show", help="print the committed baselines, or with --store what update would change",
                          description="Print the committed baseline entries as a table; with --store, the "
                          "before/after table that `update --store` would write, writing nothing.")
    add_json(show)
    add_store(show, "show what update would take from it, without writing", default="none: the committed entries")
    add_scenes(show, default="every scene with a baseline")

    regen = sub.add_parser("regenerate-references", help="re-render the small references; refused where one "
                           "disagrees statistically with the committed one",
                           description="Render the committed small references again with new seeds and keep each "
                           "only where it agrees with the committed one (per-pixel Welch t-test, Bonferroni).")
    add_json(regen)
    add_scenes(regen)
    regen.add_argument("--into", type=Path, metavar="DIR", help="write the checked new reference into this folder "
                       "instead of replacing the committed one; needs exactly one scene (default: replace it)")
    add_sms_split(regen)
    add_cluster(regen, serial=True)
    add_progress(regen)


def run(args):
    from harness.regression.baselines import run_baselines_cli

    result, text = run_baselines_cli(args)
    return result, None if args.json else text, 0
