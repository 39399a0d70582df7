"""Every parameter of the GL SSLPV renderer, with its default, in one place.

:class:`SSLPVParams` is a frozen dataclass; each field carries a one-line
description (``SSLPVParams.doc(name)``) that the command line shows as help.
Values are validated on construction: a bad value raises
:class:`harness.errors.InputError` with one line naming the parameter and the
allowed values.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from harness.errors import InputError

from .material import MAPPINGS, RESAMPLERS

__all__ = ["SSLPVParams", "LOOKUPS", "PRECISIONS", "OUTSIDE"]

LOOKUPS = ("cell", "trilinear")
PRECISIONS = ("fp32", "fp16")
OUTSIDE = ("vacuum", "material")


def _p(default, doc):
    return field(default=default, metadata={"doc": doc})


@dataclass(frozen=True)
class SSLPVParams:
    """Renderer settings (Borlum et al. 2011; paper defaults where it states them)."""

    N: int = _p(32, "LPV grid resolution per axis (paper: 32^3), in [4, 256]")
    steps: int = _p(32, "propagation steps K (paper: 8 or 32), in [0, 1024]")
    mapping: str = _p("collision", "physical (sigma_t, albedo) -> LPV (sigma_lpv, sigma_s') mapping")
    resample: str = _p("box", "medium grid -> LPV grid resampling: box average or point (trilinear)")
    outside: str = _p("vacuum", "LPV cells outside the mesh: vacuum (no attenuation/scattering) or material")
    lookup: str = _p("cell", "shading lookup of the accumulation grid: cell (texelFetch) or trilinear")
    skip: int = _p(2, "first propagation steps not accumulated (paper Sec. 4: 2), in [0, steps]")
    rsm_size: int = _p(1024, "shadow-map resolution per light for direct-light visibility (paper: 1024^2)")
    inject_size: int = _p(256, "injection RSM resolution per light (paper: 256^2 texels used for injection)")
    inject_offset: float = _p(0.0, "move injected point lights this far inwards along -n (scene units; 0 = paper)")
    precision: str = _p("fp32", "storage of the SH grids: fp32 or fp16 (paper: 16-bit floats)")
    eta2: bool = _p(False, "divide outgoing radiance by eta^2 (radiance compression leaving a medium of index "
                           "eta; not in the paper's Eq. 4)")

    def __post_init__(self):
        def bad(name, problem, fix):
            flag = "--grid" if name == "N" else "--" + name.replace("_", "-")   # the CLI's names
            raise InputError(flag, name, problem, fix)

        def integer(name, lo, hi):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
                bad(name, f"must be an integer in [{lo}, {hi}], got {v!r}", "change the value")

        def choice(name, allowed):
            v = getattr(self, name)
            if v not in allowed:
                bad(name, f"unknown {name} {v!r}", "use one of: " + ", ".join(allowed))

        integer("N", 4, 256)
        integer("steps", 0, 1024)
        integer("skip", 0, 1024)
        integer("rsm_size", 16, 8192)
        integer("inject_size", 4, 4096)
        choice("mapping", tuple(MAPPINGS))
        choice("resample", tuple(RESAMPLERS))
        choice("outside", OUTSIDE)
        choice("lookup", LOOKUPS)
        choice("precision", PRECISIONS)
        off = self.inject_offset
        if isinstance(off, bool) or not isinstance(off, (int, float)) or not off == off or abs(off) == float("inf"):
            bad("inject_offset", f"must be a finite number, got {off!r}", "change the value")
        if not isinstance(self.eta2, bool):
            bad("eta2", f"must be true or false, got {self.eta2!r}", "change the value")
        if self.skip > self.steps:
            bad("skip", f"skip {self.skip} must not exceed steps {self.steps} (nothing would be accumulated)",
                "lower --skip")

    @staticmethod
    def doc(name):
        """The one-line description of a field."""
        return {f.name: f.metadata["doc"] for f in dataclasses.fields(SSLPVParams)}[name]

    def as_dict(self):
        return dataclasses.asdict(self)

    def replace(self, **changes):
        return dataclasses.replace(self, **changes)
