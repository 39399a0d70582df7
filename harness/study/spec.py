"""The study file (``studies/default.toml``): what an accuracy study renders, compares and reports.

A study file is TOML, typed by :class:`StudyFile` (``extra = "forbid"``: an unknown key is refused):

* ``scenes``: ``"all"`` or a list of suite scene names (or scene folders);
* ``size``: ``"small"`` (each scene at its committed small size, against the committed references),
  ``[W, H]``, or left out for each scene's own size (references rendered on the sweep's cluster);
* ``[[products]]``: parameter grids, the syntax of the nightly matrix's ``[params]``/``[[also]]``
  tables (:func:`harness.runs.params.any_product_model`; ``method = "dipole"`` makes a rival's);
* ``calibrations``: calibrated mapping files (``sslpv-harness calibrate``); each is rendered at every
  budget of ``[budget]`` that it has, with the settings it was fitted with, and its
  ``calibration.json`` beside it (when there) gives the in-sample and held-out errors;
* ``[budget]``: the real-time budgets of the headline table (``grid`` N and the ``steps`` K);
* ``metrics``: the headline table's metrics; ``significance``: those judged as paired differences
  (:func:`harness.metrics.uncertainty.paired_difference`: the delta method for the metrics with a
  gradient, :data:`harness.metrics.uncertainty.GRADIENTS`; parametric resampling of the reference
  for the others, such as ``flip``, at 2 x 16 evaluations of the metric per comparison);
* ``[[twins]]``: index-matched / dielectric scene pairs for the boundary decomposition.

:func:`load_study` validates it and resolves it into the sweep's products. Every bad value is one
line naming the file and the key (an :class:`~harness.errors.InputError`).
"""

import hashlib
from pathlib import Path
from typing import Annotated, Literal, Optional, Union

from pydantic import Field

from harness.errors import InputError
from harness.metrics import METRICS
from harness.regression.nightly import _split_methods
from harness.runs.params import any_product_model, check_methods, check_products, product_dict
from harness.scene import list_scenes
from harness.validation import InputModel, SweepSize, read_toml, validate

_Name = Annotated[str, Field(min_length=1)]
_Steps = Union[Annotated[int, Field(ge=1, le=4096)], Literal["steady"]]


class Budget(InputModel):
    """The real-time budgets of the headline table: one N, several K."""

    grid: Annotated[int, Field(ge=2, le=256)] = Field(32, description="the LPV resolution N of the budgets")
    steps: Annotated[list[_Steps], Field(min_length=1)] = Field(
        [8, 16, 32, 64, "steady"], description='propagation steps K of each budget, or "steady"')


class Twin(InputModel):
    """Two scenes that differ only in their boundary."""

    index_matched: _Name
    dielectric: _Name


class StudyFile(InputModel):
    """A study file (see the module docstring)."""

    title: str = Field("SSLPV accuracy study", description="the page's title")
    scenes: Union[Literal["all"], Annotated[list[_Name], Field(min_length=1)]] = Field(
        "all", description='"all", or a list of suite scene names', examples=[["thin_ring"]])
    size: Optional[SweepSize] = Field(None, description='"small", [W, H], or left out for each scene\'s own')
    budget: Budget = Field(default_factory=Budget)
    metrics: Annotated[list[Literal[tuple(METRICS)]], Field(min_length=1)] = Field(
        ["relmse", "flip", "energy_ratio"], description="the headline metrics (subsurface image)")
    significance: list[Literal[tuple(METRICS)]] = Field(
        ["relmse", "energy_ratio"], description="metrics judged as paired differences against the best")
    products: Annotated[list[any_product_model("cli")], Field(min_length=1)] = Field(
        ..., description="parameter grids, as the nightly matrix's tables")
    calibrations: list[_Name] = Field([], description="calibrated mapping files to include")
    twins: list[Twin] = Field([], description="index-matched / dielectric scene pairs")


def study_label(mapping):
    """A calibrated mapping's family name for tables (``calibrated diffusion``; ``calibrated collision form``
    for a file whose scales are a per-cell form, :mod:`sslpv_gl.material_form`; ``calibrated collision radiance
    form`` where only its radiance scale is, Eq. F7 of :mod:`harness.calibration.form`; ``calibrated collision loss
    form`` for one fitted on the render loss, Eq. F8 of :mod:`harness.calibration.form_loss`), else the mapping."""
    m = str(mapping)
    if not m.startswith("calibrated:"):
        return m
    from sslpv_gl.calibrated import load_calibrated
    from sslpv_gl.material import MAPPINGS

    try:
        cal = load_calibrated(m.split(':', 1)[1], tuple(MAPPINGS))
        forms = [b.form for b in cal.budgets if b.form is not None]
        if not forms:
            name = f"calibrated {cal.family}"
        elif cal.fit.get("slopes") in ("loss", "channels"):
            name = f"calibrated {cal.family} {'loss' if cal.fit['slopes'] == 'loss' else 'channel'} form"
        else:
            name = f"calibrated {cal.family}" + (" radiance" if not any(any(f.sigma) for f in forms) else "") + " form"
        return name + _fit_extensions(cal)
    except InputError:
        return "calibrated " + Path(m.split(":", 1)[1]).parent.name


