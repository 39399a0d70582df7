"""The outside treatment SSLPV's extensions render with when none is given.

The study measures each outside treatment against the paper's (``vacuum``) on the suite and chooses the one
the extensions default to (:func:`harness.study.extensions.default_outside`: the lowest median ratio of the
ranking metric, pooled over mappings and scenes, provided it is below 1). ``sslpv-harness study --docs``
commits that choice to :data:`CHOICE` beside ``docs/results.md``, with every treatment's ratio, the command
and the commit. This module applies it: a configuration that turns on an extension (a value other than the
paper's of :data:`sslpv_gl.params.PAPER_SETTINGS` but ``outside``, or an extension mapping such as
``transport``) and gives no ``outside`` renders with the committed choice, or, where the configuration
refuses it (``boundary_reflect = rdr`` and ``transport`` refuse ``extrapolated``), with the next treatment
of the file that it accepts and that beat the paper's (ratio below 1). Without one, the paper's default
stands (and ``transport``, which needs a treatment that takes light out, is refused in one line as before).

SSLPV as published keeps the paper's ``vacuum``: a configuration with no extension is never changed. A
setting given explicitly is never changed, and a calibrated mapping brings its own file's settings
(:meth:`sslpv_gl.params.SSLPVParams.given`). The render records the treatment it used (``render.json``,
and the configuration's label names it, as any setting other than the default).

It acts where a configuration is built from the settings a user gave (:meth:`harness.methods.sslpv.SSLPVMethod.
make_params`: ``render``, ``sweep`` and its products, the study's products, the nightly's matrices).
``calibrate`` does not use it: a fit takes the settings it is given and the paper's for the rest, so the
command a committed calibration records reproduces it whatever this file says.

Limits: the choice is the study's last ``--docs`` run's (its suite, budgets and metric); no file (a study
never written to the docs) leaves every default the paper's. The default study gives every product an
explicit ``outside``, so its own families never depend on this file.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from harness import paths
from harness.errors import InputError

__all__ = ["CHOICE", "FORMAT", "committed_choice", "with_extension_outside", "write_choice"]

#: The committed choice, written by ``sslpv-harness study --docs``.
CHOICE = paths.REPO / "baselines" / "extensions" / "outside.json"
FORMAT = "sslpv-extensions-outside"
_FIX = "write it again with sslpv-harness study --docs"


def committed_choice(path=CHOICE):
    """The committed choice as a dict (``outside``, ``by_mode``: treatment -> median ratio, ...), or None."""
    path = Path(path)
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(str(path), "file", f"cannot be read as JSON ({exc})", _FIX) from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise InputError(str(path), "format", f"is not {FORMAT!r}", _FIX)
    from sslpv_gl.params import OUTSIDE

    by_mode = data.get("by_mode")
    if not isinstance(by_mode, dict) or not all(
            m in OUTSIDE and isinstance(v, (int, float)) and math.isfinite(v) for m, v in by_mode.items()):
        raise InputError(str(path), "by_mode", f"must map outside treatments ({', '.join(OUTSIDE)}) to finite "
                         "median ratios", _FIX)
    if data.get("outside") not in OUTSIDE:
        raise InputError(str(path), "outside", f"{data.get('outside')!r} is not one of {', '.join(OUTSIDE)}", _FIX)
    return data


def _turns_on_an_extension(fields):
    from sslpv_gl.params import EXTENSION_MAPPINGS, PAPER_SETTINGS

    if fields.get("mapping") in EXTENSION_MAPPINGS:
        return True
    return any(k in fields and fields[k] is not None and fields[k] != v
               for k, v in PAPER_SETTINGS.items() if k != "outside")


def with_extension_outside(fields, params_type, path=None):
    """``fields`` with ``outside`` set to the extensions' committed treatment where the module docstring says so.

    ``fields`` are the settings given explicitly; ``params_type`` builds a configuration from them (to learn
    whether it accepts a treatment); ``path``: the committed file (default :data:`CHOICE`). Returns a new
    dict, or ``fields`` itself when nothing applies.
    """
    from sslpv_gl.calibrated import parse_mapping
    from sslpv_gl.params import PAPER_SETTINGS

    if "outside" in fields or parse_mapping(fields.get("mapping")) is not None or not _turns_on_an_extension(fields):
        return fields
    choice = committed_choice(CHOICE if path is None else path)
    if choice is None:
        return fields
    paper, by_mode = PAPER_SETTINGS["outside"], choice["by_mode"]
    if choice["outside"] == paper:                   # no treatment beat the paper's
        return fields
    beat = sorted((m for m, r in by_mode.items() if r < 1.0 and m != paper), key=by_mode.get)
    for mode in dict.fromkeys([choice["outside"], *beat]):
        try:
            params_type(**{**fields, "outside": mode})
        except InputError:
            continue
        return {**fields, "outside": mode}
    return fields


def write_choice(choice, info, path=CHOICE):
    """Commit the study's ``default_outside`` (``choice``; None writes nothing) with its provenance -> the path or None."""
    if choice is None:
        return None
    from harness.io.atomic import atomic_write

    data = {"format": FORMAT, "version": 1, "outside": choice["outside"],
            "median_ratio": choice["median_ratio"], "by_mode": choice["by_mode"],
            "scenes": choice.get("scenes", {}), "command": info.get("command"), "commit": info.get("commit"),
            "study_sha256": info.get("study_sha256"), "created": info.get("created")}
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(path) as tmp:
        tmp.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")
    return str(path)
