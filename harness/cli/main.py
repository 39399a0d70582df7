"""``sslpv-harness``: the command line.

Every subcommand takes ``--json`` and then prints exactly one JSON object on
stdout: what it wrote (paths) and what it measured (figures). Bad input prints
one line on stderr (``error: <file or setting>: <field>: <problem>; <fix>``)
and exits with status 2; a missing system component (LLVM, OpenGL) exits 3.
"""

import argparse
import json
import sys

from harness.cli import baselines, calibrate, compare, export, nightly, reference, render, report, scenes, sweep
from harness.errors import EnvironmentProblem, InputError

#: ``(name, module)`` of every command, in the order ``--help`` lists them.
COMMANDS = [
    ("scenes", scenes), ("reference", reference), ("render", render), ("compare", compare),
    ("sweep", sweep), ("report", report), ("export", export), ("nightly", nightly), ("baselines", baselines),
    ("calibrate", calibrate),
]


def _emit(args, result, text=None):
    if args.json:
        print(json.dumps(result, indent=None, default=str))
    elif text is not None:
        print(text)
    else:
        print(json.dumps(result, indent=2, default=str))


def build_parser():
    p = argparse.ArgumentParser(prog="sslpv-harness", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)
    for name, module in COMMANDS:
        sp = sub.add_parser(name, help=module.HELP, description=module.HELP)
        sp.add_argument("--json", action="store_true", help="print one JSON object on stdout")
        module.configure(sp)
        sp.set_defaults(func=module.run)
    return p


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)      # what a command records as its own command line
    try:
        result, text, code = args.func(args)
        _emit(args, result, text)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except EnvironmentProblem as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 3
    except KeyboardInterrupt:
        print("interrupted; finished results are kept, run the same command again to resume", file=sys.stderr)
        return 130
    return int(code or 0)


if __name__ == "__main__":
    sys.exit(main())
