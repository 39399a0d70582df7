"""Host side of ``gbuffer.frag`` (with SSLPV's ``shade.vert``): the dense gather's exit points.

One raster pass of the scene mesh from the camera into five RGBA32F attachments: world
position (w = coverage), normal, the direct reflection of the lights off a dielectric
boundary (nothing when index-matched), and the shadow-map visibility of lights 0-3 and 4-7. :func:`from_points` fills the same textures from
given exit points instead, so the gather can be evaluated anywhere (the energy test).
"""

from __future__ import annotations

import numpy as np

from sslpv_gl import shaders as _sh
from sslpv_gl.rsm import camera_view_proj, gl_bytes

from .glsl import DIRS, MAX_LIGHTS
from .irradiance import set_lights

__all__ = ["build_program", "camera_program", "camera_pass", "run", "from_points", "read"]


def camera_program(ctx, vertex, fragment, label, warnings):
    """A raster program drawn by :func:`camera_pass`: the shadow-map atlas on unit 0."""
    prog = _sh.program(ctx, vertex, fragment, {"MAX_LIGHTS": MAX_LIGHTS}, dirs=DIRS)
    _sh.check_uniforms(prog, ["u_view_proj", "u_eta", "u_cam_pos", "u_shadow"], label, warnings)
    if "u_shadow" in prog:
        prog["u_shadow"].value = 0
    return prog


def build_program(ctx, warnings):
    return camera_program(ctx, "shade.vert", "gbuffer.frag", "gbuffer", warnings)


def camera_pass(ctx, prog, vao, target, scene, views, shadow_tex, shadow_size, centre, radius):
    """Draw the mesh from the camera into ``target`` with the light, shadow and reflection uniforms set."""
    cam, b = scene.camera, scene.boundary
    target.begin(ctx, (cam.width, cam.height))
    shadow_tex.use(0)
    prog["u_view_proj"].write(gl_bytes(camera_view_proj(cam, centre, radius)))
    set_lights(prog, scene, views, shadow_size)
    _sh.set_uniform(prog, "u_eta", float(b.eta))
    _sh.set_uniform(prog, "u_alpha", float(b.roughness))
    _sh.set_uniform(prog, "u_cam_pos", tuple(map(float, cam.origin)))
    _sh.set_uniform(prog, "u_n_lights", 0 if b.index_matched else len(scene.lights))
    _sh.set_uniform(prog, "u_count_lights", len(scene.lights))
    vao.render(ctx.TRIANGLES)


run = camera_pass


def from_points(target, positions, normals, visibility=None):
    """Write exit points (H, W, 3) into the G-buffer textures (no reflection), row 0 at the top.

    ``visibility`` (H, W, L) of each light at the points defaults to 1 (a light behind the
    surface still gives nothing: the near field tests the cosine).
    """
    h, w = positions.shape[:2]
    vis = np.ones((h, w, 8)) if visibility is None else np.concatenate(
        [visibility, np.zeros((h, w, 8 - visibility.shape[-1]))], axis=-1)
    layers = [np.concatenate([positions, np.ones((h, w, 1))], axis=-1),
              np.concatenate([normals, np.zeros((h, w, 1))], axis=-1), np.zeros((h, w, 4)), vis[..., :4], vis[..., 4:]]
    for tex, data in zip(target.textures, layers):
        tex.write(np.ascontiguousarray(data[::-1], dtype="f4").tobytes())


def read(tex, width, height):
    """A texture as (height, width, 4) float32, row 0 at the top."""
    return np.frombuffer(tex.read(), dtype="f4").reshape(height, width, 4)[::-1]
