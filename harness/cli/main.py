"""``sslpv-harness``: the command line.

Every subcommand takes ``--json`` and then prints exactly one JSON object on
stdout: what it wrote (paths) and what it measured (figures). Bad input prints
one line on stderr (``error: <file or setting>: <field>: <problem>; <fix>``)
and exits with status 2; a missing system component (LLVM, OpenGL) exits 3; a
result that a renderer's self-check refused (``harness.errors.ResultRefused``)
prints one line and exits 1.
"""

import argparse
import json
import re
import sys

from harness.cli import baselines, calibrate, compare, export, nightly, reference, render, report, scenes, study, sweep
from harness.errors import EnvironmentProblem, InputError, ResultRefused

#: ``(name, module)`` of every command, in the order ``--help`` lists them.
COMMANDS = [
    ("scenes", scenes), ("reference", reference), ("render", render), ("compare", compare),
    ("sweep", sweep), ("report", report), ("export", export), ("nightly", nightly), ("baselines", baselines),
    ("calibrate", calibrate), ("study", study),
]


def _emit(args, result, text=None):
    if args.json:
        print(json.dumps(result, indent=None, default=str))
    elif text is not None:
        print(text)
    else:
        print(json.dumps(result, indent=2, default=str))


class UsageError(InputError):
    """A command line that argparse refuses, as one line in the project's form."""


class _Parser(argparse.ArgumentParser):
    """argparse, but a bad command line is ONE line (``error: <command>: <option>: <problem>; <fix>``)
    instead of the usage block; ``--help`` is unchanged."""

    def error(self, message):
        raise _usage_error(self.prog, message)


def _usage_error(prog, message):
    """argparse's message -> ``<option>: <name>: <problem>; see `<command> --help```."""
    fix = f"see `{prog} --help`"

    def at(option, problem):
        if option.startswith("-"):
            return UsageError(option, option.lstrip("-").replace("-", "_"), problem, fix)
        return UsageError(prog, option, problem, fix)          # a positional argument

    m = re.match(r"argument (\S+?)(?:/\S+)?: (.*)", message)
    if m:
        if m.group(1) == "command":
            return UsageError(prog, "command", m.group(2).replace("invalid choice: ", "unknown command "), fix)
        return at(m.group(1), m.group(2))
    m = re.match(r"the following arguments are required: (.*)", message)
    if m:
        return at(m.group(1).split(",")[0].strip(), "is required")
    m = re.match(r"unrecognized arguments: (.*)", message)
    if m:
        return at(m.group(1).split()[0], f"is not an option of `{prog}`")
    return UsageError(prog, "arguments", message, fix)


def build_parser():
    p = _Parser(prog="sslpv-harness", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for name, module in COMMANDS:
        sp = sub.add_parser(name, help=module.HELP, description=module.HELP)
        sp.add_argument("--json", action="store_true", help="print one JSON object on stdout")
        module.configure(sp)
        sp.set_defaults(func=module.run)
    return p


def _parse(parser, argv):
    args, extra = parser.parse_known_args(argv)
    if extra:                                   # name the subcommand, not the top-level program
        prog = f"{parser.prog} {args.command}" if getattr(args, "command", None) else parser.prog
        raise _usage_error(prog, f"unrecognized arguments: {' '.join(extra)}")
    return args


def main(argv=None):
    parser = build_parser()
    try:
        args = _parse(parser, argv)
        args.argv = list(sys.argv[1:] if argv is None else argv)  # what a command records as its own command line
        result, text, code = args.func(args)
        _emit(args, result, text)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        if exc.filename is None:
            raise
        # A path that could not be written or read once the work had begun (a disk that
        # filled, a folder whose permissions changed): one line, not a traceback.
        line = InputError(exc.filename, "file", exc.strerror or type(exc).__name__,
                          "check the path, its permissions and the free space")
        print(f"error: {line}", file=sys.stderr)
        return 2
    except EnvironmentProblem as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 3
    except ResultRefused as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted; finished results are kept, run the same command again to resume", file=sys.stderr)
        return 130
    return int(code or 0)


if __name__ == "__main__":
    sys.exit(main())
