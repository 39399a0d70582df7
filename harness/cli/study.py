"""``sslpv-harness study``: a study file from the scene suite to the accuracy map (``harness.study``)."""

from pathlib import Path

from harness import paths
from harness.cli.options import add_cluster, add_no_cache, add_out, add_progress, add_size

HELP = "run an accuracy study (default: studies/default.toml) and write its map, tables and figures"


def configure(sp):
    sp.add_argument("study", nargs="?", type=Path, default=paths.REPO / "studies" / "default.toml",
                    help="the study file (default: studies/default.toml)")
    add_out(sp, "the study's (index.html, results.csv, results.parquet, study.json, figures/); new, empty, or an "
            "earlier study's; required without --docs", default="reports/study with --docs")
    add_size(sp, ("small", "own", "WxH"), default="the study file's")
    sp.add_argument("--docs", action="store_true", help="then write docs/results.md and its figures from it")
    add_cluster(sp)
    add_progress(sp)
    add_no_cache(sp)


def run(args):
    """Exit 1 when the sweep is incomplete (one line says how to resume it)."""
    import shlex
    import sys

    from harness.errors import InputError
    from harness.runs.sweep import parse_size
    from harness.study.run import run_study

    out = args.out or (paths.REPO / "reports" / "study" if args.docs else None)
    if out is None:
        raise InputError("--out", "out", "is required", "give the study's folder, e.g. --out /tmp/study")
    size = args.size
    size = "own" if size is not None and size.strip().lower() == "own" else parse_size(size)
    command = "sslpv-harness " + " ".join(shlex.quote(a) for a in args.argv if a != "--json")
    result = run_study(args.study, out, size=size, scheduler=args.scheduler, workers=args.workers,
                       progress=args.progress, cache=not args.no_cache, command=command, rebuild=args.docs)
    built = result.pop("_built", None)
    if result["status"] != "finished":
        line = InputError(result["out"], "sweep", f"is incomplete: {result.get('error')}",
                          f"run the same command again to render what is missing: {result['resume']}")
        print(f"error: {line}", file=sys.stderr)
        return result, None, 1
    if args.docs:
        from harness.study.docs import write_docs

        result["docs"] = write_docs(built, out)
    return result, None, 0
