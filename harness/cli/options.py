"""The command line's one vocabulary: every option name, and the options that several commands share.

An option means the same on every command that takes it, because it is added here and
nowhere else:

* the scene is a positional argument where a command takes exactly one, and
  ``--scenes A,B`` where it takes several;
* ``--out`` is always a folder;
* ``--workers``, ``--scheduler``, ``--serial``, ``--size``, ``--store``, ``--json``,
  ``--progress/--no-progress`` and ``--no-cache`` have one meaning and one wording;
* a boolean is a flag (``--eta2 / --no-eta2``), never a value ``true``.

:data:`VOCABULARY` lists every option name a command may have, with what it means;
:data:`SHARED` the beginning of the help line that a shared option has on every command.
``tests/test_cli_help.py`` walks every command and sub-command and fails on a name outside
the vocabulary, a shared option worded differently, an option without help, and a
value option whose help does not state its default.
"""

import argparse
import dataclasses
import math
from pathlib import Path

#: Every option name of every command (the renderers' parameters are added from their
#: parameter classes by :func:`parameter_options`), with what it means.
VOCABULARY = {
    "--help": "this help", "--version": "the harness's version",
    "--json": "the result as one JSON object on stdout",
    "--out": "the output folder",
    "--scenes": "several suite scenes, comma-separated",
    "--size": "the image size",
    "--workers": "LocalCluster workers",
    "--scheduler": "an existing Dask scheduler",
    "--serial": "in this process, without Dask",
    "--progress": "progress on stderr", "--no-progress": "no progress on stderr",
    "--no-cache": "render afresh instead of serving the result cache",
    "--store": "a results store",
    "--run": "a run id of a store",
    "--config": "a sweep.json to re-run",
    "--matrix": "the nightly's matrix file",
    "--date": "the night's date",
    "--method": "the method(s)",
    "--target": "a reference's noise target", "--spp": "samples per pixel", "--variant": "Mitsuba variant",
    "--sms-split": "the rest's samples per sampled one",
    "--force": "re-render a cached reference", "--max-minutes": "a wall-time cap", "--estimate": "predict only",
    "--mask": "the pixels to compare", "--all-pixels": "every pixel",
    "--budget-ms": "a cost budget",
    "--format": "an export's table format",
    "--schema": "the scene.toml JSON Schema",
    "--docs": "write docs/results.md",
    "--family": "a mapping family", "--sigma-range": "the scanned sigma_scale range",
    "--points": "the scanned sigma_scale values",
    "--into": "write elsewhere than the committed place",
    "--from": "the calibrate folders a per-cell form is fitted from",
    "--against": "the calibrate folders a form's relMSE target compares with",
    "--free-level": "a per-cell form's own level terms",
    "--slopes": "which scales a per-cell form makes depend on the material",
}

#: The start of the help line of an option that several commands take: the same on every command.
SHARED = {
    "--json": "print one JSON object on stdout",
    "--out": "output folder",
    "--scenes": "comma-separated suite scene names",
    "--size": "image size",
    "--workers": "LocalCluster workers",
    "--scheduler": "address of an existing Dask scheduler",
    "--serial": "render in this process, without Dask",
    "--progress": "progress on stderr",
    "--no-cache": "render every configuration afresh",
    "--store": "results store (a store.sqlite)",
    "--run": "run id of the store",
}


# --------------------------------------------------------------------------- value types

def positive_int(value):
    """argparse type: an integer > 0."""
    try:
        out = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer > 0, got {value!r}") from None
    if out <= 0:
        raise argparse.ArgumentTypeError(f"must be an integer > 0, got {value!r}")
    return out


def positive_number(value):
    """argparse type: a finite number > 0 (``nan``, ``inf`` and ``-1`` are refused)."""
    try:
        out = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number > 0, got {value!r}") from None
    if not math.isfinite(out) or out <= 0:
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {value!r}")
    return out


class Flag(argparse.BooleanOptionalAction):
    """``--name / --no-name``; the help states the default itself, so argparse's own ``(default: ...)``
    suffix, which some Python versions add to this action, is taken off again."""

    def __init__(self, option_strings, dest, default=None, help=None, **kwargs):
        super().__init__(option_strings, dest, default=default, help=help, **kwargs)
        self.help = help


# --------------------------------------------------------------------------- shared options

def add_scene(sp):
    """The one scene of a command, positional."""
    sp.add_argument("scene", help="the scene: a suite scene's name (`sslpv-harness scenes` lists them), or a "
                    "scene folder or scene.toml")


def add_scenes(sp, default="the whole suite"):
    sp.add_argument("--scenes", metavar="A,B", help=f"{SHARED['--scenes']} (default: {default})")


def add_out(sp, what, required=False, default=None):
    """``--out DIR``: always a folder; ``what`` says what the command writes into it."""
    tail = "" if required else f" (default: {default})"
    sp.add_argument("--out", type=Path, metavar="DIR", required=required,
                    help=f"{SHARED['--out']}: {what}{tail}")


def add_size(sp, forms, default="the scene's own size"):
    """``--size``: ``WxH``, and where a command has them ``small`` and ``own``."""
    words = {"WxH": "WxH (pixels)",
             "small": "small (each scene at its committed small size, against its committed reference in "
                      "baselines/refs/)",
             "own": "own (each scene's own size, its Mitsuba reference rendered into cache/references/ first)"}
    sp.add_argument("--size", metavar="|".join(forms),
                    help=f"{SHARED['--size']}: " + ", ".join(words[f] for f in forms) + f" (default: {default})")


