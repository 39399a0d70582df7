"""The files of a calibration form: the source calibrations read as one, and the version 3 file written.

:func:`read_sources` merges ``sslpv-harness calibrate`` folders of one family (e.g. one per grid) into one
calibration whose ``results`` hold every budget; :func:`against_medians` reads the held-out medians a form's
relMSE target compares with; :func:`form_toml` writes a version 3 ``calibrated.toml``
(:mod:`sslpv_gl.calibrated`) from per-budget coefficients. Used by :mod:`harness.calibration.form`.

Limits: the sources must share family, renderer settings and scenes, and name each budget once; anything else
is refused with one line (:class:`~harness.errors.InputError`).
"""

from __future__ import annotations

import json
from pathlib import Path

from harness.calibration.scan import budget_label
from harness.errors import InputError

__all__ = ["form_toml", "read_sources", "against_medians"]


def form_toml(family, settings, budgets, fit_info):
    """A version 3 calibrated mapping file: ``budgets`` is ``[(N, steps, terms, sigma, radiance), ...]``
    (coefficients ``[const, *terms]``), written against the file's one ``[form]`` term list."""
    from sslpv_gl.calibrated import FORM_VERSION, FORMAT
    from sslpv_gl.material_form import TERMS

    def val(v):
        return json.dumps(v) if isinstance(v, (str, bool, list)) else repr(v)

    lines = ["# Written by python -m harness.calibration.form; use it as --mapping calibrated:PATH.",
             f'format = "{FORMAT}"', f"version = {FORM_VERSION}", f'family = "{family}"', "",
             "[settings]   # the renderer settings of the fit: a render must use the same"]
    lines += [f"{k} = {val(v)}" for k, v in settings.items()]
    lines += ["", "[fit]"] + [f"{k} = {val(v)}" for k, v in fit_info.items()]
    lines += ["", "[form]   # ln s = a0 + sum_k a_k x_k, the same for ln r (sslpv_gl.material_form, Eq. F1)",
              f"terms = {val(list(TERMS))}"]
    for N, steps, terms, sigma, radiance in budgets:
        full = {}
        for name, coeffs in (("sigma_form", sigma), ("radiance_form", radiance)):
            by_term = dict(zip(terms, coeffs[1:]))
            full[name] = [float(coeffs[0])] + [float(by_term.get(t, 0.0)) for t in TERMS]
        lines += ["", "[[budget]]", f"N = {N}", f"steps = {val(steps)}",
                  f"sigma_form = {val(full['sigma_form'])}", f"radiance_form = {val(full['radiance_form'])}"]
    return "\n".join(lines) + "\n"


def against_medians(dirs):
    """``{family: {budget label: median held-out relMSE}}`` of the calibrations in ``dirs``."""
    out = {}
    for d in dirs:
        cal = json.loads((Path(d) / "calibration.json").read_text())
        out.setdefault(cal["family"], {}).update(
            {label: res["targets"]["median_held_out_relmse"] for label, res in cal["results"].items()})
    return out


def read_sources(paths):
    """The calibrations in ``paths`` as one: their budgets together (one family, one set of settings and scenes;
    a budget in two of them is refused) -> ``(cal, settings)``, ``cal["results"]`` holding every budget."""
    from sslpv_gl.calibrated import load_calibrated
    from sslpv_gl.material import MAPPINGS

    merged, settings = None, None
    for source in map(Path, paths):
        cal_path = source / "calibration.json"
        if not cal_path.is_file():
            raise InputError(cal_path, "file", "does not exist", "give the --out folder of sslpv-harness calibrate")
        cal = json.loads(cal_path.read_text())
        these = dict(load_calibrated(source / "calibrated.toml", tuple(MAPPINGS)).settings)
        if merged is None:
            merged, settings = dict(cal, budgets=[], results={}), these
        for key, have, want in (("family", cal["family"], merged["family"]), ("settings", these, settings),
                                ("scenes", cal["scenes"], merged["scenes"])):
            if have != want:
                raise InputError(cal_path, key, f"differs from the first --from calibration's ({have!r} against "
                                 f"{want!r})", "give calibrations of one family, settings and scenes")
        for N, k in cal["budgets"]:
            label = budget_label(int(N), k)
            if label in merged["results"]:
                raise InputError(cal_path, "budgets", f"{label} is also in another --from calibration",
                                 "give each budget once")
            merged["budgets"].append([int(N), k])
            merged["results"][label] = cal["results"][label] | {"source": str(source)}
    return merged, settings
