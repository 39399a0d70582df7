"""The command line, ``sslpv-harness``: one module per command, registered in :mod:`.main`.

A command module has ``HELP`` (one line), ``configure(parser)`` (its arguments) and
``run(args) -> (result, text, exit_code)``; a command with sub-commands (``baselines``) sets
``SUBCOMMANDS = True`` and adds them, each with ``--json``, in ``configure``. To add a command,
write such a module and add it to :data:`harness.cli.main.COMMANDS`; its options come from
:mod:`harness.cli.options`, whose vocabulary ``tests/test_cli_help.py`` enforces.
"""

from harness.cli.main import build_parser, main

__all__ = ["build_parser", "main"]
