"""Host side of ``single.comp``: Jensen et al. 2001's single-scattering term S^(1), per camera pixel.

The complete BSSRDF of Jensen et al. (2001, Sec. 2) is ``S = S_d + S^(1)``; the kernels of
:mod:`dipole_gl.kernels` are ``S_d``. This pass adds ``S^(1)`` to either gather's image
(``terms = both``) or renders it alone (``terms = single``), from the G-buffer's exit points
(:mod:`dipole_gl.gbuffer`) and a *light atlas*: per light, the world position and outward
normal of the first surface point seen from the light (SSLPV's ``rsm.vert/frag`` over the
shadow-map frustum, two attachments).

Per pixel (exit point ``x_o``, normal ``n_o``, direction to the camera ``w_o``):

* the refracted view ray ``x = x_o + s d``, ``d`` = Snell(``-w_o``), is marched with
  :data:`N_MARCH` nodes, a midpoint rule in ``u = 1 - exp(-sigma_ref s)`` (``sigma_ref`` the
  smallest ``sigma_t`` of the three colours): ``s_k = -ln(1 - (k + 1/2)/N)/sigma_ref``, weights
  ``exp(-(sigma_t - sigma_ref) s_k)/(N sigma_ref)`` for ``int_0^inf f(s) e^(-sigma_t s) ds``;
* per node and light ``y``: the entry point ``x_i`` of the straight line from ``y`` through
  ``x``, from the atlas (bilinear over the valid texels: its distance ``d_i`` from the light
  and its normal ``n_i``), the straight distance ``s_i = |y - x| - d_i`` and Jensen's estimate
  of the refracted one, ``s'_i = s_i cos_i / sqrt(1 - (1 - cos_i^2)/eta^2)`` (Jensen et al.
  2001, Sec. 2.3: Snell's law on the plane of ``x_i``, ``cos_i = n_i . w_i``, ``w_i`` towards
  the light);
* the light there ``E' = I T(cos_i) (cos_i/cos_t) / ((d_i + s'_i/eta)(d_i + s'_i cos_i^2/(eta cos_t^2)))``:
  a point light seen through a flat interface (the refracted beam's sagittal and tangential
  spread; ``cos_i/cos_t`` is the solid-angle compression of Jensen's integral over refracted
  directions ``dw'_i``). With ``d_i >> s'_i`` it is Jensen's ``L_i(x_i)`` at the entry point;
  at ``eta = 1`` it is ``I/|y - x|^2`` exactly;
* ``L1 = T(w_o)/eta^2 sum_k w_k sum_l sigma_s p(w_12 . (-d)) E' exp(-sigma_t s'_i)``, ``p``
  Henyey-Greenstein with ``g = 1 - sigma_s'/sigma_s`` per colour, ``w_12`` the refracted travel
  direction of the light at ``x_i``; ``T`` the Fresnel transmittances at both ends (Jensen's
  ``F = F_t(eta, w_o) F_t(eta, w_i)``), ``1/eta^2`` the radiance leaving the denser medium.

Limits (docs/dipole_rivals.md, Sec. 11): the material is the exit point's for the whole march
(as the diffusion kernels'); the light's path is the straight line from the light, refracted once
at the atlas's entry point on a locally flat interface: a line that crosses the object, air and
the object again is attenuated over the air gap as well, and a surface behind ``x`` from the
camera's side is not seen (the march assumes the medium continues; the light's depth test ends it
where ``x`` lies in front of the lit surface); no internal reflection. Exact on an index-matched
convex object up to the march's quadrature and the atlas's interpolation.
"""

from __future__ import annotations

import numpy as np

from sslpv_gl import shaders as _sh
from sslpv_gl.rsm import gl_bytes

from .glsl import DIRS, MAX_LIGHTS
from .irradiance import set_lights

__all__ = ["N_MARCH", "build_program", "render_light_atlas", "run", "read_atlas", "iterations"]

#: Nodes of the march along the refracted view ray.
N_MARCH = 64
#: Bilinear taps of the light atlas per node and light (the loop inside ``light_term``).
ATLAS_TAPS = 4


