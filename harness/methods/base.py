"""The method interface: what every renderer under comparison gives the harness.

A *method* renders a scene with its parameters and returns a :class:`MethodResult`: the
subsurface and full images, per-stage timings of one frame, its precomputation time kept
apart from the frame, and a device-independent *work count* per stage (texels, cell
updates, kernel evaluations ...), so that costs also compare fairly on a CPU OpenGL driver,
where GL times are CPU times. Each method declares its parameters once (a frozen, validating
dataclass with a one-line description per field) and the command-line names of its fields;
:mod:`harness.methods.params` turns command-line lists into validated configurations.

Adding a method: a package of its own beside ``sslpv_gl`` (the renderer, its shaders and its
NumPy twin), an adapter subclassing :class:`Method` here, and one entry in
:data:`harness.methods.METHODS`; every command (``render``, ``sweep``, ``nightly``) then takes
it with ``--method NAME`` and its parameters as flags.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from harness.errors import InputError

__all__ = ["MethodResult", "Method"]


@dataclass
class MethodResult:
    """One frame of one method (images row 0 at the top, linear RGB float32)."""

    full: np.ndarray                 # (H, W, 3) subsurface + surface reflection
    subsurface: np.ndarray           # (H, W, 3)
    mask: np.ndarray                 # (H, W) bool: pixel covered by the mesh
    timings_ms: dict                 # per-frame stage -> ms (GL timer queries, or host time where stated)
    precompute_ms: dict              # precomputation step -> host ms (not part of the frame)
    work: dict                       # per-frame stage -> work count (Method.work_units)
    precompute_work: dict            # precomputation step -> work count
    device: str                      # GL_RENDERER of the context that rendered it
    warnings: list = field(default_factory=list)
    steps_used: int | None = None    # SSLPV: propagation steps run (None: steady / not applicable)
    diagnostics: dict | None = None
    calibration: dict | None = None
    shared: list | None = None       # stages measured once for a group of configurations (SSLPV step groups)
    info: dict = field(default_factory=dict)

    @property
    def frame_ms(self):
        """The frame: the sum of the per-frame stages (None when one is missing)."""
        vals = list(self.timings_ms.values())
        return float(sum(vals)) if vals and all(np.isfinite(v) for v in vals) else None


class Method:
    """One renderer under comparison (subclass it; see the module docstring)."""

    name = ""                        # the --method value
    title = ""                       # one line with its paper
    params_type = None               # the frozen, validating dataclass of its parameters
    cli = {}                         # command-line name -> field of params_type
    stages = ()                      # per-frame stages, in order (the store's timing rows)
    precompute_steps = ()
    work_units = {}                  # stage or step -> what one unit of its work count is

    # -- parameters ----------------------------------------------------------

    def field_types(self):
        return {f.name: f.type for f in dataclasses.fields(self.params_type)}

    def doc(self, field_name):
        return self.params_type.doc(field_name)

    def make_params(self, **fields):
        """Validated parameters (an InputError names the flag and the fix)."""
        return self.params_type(**fields)

    def params_from_dict(self, d):
        """Parameters from a stored dict (the store's ``params``, a ``sweep.json`` product)."""
        return self.params_type(**{k: v for k, v in d.items() if k != "method"})

    def as_dict(self, params):
        return params.as_dict()

    def label(self, params):
        """A short stable name for one configuration."""
        d = params if isinstance(params, dict) else self.as_dict(params)
        defaults = self.as_dict(self.params_type())
        extra = [f"{self.field_to_cli(k)}={v}" for k, v in sorted(d.items()) if k != "method" and v != defaults.get(k)]
        return self.name + ("-" + "-".join(extra) if extra else "")

    def split_products(self, lists):
        """One sweep product's field lists -> the products to expand (default: as they are)."""
        return [lists]

    def field_to_cli(self, field_name):
        return {v: k for k, v in self.cli.items()}.get(field_name, field_name)

    # -- scenes and rendering -------------------------------------------------

    def check_scene(self, scene):
        """Raise an InputError (one line) when this method cannot represent ``scene``."""

    def renderer(self):
        """This process's renderer of the method (made on first use, kept)."""
        raise NotImplementedError

    def render(self, scene, params, renderer=None):
        """One frame -> :class:`MethodResult`."""
        raise NotImplementedError

    def release(self):
        """Release this process's renderer (its GL context)."""


def unknown_method(name, known):
    return InputError("--method", "method", f"unknown method {name!r}", "use one of: " + ", ".join(known))
