"""``sslpv-harness report STORE_OR_RUN --out DIR``: the static HTML report of a store or a sweep folder."""

from pathlib import Path

from harness.cli.options import add_out, add_run, positive_number
from harness.errors import InputError


def resolve_store(source):
    """A store file, or a sweep folder holding ``store.sqlite``."""
    source = Path(source)
    if source.is_dir():
        source = source / "store.sqlite"
    if not source.is_file():
        raise InputError(source, "store", "does not exist", "give a store.sqlite or the folder a sweep wrote")
    return source


def run_report_cli(args):
    from harness.report.build import build_report

    return build_report(resolve_store(args.source), args.out, run_id=args.run, cost_budget_ms=args.budget_ms)


HELP = "build the static HTML report of a store or a sweep folder"


def configure(sp):
    sp.add_argument("source", type=Path, help="store.sqlite, or a sweep folder holding one")
    add_out(sp, "the static site (index.html; opens from the file system)", required=True)
    add_run(sp, default="the latest")
    sp.add_argument("--budget-ms", type=positive_number, metavar="MS",
                    help="SSLPV cost budget for the summary, ms > 0 (default: the median cost)")


def run(args):
    return run_report_cli(args), None, 0