def iterations(n_lights, n_march=N_MARCH):
    """Loop iterations of one invocation of ``single.comp``: the march, its light loop and the atlas taps."""
    return n_march * (1 + n_lights * (1 + ATLAS_TAPS))


def build_program(ctx, warnings):
    prog = _sh.compute(ctx, "single.comp", {"MAX_LIGHTS": MAX_LIGHTS}, dirs=DIRS)
    _sh.check_uniforms(prog, ["u_add", "u_n_lights", "u_n_march", "u_eta", "u_cam_pos", "u_size", "u_light_pos",
                              "u_light_I", "u_light_vp", "u_shadow_size", "u_gpos", "u_gnrm",
                              "u_grefl", "u_atlas_pos", "u_atlas_nrm", "u_sp", "u_sa", "u_st", "u_bbox_min",
                              "u_bbox_size", "u_res"], "single", warnings)
    for unit, name in enumerate(("u_sp", "u_sa", "u_st")):
        if name in prog:
            prog[name].value = unit
    for unit, name in ((3, "u_gpos"), (4, "u_gnrm"), (5, "u_grefl"), (6, "u_atlas_pos"), (7, "u_atlas_nrm")):
        if name in prog:
            prog[name].value = unit
    return prog


def render_light_atlas(ctx, rsm_prog, vao, targets, scene, size, views, slot="dipole_light_atlas"):
    """Per light a ``size``^2 tile of world position (w = valid) and normal, side by side -> the target.

    The raster of ``sslpv_gl.rsm.render_shadow_atlas`` (same program, frusta and tiles) into two
    attachments: its position tile is the shadow map's, its normal tile the RSM's normal.
    """
    s, n = int(size), len(scene.lights)
    atlas = targets.get(slot, (s * n, s), 2)
    atlas.fbo.use()
    atlas.fbo.viewport = (0, 0, s * n, s)
    atlas.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
    ctx.disable(ctx.BLEND)
    ctx.enable(ctx.DEPTH_TEST)
    for i, (light, view) in enumerate(zip(scene.lights, views)):
        viewport = (i * s, 0, s, s)
        atlas.fbo.viewport = viewport
        rsm_prog["u_view_proj"].write(gl_bytes(view.view_proj))
        _sh.set_uniform(rsm_prog, "u_intensity", tuple(map(float, light.intensity)))
        _sh.set_uniform(rsm_prog, "u_tan_half", (view.tan_half, view.tan_half))
        _sh.set_uniform(rsm_prog, "u_viewport", tuple(map(float, viewport)))
        vao.render(ctx.TRIANGLES)
    return atlas


def read_atlas(atlas):
    """The light atlas as two (S, S * L, 4) float32 arrays (position, normal), GL's row order (row 0 at the bottom)."""
    out = []
    for t in atlas.textures:
        w, h = t.size
        out.append(np.frombuffer(t.read(), dtype="f4").reshape(h, w, 4).copy())
    return out


def run(prog, gbuf, atlas, medium, out_sub, out_full, out_single, scene, views, size, add, n_march=N_MARCH):
    """S^(1) for every G-buffer pixel into ``out_single``; added to ``out_sub``/``out_full`` (``add``) or
    written there with the G-buffer's reflection (``terms = single``)."""
    cam = scene.camera
    medium.use(prog)
    for unit, t in zip((3, 4, 5), gbuf.textures[:3]):
        t.use(unit)
    atlas.textures[0].use(6)
    atlas.textures[1].use(7)
    set_lights(prog, scene, views, size)
    out_sub.bind_to_image(0, read=True, write=True)
    out_full.bind_to_image(1, read=True, write=True)
    out_single.bind_to_image(2, read=False, write=True)
    _sh.set_uniform(prog, "u_add", int(bool(add)))
    _sh.set_uniform(prog, "u_n_lights", len(scene.lights))
    _sh.set_uniform(prog, "u_n_march", int(n_march))
    _sh.set_uniform(prog, "u_eta", float(scene.boundary.eta))
    _sh.set_uniform(prog, "u_cam_pos", tuple(map(float, cam.origin)))
    _sh.set_uniform(prog, "u_size", (cam.width, cam.height))
    prog.run((cam.width + 7) // 8, (cam.height + 7) // 8)
    prog.ctx.memory_barrier()
