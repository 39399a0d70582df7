"""SSLPV (Borlum et al., HPG 2011) as a method: :class:`sslpv_gl.renderer.SSLPVRenderer`, unchanged.

The adapter only relabels what the renderer returns: the four stages of the paper's
Table 1 are the frame; the per-cell material built on the host (``host_material``, cached
per scene and material setting, so near 0 ms when reused) is reported as the precomputation.
Work counts per stage: ``rsm`` the texels rendered (injection RSM and shadow map, every
light), ``injection`` the injected points (one per injection texel), ``propagation`` the cell
updates (``N^3`` per step, each a six-neighbour gather; unknown for ``steps = steady``, which
solves instead of stepping), ``shading`` the pixels.
"""

from __future__ import annotations

import numpy as np

from .base import Method, MethodResult

__all__ = ["SSLPVMethod", "CLI_TO_FIELD"]

#: command-line name -> SSLPVParams field (the names users know from the paper: --grid for N)
CLI_TO_FIELD = {
    "grid": "N", "steps": "steps", "mapping": "mapping", "resample": "resample", "outside": "outside",
    "phase_scaling": "phase_scaling", "boundary_reflect": "boundary_reflect",
    "lookup": "lookup", "skip": "skip", "inject_offset": "inject_offset",
    "inject_depth": "inject_depth", "shade_depth": "shade_depth", "precision": "precision",
    "rsm_size": "rsm_size", "inject_size": "inject_size", "eta2": "eta2",
    "sigma_scale": "sigma_scale", "radiance_scale": "radiance_scale", "converge_tol": "converge_tol",
    "max_steps": "max_steps", "exitance": "exitance",
}

STAGES = ("rsm", "injection", "propagation", "shading")


class SSLPVMethod(Method):
    name = "sslpv"
    title = "SSLPV (Borlum et al., HPG 2011): light propagation volumes in GLSL (sslpv_gl)"
    cli = CLI_TO_FIELD
    stages = STAGES
    precompute_steps = ("material",)
    work_units = {"rsm": "texels rendered", "injection": "injected points", "propagation": "cell updates",
                  "shading": "pixels", "material": "LPV cells"}

    def __init__(self):
        from sslpv_gl.params import SSLPVParams

        self.params_type = SSLPVParams
        self._renderer = None

    def make_params(self, **fields):
        """Validated parameters from the settings given; a calibrated mapping brings the settings it was fitted
        with for the ones not given (:meth:`sslpv_gl.params.SSLPVParams.given`), and a configuration that turns
        on an extension without an ``outside`` gets the extensions' committed treatment
        (:mod:`harness.methods.extension_outside`)."""
        from .extension_outside import with_extension_outside

        return self.params_type.given(**with_extension_outside(fields, self.params_type))

    def label(self, params):
        """``N32-K16-collision``: the paper's three axes, then any non-default setting (as before methods)."""
        p = params if isinstance(params, dict) else params.as_dict()
        extra = self.settings_label(p)
        return f"N{p['N']}-K{p['steps']}-{p['mapping']}" + ("-" + extra if extra else "")

    def settings_label(self, params):
        """The label's non-default settings beyond N, K and mapping (``skip=0``), or ``""``."""
        p = params if isinstance(params, dict) else params.as_dict()
        defaults = self.params_type().as_dict()
        return "-".join(f"{self.field_to_cli(k)}={v}" for k, v in sorted(p.items())
                        if k not in ("N", "steps", "mapping", "method") and v != defaults.get(k))

    def renderer(self):
        if self._renderer is None:
            from sslpv_gl.renderer import SSLPVRenderer

            self._renderer = SSLPVRenderer()
        return self._renderer

    def release(self):
        if self._renderer is not None:
            self._renderer.ctx.release()
            self._renderer = None

    def result(self, res, scene, params):
        """:class:`MethodResult` of one :class:`sslpv_gl.renderer.RenderResult`."""
        t = res.timings_ms
        timings = {k: float(t[k]) for k in STAGES if isinstance(t.get(k), (int, float))}
        L, cam = len(scene.lights), scene.camera
        work = {"rsm": (params.inject_size ** 2 + params.rsm_size ** 2) * L, "injection": params.inject_size ** 2 * L,
                "shading": cam.width * cam.height}
        if res.steps_used is not None:
            work["propagation"] = params.N ** 3 * int(res.steps_used)
        return MethodResult(full=res.full, subsurface=res.subsurface, mask=res.mask, timings_ms=timings,
                            precompute_ms={"material": float(t.get("host_material", np.nan))}, work=work,
                            precompute_work={"material": params.N ** 3}, device=res.gl_renderer,
                            warnings=list(res.warnings), steps_used=res.steps_used, diagnostics=res.diagnostics,
                            calibration=res.calibration, shared=t.get("shared"))

    def render(self, scene, params, renderer=None):
        return self.result((renderer or self.renderer()).render(scene, params), scene, params)

    def render_steps(self, scene, params, steps_list, diagnostics=False, renderer=None):
        """One result per step count from one propagation (:meth:`SSLPVRenderer.render_steps`)."""
        results = (renderer or self.renderer()).render_steps(scene, params, steps_list, diagnostics=diagnostics)
        return [self.result(r, scene, params.replace(steps=r.steps_used) if r.steps_used is not None else params)
                for r in results]
