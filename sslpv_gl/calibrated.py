"""Calibrated mappings: a mapping family with fitted free parameters, one set per budget.

``sslpv-harness calibrate`` (``harness.calibration``) fits, for a mapping family
(``diffusion`` or ``collision``), a global radiance scale and a scale on
``sigma_lpv`` against the references, once per real-time budget ``(N, steps)``.
It writes a TOML file that ``--mapping calibrated:PATH`` reads here::

    format = "sslpv-calibrated-mapping"
    version = 2
    family = "diffusion"                 # a key of sslpv_gl.material.MAPPINGS
    [settings]                            # the renderer settings the fit was made with
    skip = 0                              # (every key of SETTINGS; a render must use the same)
    outside = "vacuum"
    resample = "box"
    lookup = "cell"
    inject_size = 256
    inject_offset = 0.0
    precision = "fp32"
    eta2 = false
    phase_scaling = "none"                # optional: "none" when left out
    boundary_reflect = "none"             # optional: "none" when left out
    [fit]                                 # how it was fitted (free-form provenance)
    loss = "mean over scenes of log relMSE(subsurface)"
    [[budget]]
    N = 32
    steps = 8                             # an integer, or "steady"
    sigma_scale = 1.7                     # multiplies sigma_lpv of the family
    radiance_scale = 0.9                  # multiplies the subsurface radiance
    sigma_scale_se = 0.05                 # optional: standard errors from the
    radiance_scale_se = 0.01              # reference's two halves

Version 3 (a calibration that depends on the material, :mod:`sslpv_gl.material_form`) has a
``[form]`` table naming the terms of Eq. (F1) there, and each budget gives, in place of the
two scales, the coefficients ``[const, term 1, term 2, ...]`` of ``ln s`` and ``ln r``::

    version = 3
    [form]
    terms = ["ln_sigma_tr_dx", "ln_absorption", "g", "ln_eta", "ln_extent_per_step"]
    [[budget]]
    N = 32
    steps = 8
    sigma_form = [0.5, -0.3, 0.1, 0.0, 0.0, 0.2]        # ln s = a0 + a1 x1 + ...
    radiance_form = [-0.2, 0.0, 0.4, 0.0, 0.0, 0.1]     # ln r = b0 + b1 x1 + ...

``exp(a0)`` and ``exp(b0)`` act as a version 2 budget's scales; the other terms are per-cell
factors (:class:`~sslpv_gl.material_form.Form`). An unknown term, a coefficient that is not
finite, a list of the wrong length, and ``ln_extent_per_step`` at ``steps = "steady"`` are
refused in one line. Version 2 files load as before.

A render at ``(N, steps)`` uses the budget with exactly that ``N`` and ``steps``;
there is no silent nearest-budget fallback. The fitted scales hold only for the
renderer settings they were fitted with (``[settings]``, :data:`SETTINGS`): a render
with another ``skip``, ``outside`` and so on is refused (:meth:`Calibrated.check_settings`),
never silently given scales fitted for something else. Version 1 files, which had no
``[settings]``, are refused with the fix. The file is a typed model
(:class:`harness.validation.InputModel`): an unknown key, a wrong type or an out-of-range
value is one line naming the file and the field. Every defect of the file is an
:class:`~harness.errors.InputError` naming the file, the field and the fix.
"""

from __future__ import annotations

import functools
import hashlib
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field, field_validator, model_validator

from harness.errors import InputError
from harness.validation import FieldProblem, InputModel, validate

from .material_form import CONST, TERMS, Form

__all__ = ["FORMAT", "VERSION", "FORM_VERSION", "VERSIONS", "PREFIX", "SETTINGS", "Budget", "Calibrated", "load_calibrated", "parse_mapping",
           "resolve_path"]

