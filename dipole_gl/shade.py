"""Host side of ``shade_vertex.vert/frag``: the vertex gather's image.

The display (scene) mesh is drawn with its per-vertex result ``B`` as a vertex attribute
(Gouraud interpolation, Hao & Varshney 2004, Sec. 3.2); each pixel applies the exit
Fresnel transmittance and adds the direct reflection off a dielectric boundary.
"""

from __future__ import annotations

from sslpv_gl import shaders as _sh

from .glsl import DIRS, MAX_LIGHTS
from .gbuffer import camera_pass

__all__ = ["build_program", "run"]


def build_program(ctx, warnings):
    prog = _sh.program(ctx, "shade_vertex.vert", "shade_vertex.frag", {"MAX_LIGHTS": MAX_LIGHTS}, dirs=DIRS)
    _sh.check_uniforms(prog, ["u_view_proj", "u_eta", "u_cam_pos", "u_shadow"], "shade_vertex", warnings)
    if "u_shadow" in prog:
        prog["u_shadow"].value = 0
    return prog


run = camera_pass
