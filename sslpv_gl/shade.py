"""Shading (Sec. 3.3, Eqs. 4-7): the camera image from the accumulation grid and the lights.

.. list-table::
   :header-rows: 1

   * - function
     - paper
     - shaders
     - what
   * - :func:`run`
     - Sec. 3.3, Eqs. 4-7
     - ``shade.vert/frag``
     - area-light radiance from the accumulation grid (times ``1/eta^2``
       with ``params.eta2``; not in the paper), plus GGX reflection of each
       light (shadow-mapped) for a dielectric boundary
   * - :func:`read_images`
     - --
     - --
     - the four attachments read back, row 0 at the top (conventions)

The accumulation grid is looked up per cell (``lookup="cell"``, NEAREST, as the
paper) or trilinearly (``lookup="trilinear"``, LINEAR); the ``lookup`` is a
define of the program and sets the grid textures' filter. Direct reflection is
the GGX reflection half of a rough dielectric. An index-matched boundary and a
smooth one (roughness 0, whose mirror image of a point light the pinhole never
sees) reflect nothing (``u_n_lights = 0``), as in the reference.

Where the grid is read. The paper reads "the point light intensities of the boundary grid cells" (Sec. 3.3)
at the shaded point ``x_o`` itself. ``params.shade_depth = d`` (an extension, in cells; 0 = the paper) reads
them ``d`` cells inwards along the normal instead:

    q(x_o) = x_o - d dx n(x_o),     dx = the grid's cell size                                   (S1)

A boundary cell holds a fraction of medium that depends on where the surface cuts it, so the point's own
cell can be mostly outside the object: under ``outside = interior`` such a cell holds only the light that
has just stepped out of the medium, not the light inside it, and the lit side reads in a speckle of the
grid's cells; under ``vacuum`` it also holds light that left the object elsewhere and ran round it.
Read ``d = 1`` cell deep under a surface that is flat across a cell, the cell read has its centre inside the
object, at least ``(1 - sqrt(3)/2) dx`` deep.
Limits: the move is along the interpolated normal, so a part of the object thinner than ``d dx`` is read
from its far side's cells or from outside it; the read is clamped to the grid's edge as before; the radiance
estimate of Eqs. 5-7 is unchanged (it takes the deeper cell's intensities for those behind the surface).
"""

from __future__ import annotations

import numpy as np

from . import shaders as _sh
from .rsm import MAX_LIGHTS, camera_view_proj, gl_bytes, set_light_uniforms

__all__ = ["MAX_LIGHTS", "build_program", "run", "read_images"]


def build_program(ctx, lookup, warnings):
    """The shading program for ``lookup``; the grid samplers sit on units 0-2, the shadow map on 3."""
    prog = _sh.program(ctx, "shade.vert", "shade.frag",
                       {"LOOKUP_TRILINEAR": int(lookup == "trilinear"), "MAX_LIGHTS": MAX_LIGHTS})
    names = ["u_view_proj", "u_acc_r", "u_acc_g", "u_acc_b", "u_bbox_min", "u_bbox_size", "u_N",
             "u_area", "u_eta", "u_sub_scale", "u_shade_shift", "u_alpha", "u_cam_pos", "u_n_lights", "u_light_pos",
             "u_light_I", "u_light_vp", "u_shadow", "u_shadow_size", "u_shadow_texel"]
    if lookup == "trilinear":
        names.remove("u_N")                     # only the cell lookup needs N
    present = _sh.check_uniforms(prog, names, f"shade[{lookup}]", warnings)
    for unit, name in enumerate(("u_acc_r", "u_acc_g", "u_acc_b", "u_shadow")):
        if name in present:
            prog[name].value = unit
    return prog


def run(ctx, prog, vao, target, scene, params, grid, views, shadow_tex, centre, radius, acc=None):
    """Draw the mesh into ``target`` (four attachments: full, subsurface, position, normal).

    ``acc``: the three textures to shade from (default ``grid.accum``; the
    radiance-scaled copy ``grid.scaled`` when a scale applies).

    ``vao`` draws the mesh with ``prog`` (:func:`build_program` for
    ``params.lookup``); ``views`` are the lights' :class:`sslpv_gl.rsm.LightView`
    and ``shadow_tex`` the shadow-map atlas of :func:`sslpv_gl.rsm.render_maps`;
    ``centre``, ``radius`` the mesh's bounding sphere (camera near/far).
    """
    set_ = _sh.set_uniform
    cam = scene.camera
    target.begin(ctx, (cam.width, cam.height))
    filt = ctx.LINEAR if params.lookup == "trilinear" else ctx.NEAREST
    for unit, t in enumerate(grid.accum if acc is None else acc):
        t.filter = (filt, filt)
        t.use(unit)
    shadow_tex.use(3)
    med, b = scene.medium, scene.boundary
    bmin = np.asarray(med.bbox_min, dtype=np.float64)
    size = np.asarray(med.bbox_max, dtype=np.float64) - bmin
    dx = float(size[0] / params.N)
    prog["u_view_proj"].write(gl_bytes(camera_view_proj(cam, centre, radius)))
    set_(prog, "u_bbox_min", tuple(map(float, bmin)))
    set_(prog, "u_bbox_size", tuple(map(float, size)))
    set_(prog, "u_N", params.N)
    set_(prog, "u_area", dx * dx)                   # A = dx^2, the area light of Eq. 5
    set_(prog, "u_shade_shift", float(params.shade_depth) * dx)     # Eq. (S1)
    set_(prog, "u_eta", float(b.eta))
    set_(prog, "u_sub_scale", 1.0 / (float(b.eta) ** 2) if params.eta2 else 1.0)
    set_(prog, "u_alpha", float(b.roughness))
    set_(prog, "u_cam_pos", tuple(map(float, cam.origin)))
    n = len(scene.lights)
    # A smooth interface reflects a point light only into a set of directions of measure zero.
    set_(prog, "u_n_lights", 0 if b.index_matched or float(b.roughness) == 0.0 else n)
    set_light_uniforms(prog, scene, views, params.rsm_size, MAX_LIGHTS)
    vao.render(ctx.TRIANGLES)


def read_images(target, width, height):
    """``[full, subsurface, position, normal]``, each ``(height, width, 4)`` float32, row 0 at the top."""
    return [np.frombuffer(target.fbo.read(components=4, attachment=i, dtype="f4"), dtype="f4")
            .reshape(height, width, 4)[::-1] for i in range(4)]