FORMAT = "sslpv-calibrated-mapping"
VERSION = 2
#: The version with a per-cell form (sslpv_gl.material_form); VERSIONS are the ones read.
FORM_VERSION = 3
VERSIONS = (VERSION, FORM_VERSION)
PREFIX = "calibrated:"
#: Renderer settings (``SSLPVParams`` fields) that change the subsurface image and so the
#: fitted scales, with their types: a calibrated file records each, a render must match it.
SETTINGS = {"skip": int, "outside": str, "resample": str, "lookup": str, "inject_size": int,
            "inject_offset": float, "precision": str, "eta2": bool, "phase_scaling": str,
            "boundary_reflect": str, "exitance": str, "inject_depth": float, "shade_depth": float}
#: Fitted scales must lie in this range (a wider one means the fit failed).
SCALE_RANGE = (1e-4, 1e4)
#: A version 3 form's constants: |a0|, |b0| at most this. They are the scales at all terms 0, which no
#: cell need have (a scene's scales are exp(a0 + a . x), and mean terms of -5 with slopes of 10 are
#: ordinary), so SCALE_RANGE does not bound them; this keeps exp(a0) and its products with the
#: per-cell factors normal float64 numbers (exp(300) ~ 1e130).
CONST_LIMIT = 300.0


@dataclass(frozen=True)
class Budget:
    N: int
    steps: int | str
    sigma_scale: float
    radiance_scale: float
    sigma_scale_se: float | None = None
    radiance_scale_se: float | None = None
    form: Form | None = None         # version 3: the per-cell part; None when it is constant


@dataclass(frozen=True)
class Calibrated:
    path: str
    sha256: str
    family: str
    budgets: tuple
    fit: dict
    settings: dict

    def check_settings(self, params):
        """InputError naming the first of ``params``' settings that differs from the fitted ones."""
        for name in SETTINGS:
            have, want = getattr(params, name), self.settings[name]
            if have != want:
                flag = "--" + name.replace("_", "-")
                raise InputError(flag, name, f"{self.path} was calibrated with {name}={want!r}, this render has "
                                 f"{name}={have!r}", f"pass {flag} {str(want).lower() if isinstance(want, bool) else want}"
                                 f" with this mapping (or leave {flag} out: the file's value is then used), or "
                                 "calibrate it again with these settings")

    def budget(self, N, steps, where="--mapping"):
        """The parameter set for ``(N, steps)``, or an InputError listing the budgets there are (naming
        ``--grid`` when the file was fitted for other grids only)."""
        for b in self.budgets:
            if b.N == N and b.steps == steps:
                return b
        have = ", ".join(f"N={b.N} steps={b.steps}" for b in self.budgets)
        grids = sorted({b.N for b in self.budgets})
        if N not in grids:
            raise InputError("--grid", "N", f"{self.path} was fitted for N={', '.join(map(str, grids))}, this render "
                             f"has N={N} (no parameter set for N={N} steps={steps}; it has {have})",
                             f"render with --grid {' or '.join(map(str, grids))}, or calibrate at N={N}")
        raise InputError(where, "mapping", f"{self.path} has no parameter set for N={N} steps={steps}",
                         f"render at one of its budgets ({have}) or calibrate this one")


def parse_mapping(mapping):
    """``"calibrated:PATH"`` -> PATH (a str); None for a plain family name."""
    if isinstance(mapping, str) and mapping.startswith(PREFIX):
        return mapping[len(PREFIX):]
    return None


#: The repository this module sits in: relative calibrated paths not found from the current
#: folder are looked up here, so the committed mappings (``baselines/calibrated/``) keep one
#: portable name in matrices, configuration labels and baselines on every checkout.
_REPO = Path(__file__).resolve().parent.parent


def resolve_path(path):
    """A calibrated mapping's path: as given when absolute or present from the current folder, else
    relative to the repository (where the committed mappings are); unchanged when neither exists."""
    p = Path(path)
    if p.is_absolute() or p.exists():
        return p
    in_repo = _REPO / p
    return in_repo if in_repo.exists() else p


def load_calibrated(path, families):
    """Read and validate a calibrated mapping file -> :class:`Calibrated` (cached by path and content)."""
    p = resolve_path(path)
    if not p.is_file():
        raise InputError(p, "file", "does not exist" if not p.exists() else "is not a file",
                         "give a file written by `sslpv-harness calibrate`")
    data = p.read_bytes()
    return _parse(str(p), data, tuple(families))


