"""Host side of ``shade_vertex.vert/frag``: the vertex gather's image.

The display (scene) mesh is drawn with its per-vertex result ``B`` as a vertex attribute
(Gouraud interpolation, Hao & Varshney 2004, Sec. 3.2); each pixel applies the exit
Fresnel transmittance and adds the direct reflection off a dielectric boundary.
"""

from __future__ import annotations


from .gbuffer import camera_pass, camera_program

__all__ = ["build_program", "run"]


def build_program(ctx, warnings):
    return camera_program(ctx, "shade_vertex.vert", "shade_vertex.frag", "shade_vertex", warnings)


run = camera_pass
