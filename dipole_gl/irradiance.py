"""Host side of ``irradiance.comp``: per surface point and light, the flux transmitted inwards.

Inputs are two storage buffers of the points (``pos_area``: xyz + area, ``nrm``), the
lights (uniforms) and the shadow-map atlas of :func:`sslpv_gl.rsm.render_shadow_atlas`.
Outputs, kept on the GPU for the gathers: ``flux`` and ``w12`` (one vec4 per light and
point, light-major) and ``total`` (their sum over lights).
"""

from __future__ import annotations

import numpy as np

from sslpv_gl import shaders as _sh
from sslpv_gl.rsm import set_light_uniforms

from .glsl import DIRS, MAX_LIGHTS

__all__ = ["build_program", "PointBuffers", "run", "set_lights"]

LOCAL = 64


def build_program(ctx, warnings):
    prog = _sh.compute(ctx, "irradiance.comp", {"MAX_LIGHTS": MAX_LIGHTS}, dirs=DIRS)
    _sh.check_uniforms(prog, ["u_count", "u_n_lights", "u_eta", "u_light_I", "u_light_pos", "u_light_vp",
                              "u_shadow", "u_shadow_size", "u_shadow_texel"], "irradiance", warnings)
    if "u_shadow" in prog:
        prog["u_shadow"].value = 0
    return prog


class PointBuffers:
    """The surface points of one gather on the GPU, and the irradiance outputs sized for them."""

    def __init__(self, ctx, positions, normals, areas, n_lights):
        self.count = len(positions)
        pa = np.concatenate([positions, np.asarray(areas, np.float64)[:, None]], axis=1).astype("f4")
        nn = np.concatenate([normals, np.zeros((self.count, 1))], axis=1).astype("f4")
        self.pos_area = ctx.buffer(pa.tobytes())
        self.nrm = ctx.buffer(nn.tobytes())
        size = max(self.count * max(n_lights, 1) * 16, 16)
        self.flux = ctx.buffer(reserve=size)
        self.w12 = ctx.buffer(reserve=size)
        self.total = ctx.buffer(reserve=max(self.count * 16, 16))
        self.n_lights = n_lights

    def bind(self):
        for i, b in enumerate((self.pos_area, self.nrm, self.flux, self.w12, self.total)):
            b.bind_to_storage_buffer(i)

    def read_flux(self):
        """``(L, S, 4)`` float32: rgb flux and visibility per light and point."""
        return np.frombuffer(self.flux.read(), dtype="f4")[: self.n_lights * self.count * 4] \
            .reshape(self.n_lights, self.count, 4)

    def release(self):
        for b in (self.pos_area, self.nrm, self.flux, self.w12, self.total):
            b.release()


def set_lights(prog, scene, views, shadow_size):
    """The light uniforms that ``shadow.glsl`` (and the irradiance) read (:func:`sslpv_gl.rsm.set_light_uniforms`)."""
    set_light_uniforms(prog, scene, views, shadow_size, MAX_LIGHTS)


def run(prog, points, scene, views, shadow_tex, shadow_size):
    """Fill ``points.flux``, ``points.w12`` and ``points.total``."""
    points.bind()
    shadow_tex.use(0)
    set_lights(prog, scene, views, shadow_size)
    _sh.set_uniform(prog, "u_count", points.count)
    _sh.set_uniform(prog, "u_n_lights", len(scene.lights))
    _sh.set_uniform(prog, "u_eta", float(scene.boundary.eta))
    prog.run((points.count + LOCAL - 1) // LOCAL)
