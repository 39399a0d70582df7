"""``python -m tests.mutations [NAME ...] [--jobs N] [--list]``: run planted errors, print the report."""

import argparse
import json
import sys

from .catalogue import MUTATIONS
from .runner import report, run_all


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m tests.mutations", description=__doc__)
    ap.add_argument("names", nargs="*", help="mutations to run (default: all)")
    ap.add_argument("--jobs", type=int, default=2, help="mutations run at a time (one repository copy each)")
    ap.add_argument("--list", action="store_true", help="list the mutations and exit")
    ap.add_argument("--json", help="also write the results to this JSON file")
    args = ap.parse_args(argv)
    if args.list:
        for m in MUTATIONS:
            print(f"{m.name:<34} {m.kind:<8} {m.path}: {m.what}")
        return 0
    known = {m.name: m for m in MUTATIONS}
    unknown = [n for n in args.names if n not in known]
    if unknown:
        print(f"error: unknown mutation(s): {', '.join(unknown)}; see --list", file=sys.stderr)
        return 2
    chosen = [known[n] for n in args.names] if args.names else list(MUTATIONS)
    results, seconds = run_all(chosen, jobs=args.jobs,
                            progress=lambda r: print(f"{r['status']:<8} {r['seconds']:6.1f} s  {r['name']}",
                                                     file=sys.stderr, flush=True))
    print(report(results, seconds))
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"seconds": seconds, "results": results}, f, indent=1)
    return 0 if all(r["status"] == "killed" for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
