"""The command line's vocabulary and help: every command's and sub-command's ``--help``.

:func:`harness.cli.main.walk` visits the top-level parser, every command and every
sub-command (``baselines update | show | regenerate-references``). Each option must have
help text, a value option that is not required must state its default, every option name
must be in :data:`harness.cli.options.VOCABULARY` (or be a renderer parameter), and an
option that several commands share must be worded as :data:`harness.cli.options.SHARED`
says, with the same type, on every command.
"""

import argparse
from pathlib import Path

import pytest

from harness import paths
from harness.cli import options
from harness.cli.main import build_parser, walk

PARSERS = list(walk(build_parser()))
IDS = [" ".join(path) or "sslpv-harness" for path, _ in PARSERS]
SKIP = (argparse._HelpAction, argparse._VersionAction, argparse._SubParsersAction)


def _options(parser):
    return [a for a in parser._actions if not isinstance(a, SKIP)]


def _takes_value(action):
    return action.nargs != 0 and not isinstance(action, argparse.BooleanOptionalAction)


def _default_text(default):
    """How a default must appear in the help: a path relative to the repository, else as written."""
    if isinstance(default, Path):
        try:
            return str(default.relative_to(paths.REPO))
        except ValueError:
            return str(default)
    return str(default)


def test_every_command_and_sub_command_is_walked():
    assert {"render", "sweep", "nightly", "calibrate", "baselines update", "baselines show",
            "baselines regenerate-references"} <= set(IDS)


@pytest.mark.parametrize("path,parser", PARSERS, ids=IDS)
def test_help_renders(path, parser):
    text = parser.format_help()
    assert "``" not in text, "reStructuredText markup in the help"


@pytest.mark.parametrize("path,parser", PARSERS, ids=IDS)
def test_every_option_has_help(path, parser):
    missing = [a.option_strings or [a.dest] for a in _options(parser)
               if not a.help or a.help == argparse.SUPPRESS or not a.help.strip()]
    assert not missing, f"`{' '.join(path)}`: options without help text: {missing}"


@pytest.mark.parametrize("path,parser", PARSERS, ids=IDS)
def test_every_default_is_shown(path, parser):
    """A value option that may be left out says what it is then; a fixed default appears as it is."""
    bad = []
    for a in _options(parser):
        optional = not a.required and (a.option_strings or a.nargs == "?")
        if not optional or (not _takes_value(a) and not isinstance(a, argparse.BooleanOptionalAction)):
            continue
        help_text = a.help or ""
        if "default" not in help_text:
            bad.append((a.option_strings or [a.dest], "no default stated"))
        elif a.default not in (None, False, argparse.SUPPRESS) and not isinstance(a, argparse.BooleanOptionalAction):
            if _default_text(a.default) not in help_text:
                bad.append((a.option_strings or [a.dest], f"default {_default_text(a.default)!r} not shown"))
    assert not bad, f"`{' '.join(path)}`: {bad}"


@pytest.mark.parametrize("path,parser", PARSERS, ids=IDS)
def test_option_names_are_in_the_vocabulary(path, parser):
    allowed = set(options.VOCABULARY) | options.parameter_options() | {"-h"}
    outside = sorted({o for a in parser._actions for o in a.option_strings} - allowed)
    assert not outside, f"`{' '.join(path)}`: option names outside the vocabulary: {outside}"


@pytest.mark.parametrize("path,parser", PARSERS, ids=IDS)
def test_shared_options_mean_the_same(path, parser):
    """``--out`` is a folder, ``--workers`` an integer > 0, ``--progress`` a flag pair, ... on every command."""
    kinds = {"--out": (Path, "DIR"), "--workers": (options.positive_int, "N"), "--scheduler": (None, "ADDR"),
             "--store": (Path, "STORE"), "--run": (options.positive_int, "ID"), "--scenes": (None, "A,B")}
    for a in _options(parser):
        for name in a.option_strings:
            if name in options.SHARED:
                assert a.help.startswith(options.SHARED[name]), (path, name, a.help)
            if name in kinds:
                assert (a.type, a.metavar) == kinds[name], (path, name, a.type, a.metavar)
            if name == "--progress":
                assert isinstance(a, argparse.BooleanOptionalAction) and a.default is True, path


def test_booleans_are_flags():
    """A renderer's boolean parameter is ``--x / --no-x``, never a value ``true``."""
    for path, parser in PARSERS:
        for a in _options(parser):
            if "--eta2" in a.option_strings:
                assert "--no-eta2" in a.option_strings and "true:" not in a.help, (path, a.help)


def test_a_scene_is_positional_or_scenes():
    """One scene: a positional ``scene``; several: ``--scenes``; never ``--scene``."""
    for path, parser in PARSERS:
        names = {o for a in parser._actions for o in a.option_strings}
        assert "--scene" not in names, path
        if path in (("render",), ("reference",)):
            assert any(a.dest == "scene" and not a.option_strings for a in parser._actions), path
