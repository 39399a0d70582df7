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
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field, field_validator, model_validator

from harness.errors import InputError
from harness.validation import FieldProblem, InputModel, validate

__all__ = ["FORMAT", "VERSION", "PREFIX", "SETTINGS", "Budget", "Calibrated", "load_calibrated", "parse_mapping",
           "resolve_path"]

FORMAT = "sslpv-calibrated-mapping"
VERSION = 2
PREFIX = "calibrated:"
#: Renderer settings (``SSLPVParams`` fields) that change the subsurface image and so the
#: fitted scales, with their types: a calibrated file records each, a render must match it.
SETTINGS = {"skip": int, "outside": str, "resample": str, "lookup": str, "inject_size": int,
            "inject_offset": float, "precision": str, "eta2": bool, "phase_scaling": str,
            "boundary_reflect": str}
#: Fitted scales must lie in this range (a wider one means the fit failed).
SCALE_RANGE = (1e-4, 1e4)


@dataclass(frozen=True)
class Budget:
    N: int
    steps: int | str
    sigma_scale: float
    radiance_scale: float
    sigma_scale_se: float | None = None
    radiance_scale_se: float | None = None


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
                                 " with this mapping, or calibrate it again with these settings")

    def budget(self, N, steps, where="--mapping"):
        """The parameter set for ``(N, steps)``, or an InputError listing the budgets there are."""
        for b in self.budgets:
            if b.N == N and b.steps == steps:
                return b
        have = ", ".join(f"N={b.N} steps={b.steps}" for b in self.budgets)
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


class _Budget(InputModel):
    N: Annotated[int, Field(ge=4, le=256, examples=[32])]
    steps: Annotated[int, Field(ge=0, le=1024)] | Literal["steady", "auto"] = Field(examples=[8])
    sigma_scale: _Scale
    radiance_scale: _Scale
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
    budget: Annotated[list[_Budget], Field(min_length=1)]

    @field_validator("version")
    @classmethod
    def _version(cls, v):
        if v != VERSION:
            raise FieldProblem((), f"is {v}; this harness reads version {VERSION}", _FIX)
        return v

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
    budgets = tuple(Budget(N=b.N, steps=b.steps, sigma_scale=float(b.sigma_scale),
                           radiance_scale=float(b.radiance_scale),
                           sigma_scale_se=None if b.sigma_scale_se is None else float(b.sigma_scale_se),
                           radiance_scale_se=None if b.radiance_scale_se is None else float(b.radiance_scale_se))
                    for b in f.budget)
    settings = f.settings.model_dump()
    settings["inject_offset"] = float(settings["inject_offset"])
    return Calibrated(path=path, sha256=sha, family=f.family, budgets=budgets, fit=f.fit, settings=settings)
