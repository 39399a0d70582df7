"""The ``sslpv-harness`` command: its parser, its error lines and its exit statuses.

Every subcommand takes ``--json`` and then prints exactly one JSON object on
stdout: what it wrote (paths) and what it measured (figures). Bad input prints
one line on stderr (``error: <file or setting>: <field>: <problem>; <fix>``)
and exits with status 2; a missing system component (LLVM, OpenGL) exits 3; a
result that a renderer's self-check refused (``harness.errors.ResultRefused``)
prints one line and exits 1. A bare ``sslpv-harness`` (or a command with
sub-commands called without one) prints its usage on stderr and exits 2. The option
names and the options that several commands share are declared in :mod:`.options`.
"""

import argparse
import json
import re
import sys

from harness.cli import (baselines, calibrate, calibrate_best, calibrate_floor, calibrate_form, compare, export, nightly, reference, render, report,
                         scenes, study, sweep)
from harness.cli.options import add_json
from harness.errors import EnvironmentProblem, InputError, ResultRefused

#: ``(name, module)`` of every command, in the order ``--help`` lists them.
COMMANDS = [
    ("scenes", scenes), ("reference", reference), ("render", render), ("compare", compare),
    ("sweep", sweep), ("report", report), ("export", export), ("nightly", nightly), ("baselines", baselines),
    ("calibrate", calibrate), ("calibrate-form", calibrate_form), ("calibrate-floor", calibrate_floor),
    ("calibrate-best", calibrate_best),
    ("study", study),
]


def _emit(args, result, text=None):
    if args.json:
        print(json.dumps(result, indent=None, default=str))
    elif text is not None:
        print(text)
    else:
        print(json.dumps(result, indent=2, default=str))


#: The top-level ``--help``: what the harness is, then its commands.
DESCRIPTION = ("Compare SSLPV (Subsurface Light Propagation Volumes, Borlum et al. 2011) and its rivals with "
               "Mitsuba 3 ground truth, scene by scene.")
EPILOG = ("`sslpv-harness COMMAND --help` documents every option of a command. With --json a command prints one "
          "JSON object on stdout; progress goes to stderr. Exit status: 0 done; 1 a regression, an incomplete run "
          "or a refused result; 2 bad input (one line: error: <file or setting>: <field>: <problem>; <fix>); "
          "3 a missing system component.")


def version():
    """The installed package's version (the source tree's pyproject.toml when it is not installed)."""
    from importlib import metadata

    try:
        return metadata.version("sslpv-harness")
    except metadata.PackageNotFoundError:
        import tomllib

        from harness import paths

        return tomllib.loads((paths.REPO / "pyproject.toml").read_text())["project"]["version"]


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
        if m.group(1) in ("COMMAND", "ACTION"):
            return _unknown_command(prog, m.group(2), fix)
        return at(m.group(1), m.group(2))
    m = re.match(r"the following arguments are required: (.*)", message)
    if m:
        return at(m.group(1).split(",")[0].strip(), "is required")
    m = re.match(r"unrecognized arguments: (.*)", message)
    if m:
        word = m.group(1).split()[0]
        if not word.startswith("-"):                # a value after a flag, or one positional too many
            return UsageError(prog, "arguments", f"{word!r} is not expected here", "a flag such as --eta2 takes no "
                              f"value; see `{prog} --help`")
        return at(word, f"is not an option of `{prog}`")
    return UsageError(prog, "arguments", message, fix)


def _unknown_command(prog, problem, fix):
    """``invalid choice: 'rendr' (choose from ...)`` -> ``unknown command 'rendr'; did you mean render? ...``."""
    import difflib

    m = re.match(r"invalid choice: '([^']*)' \(choose from (.*)\)", problem)
    if not m:
        return UsageError(prog, "command", problem, fix)
    choices = re.findall(r"'([^']*)'", m.group(2))
    close = difflib.get_close_matches(m.group(1), choices, n=1, cutoff=0.6)
    hint = f"did you mean {close[0]}? " if close else ""
    return UsageError(prog, "command", f"unknown command {m.group(1)!r}", f"{hint}one of: {', '.join(choices)}")


def build_parser():
    """The whole command line: a command module's ``configure`` adds its options; one with sub-commands
    (``SUBCOMMANDS``) adds them itself, each with ``--json``."""
    p = _Parser(prog="sslpv-harness", description=DESCRIPTION, epilog=EPILOG)
    p.add_argument("--version", action="version", version=f"sslpv-harness {version()}",
                   help="print the harness's version and exit")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", required=True, parser_class=_Parser)
    for name, module in COMMANDS:
        sp = sub.add_parser(name, help=module.HELP, description=module.HELP)
        if not getattr(module, "SUBCOMMANDS", False):
            add_json(sp)
        module.configure(sp)
        sp.set_defaults(func=module.run)
    return p


def walk(parser, path=()):
    """``(path, parser)`` of the parser and of every command and sub-command under it, depth first."""
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, child in action.choices.items():
                yield from walk(child, path + (name,))


def _bare(parser, argv):
    """The parser whose usage a call without its command (or sub-command) should print, else None."""
    for path, p in walk(parser):
        if list(argv) == list(path) and any(isinstance(a, argparse._SubParsersAction) for a in p._actions):
            return p
    return None


def _parse(parser, argv):
    args, extra = parser.parse_known_args(argv)
    if extra:                                   # name the subcommand, not the top-level program
        words = [w for w in (getattr(args, "command", None), getattr(args, "action", None)) if w]
        prog = " ".join([parser.prog, *words])
        raise _usage_error(prog, f"unrecognized arguments: {' '.join(extra)}")
    return args


def main(argv=None):
    parser = build_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    bare = _bare(parser, [str(a) for a in argv])
    if bare is not None:                        # `sslpv-harness`, `sslpv-harness baselines`: the usage
        print(bare.format_help().rstrip(), file=sys.stderr)
        return 2
    try:
        args = _parse(parser, argv)
        args.argv = argv                        # what a command records as its own command line
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