# ------------------------------------------------------------------ the file's typed model

_FIX = "write it again with `sslpv-harness calibrate`"
_Scale = Annotated[float, Field(ge=SCALE_RANGE[0], le=SCALE_RANGE[1], examples=[1.0])]
_SE = Annotated[float, Field(ge=0.0, examples=[0.01])]


class _Settings(InputModel):
    skip: Annotated[int, Field(ge=0, le=1024, examples=[0])]
    outside: Annotated[str, Field(examples=["vacuum"])]
    resample: Annotated[str, Field(examples=["box"])]
    lookup: Annotated[str, Field(examples=["cell"])]
    inject_size: Annotated[int, Field(ge=4, le=4096, examples=[256])]
    inject_offset: Annotated[float, Field(examples=[0.0])]
    precision: Annotated[str, Field(examples=["fp32"])]
    eta2: Annotated[bool, Field(examples=[False])]
    phase_scaling: Annotated[str, Field(examples=["none"])] = "none"     # files that predate it: the paper's
    boundary_reflect: Annotated[str, Field(examples=["none"])] = "none"  # files that predate it: the paper's
    exitance: Annotated[str, Field(examples=["isotropic"])] = "isotropic"  # files that predate it: Eq. (21)'s
    inject_depth: Annotated[float, Field(ge=0.0, le=16.0, examples=[0.0])] = 0.0   # files that predate it: the paper's
    shade_depth: Annotated[float, Field(ge=0.0, le=4.0, examples=[0.0])] = 0.0     # files that predate it: the paper's


_Coef = Annotated[float, Field(examples=[0.0])]        # finite (InputModel refuses NaN and infinities)


class _Form(InputModel):
    terms: Annotated[list[str], Field(max_length=len(TERMS), examples=[list(TERMS)])]

    @field_validator("terms")
    @classmethod
    def _terms(cls, v):
        for i, t in enumerate(v):
            if t not in TERMS:
                raise FieldProblem((i,), f"{t!r} is not a term of the form", f"use some of: {', '.join(TERMS)}")
        if len(set(v)) != len(v):
            raise FieldProblem((), "a term appears twice", "list each term once")
        return v


class _Budget(InputModel):
    N: Annotated[int, Field(ge=4, le=256, examples=[32])]
    steps: Annotated[int, Field(ge=0, le=1024)] | Literal["steady", "auto"] = Field(examples=[8])
    sigma_scale: _Scale | None = None           # version 2
    radiance_scale: _Scale | None = None        # version 2
    sigma_form: list[_Coef] | None = None       # version 3: [const, *form.terms]
    radiance_form: list[_Coef] | None = None    # version 3
    sigma_scale_se: _SE | None = None
    radiance_scale_se: _SE | None = None
    loss: float | None = None
    loss_held_out: float | None = None


