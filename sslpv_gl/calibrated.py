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
``[settings]``, are refused with the fix. Every defect of the file is an
:class:`~harness.errors.InputError` naming the file, the field and the fix.
"""

from __future__ import annotations

import functools
import hashlib
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

from harness.errors import InputError

__all__ = ["FORMAT", "VERSION", "PREFIX", "SETTINGS", "Budget", "Calibrated", "load_calibrated", "parse_mapping",
           "resolve_path"]

FORMAT = "sslpv-calibrated-mapping"
VERSION = 2
PREFIX = "calibrated:"
#: Renderer settings (``SSLPVParams`` fields) that change the subsurface image and so the
#: fitted scales, with their types: a calibrated file records each, a render must match it.
SETTINGS = {"skip": int, "outside": str, "resample": str, "lookup": str, "inject_size": int,
            "inject_offset": float, "precision": str, "eta2": bool}
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


@functools.lru_cache(maxsize=32)
def _parse(path, data, families):
    sha = hashlib.sha256(data).hexdigest()
    fix = "write it again with `sslpv-harness calibrate`"
    try:
        doc = tomllib.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise InputError(path, "toml", f"is not valid UTF-8 TOML ({str(exc).splitlines()[0]})", fix) from None
    if doc.get("format") != FORMAT:
        raise InputError(path, "format", f"is {doc.get('format')!r}, not {FORMAT!r}", fix)
    if doc.get("version") != VERSION:
        raise InputError(path, "version", f"is {doc.get('version')!r}; this harness reads version {VERSION}", fix)
    family = doc.get("family")
    if family not in families:
        raise InputError(path, "family", f"{family!r} is not a mapping family of this harness",
                         f"use one of: {', '.join(families)}; {fix}")
    unknown = set(doc) - {"format", "version", "family", "fit", "budget", "settings"}
    if unknown:
        raise InputError(path, sorted(unknown)[0], "is not a field of a calibrated mapping", fix)
    raw = doc.get("budget")
    if not isinstance(raw, list) or not raw:
        raise InputError(path, "budget", "has no [[budget]] table", fix)
    budgets, seen = [], set()
    for i, b in enumerate(raw):
        where = f"budget[{i}]"
        if not isinstance(b, dict):
            raise InputError(path, where, "is not a table", fix)
        extra = set(b) - {"N", "steps", "sigma_scale", "radiance_scale", "sigma_scale_se", "radiance_scale_se",
                          "loss", "loss_held_out"}
        if extra:
            raise InputError(path, f"{where}.{sorted(extra)[0]}", "is not a field of a budget", fix)
        N, steps = b.get("N"), b.get("steps")
        if isinstance(N, bool) or not isinstance(N, int) or not 4 <= N <= 256:
            raise InputError(path, f"{where}.N", f"is {N!r}; must be an integer in [4, 256]", fix)
        if not ((isinstance(steps, int) and not isinstance(steps, bool) and 0 <= steps <= 1024)
                or steps in ("steady", "auto")):
            raise InputError(path, f"{where}.steps", f"is {steps!r}; must be an integer in [0, 1024], "
                             "'auto' or 'steady'", fix)
        vals = {}
        for name in ("sigma_scale", "radiance_scale"):
            v = b.get(name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                    or not SCALE_RANGE[0] <= v <= SCALE_RANGE[1]:
                raise InputError(path, f"{where}.{name}", f"is {v!r}; must be a number in "
                                 f"[{SCALE_RANGE[0]:g}, {SCALE_RANGE[1]:g}]", fix)
            vals[name] = float(v)
        for name in ("sigma_scale_se", "radiance_scale_se"):
            v = b.get(name)
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not v >= 0):
                raise InputError(path, f"{where}.{name}", f"is {v!r}; must be a number >= 0", fix)
            vals[name] = None if v is None else float(v)
        if (N, steps) in seen:
            raise InputError(path, where, f"budget N={N} steps={steps} appears twice", fix)
        seen.add((N, steps))
        budgets.append(Budget(N=N, steps=steps, **vals))
    fit = doc.get("fit", {})
    if not isinstance(fit, dict):
        raise InputError(path, "fit", "is not a table", fix)
    return Calibrated(path=path, sha256=sha, family=family, budgets=tuple(budgets), fit=fit,
                      settings=_settings(path, doc.get("settings"), fix))


def _settings(path, raw, fix):
    """The ``[settings]`` table: every key of :data:`SETTINGS`, each of its type."""
    if not isinstance(raw, dict):
        raise InputError(path, "settings", "is missing or not a table", fix)
    extra = set(raw) - set(SETTINGS)
    if extra:
        raise InputError(path, f"settings.{sorted(extra)[0]}", "is not a renderer setting of a calibration", fix)
    out = {}
    for name, kind in SETTINGS.items():
        if name not in raw:
            raise InputError(path, f"settings.{name}", "is missing", fix)
        v = raw[name]
        ok = isinstance(v, bool) if kind is bool else (
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) if kind is float else
            isinstance(v, kind) and not isinstance(v, bool))
        if not ok:
            raise InputError(path, f"settings.{name}", f"is {v!r}; must be a{'n' if kind is int else ''} "
                             f"{kind.__name__}", fix)
        out[name] = float(v) if kind is float else v
    return out