def _fit_extensions(cal):
    """``" (extrapolated, J exitance)"``: the extensions a calibrated file was fitted with beyond its family's own
    settings (:func:`harness.calibration.families.fit_extensions`), so that two calibrations of one family with other
    extensions are two columns; ``""`` where there are none. In parentheses, not joined with `` + ``: a
    calibration stays a column of the headline, not an extension family judged against its base."""
    from harness.calibration.families import fit_extensions
    from harness.study.extensions import extension_tags

    tags = extension_tags(fit_extensions(cal.family, cal.settings))
    return f" ({', '.join(tags)})" if tags else ""


def _calibration_products(files, budget, path):
    """One product per calibration file: its budgets among ``budget``'s, at its fitted settings."""
    from sslpv_gl.calibrated import load_calibrated, resolve_path
    from sslpv_gl.material import MAPPINGS

    out, info = [], []
    for i, name in enumerate(files):
        where = f"calibrations[{i}]"
        p = resolve_path(name)
        if not p.is_file():
            raise InputError(path, where, f"{name!r} does not exist", "give a calibrated.toml written by "
                             "`sslpv-harness calibrate`, e.g. baselines/calibrated/diffusion/calibrated.toml")
        try:
            cal = load_calibrated(name, tuple(MAPPINGS))
        except InputError as exc:
            raise InputError(path, where, f"{name!r} is not a calibrated mapping ({exc.problem})",
                             "give a calibrated.toml written by `sslpv-harness calibrate`") from None
        have = [b.steps for b in cal.budgets if b.N == budget.grid]
        steps = [k for k in budget.steps if k in have]
        if not steps:
            raise InputError(path, where, f"{name!r} has no budget at N={budget.grid} with steps in "
                             f"{budget.steps}", "calibrate it at the study's budget, or change [budget]")
        lists = {"N": [budget.grid], "steps": steps, "mapping": [f"calibrated:{name}"]}
        lists.update({k: [v] for k, v in cal.settings.items()})
        check_products(lists, path, where, keys="field")
        out.append(lists)
        info.append({"file": name, "path": str(p), "sha256": cal.sha256, "family": cal.family,
                     "label": study_label(f"calibrated:{name}"),
                     "report": str(p.with_name("calibration.json")) if p.with_name("calibration.json").is_file()
                     else None})
    return out, info


def load_study(path, size=None):
    """Read and validate a study file -> a dict: ``scenes``, ``params`` (the sweep's products), ``size``,
    ``budget``, ``metrics``, ``significance``, ``calibrations`` (file, path, sha256, family, report),
    ``twins``, ``title``, ``path``, ``text`` and ``sha256`` of the file.

    ``size`` ("small", "own" or ``[W, H]``) overrides the file's (``--size``).
    """
    from harness.runs.sweep import resolve_scenes

    path = Path(path)
    data = read_toml(path, "a study file", "give a study file such as studies/default.toml")
    if isinstance(data, dict):
        check_methods(data.get("products", []), path, "products")
    m = validate(StudyFile, data, path)
    scenes = list_scenes() if m.scenes == "all" else resolve_scenes(m.scenes, where=path, field="scenes")
    products = []
    for i, table in enumerate(m.products):
        where = f"products[{i}]"
        for lists in _split_methods([product_dict(table)], path, where):
            check_products(lists, path, where)
            products.append(lists)
    cal_products, cal_info = _calibration_products(m.calibrations, m.budget, path)
    products += cal_products
    for i, t in enumerate(m.twins):
        for key in ("index_matched", "dielectric"):
            if getattr(t, key) not in scenes:
                raise InputError(path, f"twins[{i}].{key}", f"{getattr(t, key)!r} is not one of the study's scenes",
                                 "name two scenes of `scenes`, or drop the pair")
    if size is not None:
        chosen = None if size == "own" else size
    else:
        chosen = m.size
    text = path.read_text()
    return {"scenes": scenes, "params": products, "size": chosen, "budget": m.budget.model_dump(),
            "metrics": list(m.metrics), "significance": list(m.significance), "calibrations": cal_info,
            "twins": [t.model_dump() for t in m.twins], "title": m.title, "path": str(path), "text": text,
            "sha256": hashlib.sha256(text.encode()).hexdigest()}