class _File(InputModel):
    format: Literal[FORMAT]
    version: Annotated[int, Field(examples=[VERSION])]
    family: Annotated[str, Field(examples=["diffusion"])]
    settings: _Settings
    fit: dict = Field(default_factory=dict)
    form: _Form | None = None
    budget: Annotated[list[_Budget], Field(min_length=1)]

    @field_validator("version")
    @classmethod
    def _version(cls, v):
        if v not in VERSIONS:
            raise FieldProblem((), f"is {v}; this harness reads versions {' and '.join(map(str, VERSIONS))}", _FIX)
        return v

    @model_validator(mode="after")
    def _per_version(self):
        """Version 2: two scales per budget, no form; version 3: a [form] and two coefficient lists per budget."""
        form = self.version == FORM_VERSION
        if form and self.form is None:
            raise FieldProblem(("form",), "is missing (version 3 has a per-cell form)",
                               'add [form] with terms = [...], or write version = 2')
        if not form and self.form is not None:
            raise FieldProblem(("form",), "is not part of version 2", "write version = 3, or remove [form]")
        for i, b in enumerate(self.budget):
            need, other = (("sigma_form", "radiance_form"), ("sigma_scale", "radiance_scale")) if form else \
                (("sigma_scale", "radiance_scale"), ("sigma_form", "radiance_form"))
            for name in need:
                if getattr(b, name) is None:
                    raise FieldProblem(("budget", i, name), f"is missing (version {self.version})", _FIX)
            for name in other:
                if getattr(b, name) is not None:
                    raise FieldProblem(("budget", i, name), f"is not part of version {self.version}",
                                       f"use {' and '.join(need)}")
            if not form:
                continue
            n = 1 + len(self.form.terms)
            for name in need:
                coeffs = getattr(b, name)
                if len(coeffs) != n:
                    raise FieldProblem(("budget", i, name), f"has {len(coeffs)} coefficients, the form has {n} "
                                       f"([{CONST}, {', '.join(self.form.terms)}])", "give one per term")
                if abs(coeffs[0]) > CONST_LIMIT:
                    raise FieldProblem(("budget", i, name, 0), f"{coeffs[0]:g} is outside [-{CONST_LIMIT:g}, "
                                       f"{CONST_LIMIT:g}]", _FIX)
                if not isinstance(b.steps, int) and "ln_extent_per_step" in self.form.terms and \
                        coeffs[1 + self.form.terms.index("ln_extent_per_step")] != 0.0:
                    raise FieldProblem(("budget", i, name), f"uses ln_extent_per_step, which steps = {b.steps} does "
                                       "not define (no step count K)", "set its coefficient to 0 for this budget")
        return self

    @field_validator("family")
    @classmethod
    def _family(cls, v, info):
        families = (info.context or {}).get("families", ())
        if v not in families:
            raise FieldProblem((), f"{v!r} is not a mapping family of this harness",
                               f"use one of: {', '.join(families)}; {_FIX}")
        return v

    @model_validator(mode="after")
    def _unique(self):
        seen = set()
        for i, b in enumerate(self.budget):
            if (b.N, b.steps) in seen:
                raise FieldProblem(("budget", i), f"budget N={b.N} steps={b.steps} appears twice", _FIX)
            seen.add((b.N, b.steps))
        return self


@functools.lru_cache(maxsize=32)
def _parse(path, data, families):
    sha = hashlib.sha256(data).hexdigest()
    try:
        doc = tomllib.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise InputError(path, "toml", f"is not valid UTF-8 TOML ({str(exc).splitlines()[0]})", _FIX) from None
    f = validate(_File, doc, path, context={"families": families})
    budgets = tuple(_budget(b, f.form) for b in f.budget)
    settings = f.settings.model_dump()
    settings["inject_offset"] = float(settings["inject_offset"])
    settings["inject_depth"] = float(settings["inject_depth"])
    settings["shade_depth"] = float(settings["shade_depth"])
    return Calibrated(path=path, sha256=sha, family=f.family, budgets=budgets, fit=f.fit, settings=settings)


def _budget(b, form):
    """A :class:`Budget` from the file's model: version 3's constants become the scales (so that a constant
    form is the version 2 budget, bit for bit) and its other coefficients the per-cell :class:`Form`."""
    se = {"sigma_scale_se": None if b.sigma_scale_se is None else float(b.sigma_scale_se),
          "radiance_scale_se": None if b.radiance_scale_se is None else float(b.radiance_scale_se)}
    if form is None:
        return Budget(N=b.N, steps=b.steps, sigma_scale=float(b.sigma_scale), radiance_scale=float(b.radiance_scale),
                      **se)
    sig, rad = [float(c) for c in b.sigma_form], [float(c) for c in b.radiance_form]
    per_cell = None
    if any(c != 0.0 for c in sig[1:] + rad[1:]):
        per_cell = Form(terms=tuple(form.terms), sigma=tuple(sig[1:]), radiance=tuple(rad[1:]), steps=b.steps)
    return Budget(N=b.N, steps=b.steps, sigma_scale=math.exp(sig[0]), radiance_scale=math.exp(rad[0]), form=per_cell,
                  **se)
