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

from .boundary import OUTSIDE_MODES
from .calibrated import load_calibrated, parse_mapping
from .material import MAPPINGS, PHASE_SCALINGS, RESAMPLERS, check_exitance, check_transport_outside
from .reflect import BOUNDARY_REFLECTS, check

__all__ = ["SSLPVParams", "Resolved", "LOOKUPS", "PRECISIONS", "OUTSIDE", "STEP_MODES", "PAPER_SETTINGS",
           "EXTENSION_MAPPINGS"]

LOOKUPS = ("cell", "trilinear")
PRECISIONS = ("fp32", "fp16")
OUTSIDE = OUTSIDE_MODES
#: The settings whose other values are extensions (options the paper does not have), with the paper's value of each.
#: The paper shades from "the point light intensities of the boundary grid cells" (Sec. 3.3): a cell's own
#: coefficients, ``lookup = "cell"``; the trilinear read between cell centres is an extension.
PAPER_SETTINGS = {"outside": "vacuum", "boundary_reflect": "none", "phase_scaling": "none", "eta2": False,
                  "inject_offset": 0.0, "inject_depth": 0.0, "exitance": "isotropic", "shade_depth": 0.0,
                  "lookup": "cell"}
#: Mappings that are themselves extensions, and the published mapping each is judged against.
EXTENSION_MAPPINGS = {"transport": "collision"}
#: ``steps`` values other than a count: propagate to convergence, or solve the steady state.
STEP_MODES = ("auto", "steady")


@dataclass(frozen=True)
class Resolved:
    """What a render actually uses once ``mapping = "calibrated:PATH"`` is looked up."""

    family: str                      # a key of MAPPINGS
    sigma_scale: float
    radiance_scale: float
    calibration: dict | None = None  # {"path", "sha256", "N", "steps"} for a calibrated mapping
    form: object = None              # a version 3 file's per-cell part (sslpv_gl.material_form.Form)


def _p(default, doc):
    return field(default=default, metadata={"doc": doc})