def add_cluster(sp, serial=False):
    """``--scheduler``, ``--workers`` and, where a command can render without Dask, ``--serial``."""
    sp.add_argument("--scheduler", metavar="ADDR", help=f"{SHARED['--scheduler']} whose workers have this project "
                    "installed (default: a LocalCluster on this machine)")
    sp.add_argument("--workers", type=positive_int, metavar="N",
                    help=f"{SHARED['--workers']}, an integer > 0 (default: the CPU cores)")
    if serial:
        sp.add_argument("--serial", action="store_true", help=SHARED["--serial"])


def add_progress(sp):
    sp.add_argument("--progress", action=Flag, default=True,
                    help=f"{SHARED['--progress']}: a bar on a terminal, one line per step in a log "
                         "(SSLPV_PROGRESS=bar|lines|off overrides the form; default: --progress)")


def add_sms_split(sp):
    sp.add_argument("--sms-split", dest="sms_split", type=positive_int, metavar="N", help="with specular manifold "
                    "sampling ([boundary] sms_trials): render the sampled solutions' light in a pass of its own, "
                    "with one sample for every N of the rest, 1 to 64; 1 renders one pass (default: "
                    "harness/reference/jobs.py's DEFAULT_SMS_SPLIT where the scene samples)")


def add_no_cache(sp):
    sp.add_argument("--no-cache", action="store_true", help=f"{SHARED['--no-cache']} instead of serving an "
                    "unchanged one from the result cache (cache/results/)")


def add_store(sp, what, required=False, default=None):
    tail = "" if required else f" (default: {default})"
    sp.add_argument("--store", type=Path, metavar="STORE", required=required,
                    help=f"{SHARED['--store']}: {what}{tail}")


def add_run(sp, default):
    sp.add_argument("--run", type=positive_int, metavar="ID", help=f"{SHARED['--run']} (default: {default})")


def add_json(sp):
    sp.add_argument("--json", action="store_true", help=f"{SHARED['--json']}: what the command wrote and measured")


# --------------------------------------------------------------------------- renderer parameters

def _param_help(method, field, multi, owners=None):
    """A parameter's help: its class's one-line doc, with its default when the doc does not state it."""
    doc = method.doc(field)
    is_flag = method.field_types()[field] in ("bool", bool)
    if "default" not in doc:
        default = {f.name: f.default for f in dataclasses.fields(method.params_type)}[field]
        if is_flag:
            default = f"--{'' if default else 'no-'}{field.replace('_', '-')}"
        doc += f" (default {default})"
    head = "comma-separated list of values; " if multi and not is_flag else ""
    return head + (f"[{owners}] " if owners else "") + doc


def parameter_options():
    """Every renderer parameter's option name (``--grid``, ``--eta2``/``--no-eta2``, ...)."""
    from harness.methods import METHOD_NAMES, get_method

    names = set()
    for name in METHOD_NAMES:
        m = get_method(name)
        types = m.field_types()
        for cli, field in m.cli.items():
            names.add("--" + cli.replace("_", "-"))
            if types[field] in ("bool", bool):
                names.add("--no-" + cli.replace("_", "-"))
    return names


def _add_param(sp, method, cli, field, multi, owners=None):
    help_text = _param_help(method, field, multi, owners)
    if method.field_types()[field] in ("bool", bool):
        # A flag: the value reaches the parameter parser as the word it reads (harness.methods.params.convert).
        if multi:
            help_text += "; give both flags to sweep both values"
        sp.add_argument("--" + cli.replace("_", "-"), dest=cli, action=_WordFlag, help=help_text, const=multi)
    else:
        sp.add_argument("--" + cli.replace("_", "-"), dest=cli, metavar=_metavar(cli, multi), help=help_text)


class _WordFlag(Flag):
    """``--eta2`` -> ``"true"``, ``--no-eta2`` -> ``"false"``, absent -> None (the parameter's default).

    On a sweep (``const=True``) both flags together give the list ``"true,false"``, in the order given.
    """

    def __init__(self, option_strings, dest, const=False, **kwargs):
        super().__init__(option_strings, dest, **kwargs)
        self.multi = const

    def __call__(self, parser, namespace, values, option_string=None):
        if option_string in self.option_strings:
            word = "false" if option_string.startswith("--no-") else "true"
            old = getattr(namespace, self.dest, None)
            if self.multi and old is not None and word not in old.split(","):
                word = f"{old},{word}"
            setattr(namespace, self.dest, word)


def _metavar(cli, multi):
    base = {"grid": "N", "steps": "K"}.get(cli, cli.upper())
    return f"{base},..." if multi else base


def add_sslpv_args(sp, multi):
    """SSLPV's parameters (:class:`sslpv_gl.params.SSLPVParams`), with their defaults and ranges; a sweep
    takes each as a comma-separated list."""
    from harness.methods import get_method

    m = get_method("sslpv")
    for cli, field in m.cli.items():
        _add_param(sp, m, cli, field, multi)


def add_method_args(sp, multi):
    """``--method`` and the parameters of every method other than SSLPV (``harness.methods``), from their docs."""
    from harness.methods import METHOD_NAMES, get_method

    kind = "comma-separated list of methods" if multi else "method"
    sp.add_argument("--method", metavar="M,..." if multi else "M",
                    help=f"{kind}: {' | '.join(METHOD_NAMES)} (default: sslpv); each method takes only its own "
                         "parameters")
    seen = set(get_method("sslpv").cli)
    for name in METHOD_NAMES:
        m = get_method(name)
        for cli, field in m.cli.items():
            if cli in seen:
                continue
            seen.add(cli)
            owners = ", ".join(n for n in METHOD_NAMES if cli in get_method(n).cli)
            _add_param(sp, m, cli, field, multi, owners)
