"""Every parameter of the dipole rivals, with its default, in one place.

:class:`DipoleParams` is a frozen dataclass; each field carries a one-line description
(``DipoleParams.doc(name)``, the command line's help). A parameter that belongs to one
gather only is ``None`` for the other (``as_dict()`` leaves it out), so a configuration
never carries a setting that does nothing. Bad values raise
:class:`harness.errors.InputError` with one line naming the command-line flag.

=================  =========  ==========================================================
field              gather     meaning
=================  =========  ==========================================================
``gather``         all        ``dense`` (whole surface), ``vertex`` (Hao & Varshney) or
                              ``cubemap`` (the thesis draft's real-time directional dipole) or
                              ``hierarchical`` (Jensen & Buhler's octree) or ``atlas``
                              (Carr, Hall & Hart's links into a MIP-mapped atlas)
``spacing``        dense,     surface sample spacing, in reduced mean free paths
                   hierarch.  ``l' = 1/sigma_t'`` (default 1)
``epsilon``        hierarch.  the octree's solid-angle bound: a node subtending less than
                              ``epsilon`` sr is used whole (default :data:`DEFAULT_EPSILON`)
``atlas_size``     atlas      texels per side of the atlas, a power of two (default 128)
``links``          atlas      adaptive scheme: links per texel (default 16, the paper's)
``link_level``     atlas      non-adaptive scheme: every texel linked to every node of this
                              MIP level (default: none, the adaptive scheme)
``adaptive``       atlas      ``true`` (the default when ``link_level`` is not given) or
                              ``false`` (requires ``link_level``)
``range``          vertex     neighbourhood radius, in diffusion lengths ``1/sigma_tr``
                              (default 4)
``density``        vertex     scattering vertices per ``l'^2`` (default 1)
``cube_size``      cubemap    texels per cube-face side (default 64)
``light_size``     cubemap    light-buffer texels per side, per light (default 256)
``samples``        cubemap    disc samples per face texel, light and frame (default 32)
``frames``         cubemap    disc rotations accumulated while static (default 8)
``disc_radius``    cubemap    the disc's world radius, in diffusion lengths (default 4)
``eps_g``          cubemap    G-buffer fix, light-buffer texels (default 0.75)
``eps_c``          cubemap    cubemap fix, cube texels (default 0.75)
``eps_b``          cubemap    depth bias, cube texels (default 2.5)
``shadow_size``    all        shadow-map resolution per light (default 1024)
``fit``            all        ``refuse`` (default) or ``coarsen``: a setting over the
                              gather's budget is refused, or coarsened just enough
                              (:mod:`dipole_gl.sizing`)
``terms``          both       ``both`` (default: Jensen et al. 2001's ``S_d + S^(1)``),
                              ``diffusion`` (the kernel alone) or ``single`` (``S^(1)``
                              alone, :mod:`dipole_gl.single`)
=================  =========  ==========================================================

``l'`` is the smallest reduced mean free path of the medium (largest ``sigma_t'`` over
colours and the voxels inside the mesh) and ``1/sigma_tr`` the largest diffusion length,
so a setting is at least as fine, and a range at least as wide, in every colour. The cubemap
gather's defaults of ``eps_g``, ``eps_c`` and ``eps_b`` are derived in
:mod:`dipole_gl.cubemap_geometry`; ``fit = coarsen`` leaves its settings as given.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

from harness.errors import InputError

from .cubemap_geometry import EPS_B, EPS_C, EPS_G

__all__ = ["DipoleParams", "GATHERS", "KERNELS", "FITS", "TERMS", "GATHER_FIELDS", "DEFAULTS", "LIMITS",
           "DEFAULT_EPSILON"]

KERNELS = ("dipole", "dirpole")
GATHERS = ("dense", "vertex", "cubemap", "hierarchical", "atlas")
#: What a setting over the gather's budget does (:mod:`dipole_gl.sizing`); ``refuse`` is the default.
FITS = ("refuse", "coarsen")
#: Which terms of the BSSRDF a render adds (``both`` is the default, as Jensen et al. 2001 render it).
TERMS = ("diffusion", "single", "both")
#: gather -> the parameters that belong to it alone, with their defaults
#: The hierarchical gather's default solid-angle bound (sr): ``docs/dipole_rivals.md``, the hierarchical gather.
DEFAULT_EPSILON = 0.03
GATHER_FIELDS = {"dense": {"spacing": 1.0}, "vertex": {"range": 4.0, "density": 1.0},
                 "cubemap": {"cube_size": 64, "light_size": 256, "samples": 32, "frames": 8, "disc_radius": 4.0,
                             "eps_g": EPS_G, "eps_c": EPS_C, "eps_b": EPS_B},
                 "hierarchical": {"spacing": 1.0, "epsilon": DEFAULT_EPSILON},
                 "atlas": {"atlas_size": 128, "links": 16, "link_level": None, "adaptive": None}}
#: The atlas gather's fields checked by hand (a scheme switch, not a range): ``DipoleParams.__post_init__``.
_SCHEME = ("links", "link_level", "adaptive")
#: name -> (lowest, highest, lowest allowed, integer)
LIMITS = {"spacing": (0.05, 10.0, True, False), "range": (0.0, 100.0, False, False),
          "density": (0.01, 100.0, True, False), "cube_size": (8, 2048, True, True),
          "light_size": (16, 4096, True, True), "samples": (1, 65536, True, True), "frames": (1, 4096, True, True),
          "disc_radius": (0.0, 100.0, False, False), "eps_g": (0.0, 16.0, True, False),
          "eps_c": (0.0, 16.0, True, False), "eps_b": (0.0, 64.0, True, False),
          "epsilon": (0.0, 4.0 * math.pi, True, False), "atlas_size": (8, 4096, True, True),
          "links": (1, 65536, True, True), "link_level": (0, 12, True, True)}
DEFAULTS = {k: v for d in GATHER_FIELDS.values() for k, v in d.items()}


def _p(default, doc):
    return field(default=default, metadata={"doc": doc})


@dataclass(frozen=True)
class DipoleParams:
    """Settings of the ``dipole`` and ``dirpole`` methods (see the module docstring)."""

    gather: str = _p("dense", "surface gather: dense (the kernel over the whole surface, dense stated sampling), "
                              "vertex (Hao & Varshney 2004: per vertex, precomputed neighbourhood factors), "
                              "cubemap (the thesis draft: light buffer, six cube faces, disc samples, frames) or "
                              "hierarchical (Jensen & Buhler 2002: an octree of the dense samples) or atlas "
                              "(Carr, Hall & Hart 2003: links into a MIP-mapped texture atlas)")
    spacing: float | None = _p(None, "gather=dense or hierarchical: sample spacing in reduced mean free paths "
                                     "1/sigma_t' (default 1), in [0.05, 10]")
    epsilon: float | None = _p(None, f"gather=hierarchical: a node subtending a solid angle below epsilon (sr) is "
                                     f"used whole (default {DEFAULT_EPSILON:g}; 0 is the dense far field), in [0, 4 pi]")
    atlas_size: int | None = _p(None, "gather=atlas: texels per side of the multiresolution meshed atlas, a power "
                                      "of two (default 128), in [8, 4096]")
    links: int | None = _p(None, "gather=atlas, adaptive scheme: links per texel from the priority queue on "
                                 "throughput (default 16), in [1, 65536]")
    link_level: int | None = _p(None, "gather=atlas, non-adaptive scheme: link every texel to every node of this "
                                      "MIP level (default: the adaptive scheme), in [0, log2 atlas-size]")
    adaptive: bool | None = _p(None, "gather=atlas: true (the default without --link-level) or false (needs "
                                     "--link-level)")
    range: float | None = _p(None, "gather=vertex: effective scattering range in diffusion lengths 1/sigma_tr "
                                   "(default 4), in (0, 100]")
    density: float | None = _p(None, "gather=vertex: scattering vertices per square reduced mean free path "
                                     "(default 1), in [0.01, 100]")
    cube_size: int | None = _p(None, "gather=cubemap: texels per side of each of the six cube faces (default 64), "
                                     "in [8, 2048]")
    light_size: int | None = _p(None, "gather=cubemap: light-buffer texels per side, per light (default 256), "
                                      "in [16, 4096]")
    samples: int | None = _p(None, "gather=cubemap: disc samples in the light buffer per face texel, light and "
                                   "frame (default 32), in [1, 65536]")
    frames: int | None = _p(None, "gather=cubemap: disc rotations accumulated while the scene is static "
                                  "(default 8), in [1, 4096]")
    disc_radius: float | None = _p(None, "gather=cubemap: the disc's world radius in diffusion lengths 1/sigma_tr "
                                         "(default 4), in (0, 100]")
    eps_g: float | None = _p(None, "gather=cubemap: the G-buffer fix (thesis Sec. 4.3.1) in light-buffer texels "
                                   "(default 0.75), in [0, 16]")
    eps_c: float | None = _p(None, "gather=cubemap: the cubemap fix (thesis Sec. 4.3.2) in cube texels "
                                   "(default 0.75), in [0, 16]")
    eps_b: float | None = _p(None, "gather=cubemap: the depth bias (thesis Sec. 4.3.3) in cube texels "
                                   "(default 2.5), in [0, 64]")
    shadow_size: int = _p(1024, "shadow-map resolution per light (visibility of the irradiance), in [16, 8192]")
    fit: str | None = _p(None, "a spacing (dense) or vertex density (vertex) over the gather's budget: refuse "
                               "(default) or coarsen it just enough to fit (the value used is in the result)")
    terms: str = _p("both", "BSSRDF terms: both (default; Jensen et al. 2001's diffusion term plus single "
                            "scattering), diffusion (the kernel alone) or single (single scattering alone)")

    def __post_init__(self):
        def bad(name, problem, fix):
            raise InputError("--" + name.replace("_", "-"), name, problem, fix)

        if self.gather not in GATHERS:
            bad("gather", f"unknown gather {self.gather!r}", "use one of: " + ", ".join(GATHERS))
        mine = GATHER_FIELDS[self.gather]
        for g, names in GATHER_FIELDS.items():
            for name in names:
                if name not in mine and getattr(self, name) is not None:
                    owner = "|".join(o for o, n in GATHER_FIELDS.items() if name in n)
                    bad(name, f"belongs to gather={owner}, not gather={self.gather}",
                        f"drop --{name} or use --gather {owner.split('|')[0]}")
        if self.gather == "atlas":
            self._scheme(bad)
        for name, default in mine.items():
            if getattr(self, name) is None and name not in _SCHEME:
                object.__setattr__(self, name, default)
        for name in mine:
            v = getattr(self, name)
            if name == "adaptive" or (v is None and name in _SCHEME):
                continue
            lo, hi, lo_closed, integer = LIMITS[name]
            ok = isinstance(v, int if integer else (int, float)) and not isinstance(v, bool) and math.isfinite(v) \
                and (v >= lo if lo_closed else v > lo) and v <= hi
            if not ok:
                bad(name, f"must be {'an integer' if integer else 'a number'} in {'[' if lo_closed else '('}"
                    f"{lo:g}, {hi:g}], got {v!r}", "change the value")
            object.__setattr__(self, name, int(v) if integer else float(v))
        if self.gather == "atlas" and self.atlas_size & (self.atlas_size - 1):
            bad("atlas_size", f"must be a power of two, got {self.atlas_size}", "use e.g. 64, 128 or 256")
        if self.link_level is not None and 1 << self.link_level > self.atlas_size:
            bad("link_level", f"level {self.link_level} is above the atlas's top level "
                f"{self.atlas_size.bit_length() - 1}", "use a lower --link-level")
        if self.fit not in (None,) + FITS:
            bad("fit", f"unknown value {self.fit!r}", "use one of: " + ", ".join(FITS))
        if self.fit == "refuse":                       # the default: left out of the label
            object.__setattr__(self, "fit", None)
        if self.terms not in TERMS:
            bad("terms", f"unknown value {self.terms!r}", "use one of: " + ", ".join(TERMS))
        v = self.shadow_size
        if isinstance(v, bool) or not isinstance(v, int) or not 16 <= v <= 8192:
            bad("shadow_size", f"must be an integer in [16, 8192], got {v!r}", "change the value")

    def _scheme(self, bad):
        """The atlas's link scheme: ``link_level`` given is the non-adaptive one (no ``links``), else adaptive."""
        if self.link_level is not None:
            if self.adaptive:
                bad("adaptive", "the adaptive scheme takes no --link-level", "drop --adaptive or --link-level")
            if self.links is not None:
                bad("links", "the non-adaptive scheme links every texel to every node of --link-level",
                    "drop --links (or --link-level for the adaptive scheme)")
            object.__setattr__(self, "adaptive", False)
            return
        if self.adaptive is False:
            bad("adaptive", "the non-adaptive scheme needs a level", "give --link-level")
        if self.adaptive is not None and not isinstance(self.adaptive, bool):
            bad("adaptive", f"must be true or false, got {self.adaptive!r}", "write true or false")
        object.__setattr__(self, "adaptive", True)
        object.__setattr__(self, "links", 16 if self.links is None else self.links)

    @staticmethod
    def doc(name):
        """The one-line description of a field."""
        return {f.name: f.metadata["doc"] for f in dataclasses.fields(DipoleParams)}[name]

    @staticmethod
    def field_types():
        return {f.name: f.type for f in dataclasses.fields(DipoleParams)}

    def as_dict(self):
        """The settings that apply (a parameter of the other gather is left out)."""
        return {k: v for k, v in dataclasses.asdict(self).items() if v is not None}

    def replace(self, **changes):
        return dataclasses.replace(self, **changes)