@dataclass(frozen=True)
class SSLPVParams:
    """Renderer settings (Borlum et al. 2011; paper defaults where it states them)."""

    N: int = _p(32, "LPV grid resolution per axis (paper: 32^3), in [4, 256]; odd sizes too (the dispatch "
                    "rounds up and every shader stops at the grid's edge)")
    steps: int | str = _p(32, "propagation steps K (paper: 8 or 32), in [0, 1024]; 'auto': until the grid holds "
                              "less than converge_tol of the injected flux; 'steady': the converged sum, solved "
                              "directly (sslpv_gl.steady)")
    mapping: str = _p("collision", "physical (sigma_t, albedo) -> LPV (sigma_lpv, sigma_s') mapping: literal, "
                                   "collision, diffusion, transport (an extension: one step is one cell of path; "
                                   "outside absorb or interior), or calibrated:PATH (a file of sslpv-harness "
                                   "calibrate)")
    resample: str = _p("box", "medium grid -> LPV grid resampling: box average or point (trilinear)")
    outside: str = _p("vacuum", "LPV cells outside the mesh: vacuum (the paper), material, absorb, extrapolated "
                                  "or interior (no light moves between two outside cells; sslpv_gl.boundary)")
    phase_scaling: str = _p("none", "forward-peaked media: none (the paper) or delta-eddington (the forward peak "
                                    "f = g^2 treated as unscattered; sslpv_gl.material)")
    boundary_reflect: str = _p("none", "dielectric boundary: none (the paper: all light reaching the surface "
                                       "from inside leaves) or rdr (R_dr(eta) of it returns into the medium, "
                                       "mirrored; sslpv_gl.reflect); outside vacuum, absorb or interior")
    exitance: str = _p("isotropic", "how the shading reads a diffusion-mapped cell: isotropic (its fluence's "
                                    "isotropic part, Eq. (21)) or boundary (diffusion theory's exitance at the "
                                    "extrapolated boundary, J = phi / (2 A); diffusion with outside extrapolated "
                                    "only; sslpv_gl.bounded Eq. (D5))")
    lookup: str = _p("cell", "shading lookup of the accumulation grid: cell (texelFetch) or trilinear")
    shade_depth: float = _p(0.0, "read the accumulation grid this many cells inwards of the shaded point along -n "
                                 "(an extension: 0 = the paper, the point's own cell; sslpv_gl.shade Eq. (S1)), "
                                 "in [0, 4]")
    skip: int = _p(2, "first propagation steps not accumulated (paper Sec. 4: 2), in [0, steps]")
    rsm_size: int = _p(1024, "shadow-map resolution per light for direct-light visibility (paper: 1024^2)")
    inject_size: int = _p(256, "injection RSM resolution per light (paper: 256^2 texels used for injection)")
    inject_offset: float = _p(0.0, "move injected point lights this far inwards along -n (scene units; 0 = paper)")
    inject_depth: float = _p(0.0, "move each injected point light this many reduced mean free paths inwards along -n, "
                                  "1 / sigma_t' of the medium in its cell (mean over colours); adds to inject_offset "
                                  "(an extension: 0 = paper), in [0, 16]")
    precision: str = _p("fp32", "storage of the SH grids: fp32 or fp16 (paper: 16-bit floats)")
    eta2: bool = _p(False, "divide outgoing radiance by eta^2 (radiance compression leaving a medium of index "
                           "eta; not in the paper's Eq. 4)")
    sigma_scale: float = _p(1.0, "multiplies the mapping's sigma_lpv (a calibration parameter), in (0, 1e4]")
    radiance_scale: float = _p(1.0, "multiplies the subsurface radiance (a calibration parameter), in (0, 1e4]")
    converge_tol: float = _p(1e-3, "steps=auto: stop when the propagation grid holds less than this fraction of "
                                   "the injected flux, in (0, 1)")
    max_steps: int = _p(4096, "steps=auto: at most this many steps, in [1, 65536]")

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
        st = self.steps
        if st not in STEP_MODES and (isinstance(st, bool) or not isinstance(st, int) or not 0 <= st <= 1024):
            bad("steps", f"must be an integer in [0, 1024], 'auto' or 'steady', got {st!r}", "change the value")
        integer("skip", 0, 1024)
        integer("rsm_size", 16, 8192)
        integer("inject_size", 4, 4096)
        integer("max_steps", 1, 65536)
        if parse_mapping(self.mapping) is None:
            choice("mapping", tuple(MAPPINGS) + ("calibrated:PATH",))
        choice("resample", tuple(RESAMPLERS))
        choice("outside", OUTSIDE)
        check_transport_outside(self.mapping, self.outside)
        choice("phase_scaling", PHASE_SCALINGS)
        choice("boundary_reflect", BOUNDARY_REFLECTS)
        check(self.boundary_reflect, self.outside)
        choice("lookup", LOOKUPS)
        choice("precision", PRECISIONS)
        off = self.inject_offset
        if isinstance(off, bool) or not isinstance(off, (int, float)) or not off == off or abs(off) == float("inf"):
            bad("inject_offset", f"must be a finite number, got {off!r}", "change the value")
        dep = self.inject_depth
        if isinstance(dep, bool) or not isinstance(dep, (int, float)) or not 0.0 <= dep <= 16.0:
            bad("inject_depth", f"must be a number in [0, 16] (reduced mean free paths), got {dep!r}",
                "change the value")
        sd = self.shade_depth
        if isinstance(sd, bool) or not isinstance(sd, (int, float)) or not 0.0 <= sd <= 4.0:
            bad("shade_depth", f"must be a number in [0, 4] (cells), got {sd!r}", "change the value")
        for name, lo, hi in (("sigma_scale", 0.0, 1e4), ("radiance_scale", 0.0, 1e4), ("converge_tol", 0.0, 1.0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not lo < v <= hi or (name == "converge_tol"
                                                                                               and v >= 1.0):
                bad(name, f"must be a number in ({lo:g}, {hi:g}{')' if name == 'converge_tol' else ']'}, got {v!r}",
                    "change the value")
        family = self.mapping
        if parse_mapping(self.mapping) is not None:
            if self.sigma_scale != 1.0 or self.radiance_scale != 1.0:
                bad("mapping", "a calibrated mapping brings its own sigma_scale and radiance_scale",
                    "leave --sigma-scale and --radiance-scale at 1 with calibrated:PATH")
            family = self.resolved().family          # the file, its budget and settings are checked now
        check_exitance(family, self.outside, self.exitance)
        if not isinstance(self.eta2, bool):
            bad("eta2", f"must be true or false, got {self.eta2!r}", "change the value")
        if isinstance(self.steps, int) and self.skip > self.steps:
            # Name the setting the user changed: --steps when --skip is at its default.
            if self.skip == SSLPVParams.skip:
                bad("steps", f"{self.steps} is fewer than the {self.skip} steps that --skip leaves out by default "
                    "(nothing would be accumulated)", f"give --steps {self.skip} or more, or lower --skip")
            bad("skip", f"skip {self.skip} must not exceed steps {self.steps} (nothing would be accumulated)",
                "lower --skip")

    @classmethod
    def given(cls, **fields):
        """The parameters of a command, a sweep's product or a study: ``fields`` are the settings given
        explicitly, and for ``mapping = "calibrated:PATH"`` every renderer setting the file was fitted with
        (its ``[settings]``, :data:`sslpv_gl.calibrated.SETTINGS`) that ``fields`` does not give is the
        file's, so ``--mapping calibrated:PATH`` alone renders with the calibration's outside treatment,
        phase scaling, boundary reflection and the rest. A setting given explicitly that differs from the
        file's is refused in one line by the constructor (:meth:`Calibrated.check_settings`), as before;
        a plain mapping takes the defaults of this class for what is not given."""
        path = parse_mapping(fields.get("mapping"))
        if path is not None:
            from .calibrated import SETTINGS

            cal = load_calibrated(path, tuple(MAPPINGS))
            fields = {**{k: cal.settings[k] for k in SETTINGS if k not in fields}, **fields}
        return cls(**fields)

    @staticmethod
    def doc(name):
        """The one-line description of a field."""
        return {f.name: f.metadata["doc"] for f in dataclasses.fields(SSLPVParams)}[name]

    def resolved(self):
        """:class:`Resolved`: the mapping family and scales this render uses.

        For ``mapping = "calibrated:PATH"`` they come from the file's budget for
        ``(N, steps)`` (an :class:`~harness.errors.InputError` if the file is bad or has
        no such budget); otherwise they are this object's own fields.
        """
        path = parse_mapping(self.mapping)
        if path is None:
            return Resolved(self.mapping, float(self.sigma_scale), float(self.radiance_scale))
        cal = load_calibrated(path, tuple(MAPPINGS))
        cal.check_settings(self)
        b = cal.budget(self.N, self.steps)
        return Resolved(cal.family, b.sigma_scale, b.radiance_scale,
                        {"path": cal.path, "sha256": cal.sha256, "N": b.N, "steps": b.steps}, b.form)

    def as_dict(self):
        return dataclasses.asdict(self)

    def replace(self, **changes):
        return dataclasses.replace(self, **changes)
