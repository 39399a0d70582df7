"""Reflective shadow maps (Sec. 3.1): light frusta, the camera, and the RSM pass.

.. list-table::
   :header-rows: 1

   * - function
     - paper
     - shaders
     - what
   * - :func:`light_view`, :func:`light_views`
     - Sec. 3.1
     - --
     - one square frustum per point light, fitted to the mesh's bounding sphere
   * - :func:`camera_view_proj`
     - --
     - ``shade.vert``
     - the camera of ``docs/conventions.md``, near/far fitted to the mesh
   * - :func:`render_maps`
     - Sec. 3.1
     - ``rsm.vert/frag``
     - per light: injection RSM (``inject_size``^2: position, normal,
       ``Phi_p = I dOmega_p``) and a tile of the shadow-map atlas
       (``rsm_size``^2), same frustum
   * - :func:`render_shadow_atlas`
     - Sec. 3.3 (direct light)
     - ``rsm.vert/frag``
     - the shadow-map atlas alone (also the dipole rivals' visibility)
   * - :func:`read_texels`
     - Sec. 3.1
     - --
     - an injection RSM read back as ``(M, 10)`` texels (conventions, "RSM texels")

Each point light gets a square perspective frustum aimed at the mesh's
bounding sphere, its half field of view ``asin(r / d)`` (times a 2 % margin)
so that the sphere's cone fits exactly inside the frustum. The same frustum
serves two renders:

* the **injection RSM**, ``inject_size`` squared (256^2 by default): world
  position, normal and flux ``Phi_p = I dOmega_p`` per texel, with
  ``dOmega_p = A_p cos^3(theta_p) / near^2`` (authors' answer);
* the **shadow map**, ``rsm_size`` squared (1024^2 by default), used only for
  direct-light visibility in shading.

The paper renders one 1024^2 RSM and uses "only 256^2 texel values for
injection" (Sec. 5). Rendering the injection RSM separately at 256^2 over the
same frustum gives each injection texel the flux of the 4x4 block of
shadow-map texels it covers (``dOmega`` scales with the texel area), i.e. the
same total flux with a 16x coarser spatial sampling, without reading the big
map back or downsampling it.

Matrices are NumPy float64, row-major, for column vectors; upload them with
:func:`gl_bytes` (column-major float32).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import shaders as _sh

__all__ = ["MAX_LIGHTS", "LightView", "bounding_sphere", "look_at", "perspective", "light_view", "light_views",
           "camera_view_proj", "gl_bytes", "MAX_RSM_HALF_FOV_DEG", "build_program", "render_maps",
           "render_shadow_atlas", "set_light_uniforms", "read_texels"]

#: Lights a render takes at most: the length of the light arrays of every stage that loops over the
#: lights (SSLPV's ``shade.frag``, the rivals' ``irradiance.comp``; the ``MAX_LIGHTS`` define).
MAX_LIGHTS = 8
#: Upper bound of the RSM half field of view (a light inside the bounding
#: sphere would otherwise need a frustum wider than 180 degrees).
MAX_RSM_HALF_FOV_DEG = 75.0


@dataclass(frozen=True)
class LightView:
    view_proj: np.ndarray       # (4, 4) float64
    tan_half: float             # tan of the half field of view (square frustum)
    near: float
    far: float
    clipped: bool               # the half FOV was capped: part of the mesh may be missed


def bounding_sphere(mesh):
    """``(centre, radius)``: centre of the mesh's box, radius to the farthest vertex."""
    v = np.asarray(mesh.vertices, dtype=np.float64)
    centre = 0.5 * (v.min(axis=0) + v.max(axis=0))
    radius = float(np.linalg.norm(v - centre, axis=1).max())
    return centre, radius


def look_at(origin, target, up):
    """View matrix of the conventions' right-handed look-at (camera looks down -z)."""
    o = np.asarray(origin, dtype=np.float64)
    f = np.asarray(target, dtype=np.float64) - o
    f /= np.linalg.norm(f)
    r = np.cross(f, np.asarray(up, dtype=np.float64))
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = r, u, -f
    m[:3, 3] = -m[:3, :3] @ o
    return m


def perspective(fov_y_deg, aspect, near, far):
    """OpenGL perspective projection; ``fov_y_deg`` is the full vertical FOV."""
    t = 1.0 / np.tan(np.radians(fov_y_deg) / 2.0)
    m = np.zeros((4, 4))
    m[0, 0], m[1, 1] = t / aspect, t
    m[2, 2] = (far + near) / (near - far)
    m[2, 3] = 2.0 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


def _any_up(forward):
    f = forward / np.linalg.norm(forward)
    for cand in ((0.0, 1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)):
        if abs(np.dot(f, cand)) < 0.9:
            return np.array(cand)
    return np.array((0.0, 1.0, 0.0))  # pragma: no cover


def light_view(light_pos, centre, radius, margin=1.02):
    """Square frustum from ``light_pos`` fitted to the bounding sphere (Sec. 3.1)."""
    L = np.asarray(light_pos, dtype=np.float64)
    c = np.asarray(centre, dtype=np.float64)
    d = float(np.linalg.norm(c - L))
    cap = np.radians(MAX_RSM_HALF_FOV_DEG)
    half = np.arcsin(min(radius / d, 1.0)) * margin if d > 0 else cap
    clipped = bool(half > cap)
    half = min(half, cap)
    near = max(d - radius, 1e-4 * max(d, radius)) * 0.5
    far = d + 2.0 * radius
    view = look_at(L, c, _any_up(c - L))
    proj = perspective(np.degrees(2.0 * half), 1.0, near, far)
    return LightView(proj @ view, float(np.tan(half)), near, far, clipped)


def camera_view_proj(camera, centre, radius):
    """Camera matrix (conventions' look-at/perspective), near/far fitted to the mesh."""
    o = np.asarray(camera.origin, dtype=np.float64)
    d = float(np.linalg.norm(np.asarray(centre) - o))
    near = max(d - radius, 1e-4 * max(d, radius)) * 0.5
    far = d + 2.0 * radius
    view = look_at(o, camera.target, camera.up)
    proj = perspective(camera.fov_y_deg, camera.width / camera.height, near, far)
    return proj @ view


def gl_bytes(mat):
    """A (…, 4, 4) row-major matrix as column-major float32 bytes for a GLSL mat4."""
    m = np.asarray(mat, dtype=np.float64)
    return np.ascontiguousarray(np.swapaxes(m, -1, -2), dtype=np.float32).tobytes()


def light_views(scene):
    """``(views, centre, radius, warnings)``: :func:`light_view` of every light of ``scene``."""
    centre, radius = bounding_sphere(scene.mesh)
    views = [light_view(l.position, centre, radius) for l in scene.lights]
    warnings = [f"light {i} lies inside the mesh's bounding sphere: RSM field of view capped, part of the "
                "mesh may receive no injected light" for i, v in enumerate(views) if v.clipped]
    return views, centre, radius, warnings


# ---------------------------------------------------------------- the RSM pass (GL)

def build_program(ctx, warnings):
    """The RSM program; every uniform changes per light, so none is set here."""
    prog = _sh.program(ctx, "rsm.vert", "rsm.frag")
    _sh.check_uniforms(prog, ["u_view_proj", "u_intensity", "u_tan_half", "u_viewport"], "rsm", warnings)
    return prog


def _draw_light(prog, vao, ctx, light, view, viewport):
    prog["u_view_proj"].write(gl_bytes(view.view_proj))
    _sh.set_uniform(prog, "u_intensity", tuple(map(float, light.intensity)))
    _sh.set_uniform(prog, "u_tan_half", (view.tan_half, view.tan_half))
    # rsm.frag measures each texel's solid angle from its position in this light's viewport
    _sh.set_uniform(prog, "u_viewport", tuple(map(float, viewport)))
    vao.render(ctx.TRIANGLES)


def render_maps(ctx, prog, vao, targets, scene, params, views):
    """Injection RSMs (one per light) and the shadow-map atlas.

    ``vao`` draws the mesh with ``prog`` (from :func:`build_program`); ``targets``
    is the renderer's :class:`sslpv_gl.targets.Targets`. Returns ``(maps, shadow)``:
    one ``[position, normal, flux]`` texture list per light, and the shadow-map
    atlas texture (one ``rsm_size``^2 tile per light, side by side).
    """
    ctx.disable(ctx.BLEND)
    ctx.enable(ctx.DEPTH_TEST)
    maps = []
    size = params.inject_size
    for i, (light, view) in enumerate(zip(scene.lights, views)):
        t = targets.get(("rsm", i), (size, size), 3)
        t.fbo.use()
        t.fbo.viewport = (0, 0, size, size)
        t.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        _draw_light(prog, vao, ctx, light, view, (0, 0, size, size))
        maps.append(t.textures)
    return maps, render_shadow_atlas(ctx, prog, vao, targets, scene, params.rsm_size, views)


def set_light_uniforms(prog, scene, views, shadow_size, max_lights):
    """The light uniforms that ``shadow.glsl`` and ``reflection.glsl`` read: position, intensity,
    view-projection and shadow-map texel size at distance 1 of every light (arrays of ``max_lights``),
    and the tile size of the shadow-map atlas. A uniform the compiler optimised away is skipped."""
    pos = np.zeros((max_lights, 3), dtype="f4")
    inten = np.zeros((max_lights, 3), dtype="f4")
    vps = np.tile(np.eye(4), (max_lights, 1, 1))
    texel = np.zeros(max_lights, dtype="f4")
    for i, (light, view) in enumerate(zip(scene.lights, views)):
        pos[i], inten[i], vps[i] = light.position, light.intensity, view.view_proj
        texel[i] = 2.0 * view.tan_half / shadow_size             # shadow-map texel size at distance 1
    for name, data in (("u_light_pos", pos.tobytes()), ("u_light_I", inten.tobytes()),
                       ("u_light_vp", gl_bytes(vps)), ("u_shadow_texel", texel.tobytes())):
        if name in prog:
            prog[name].write(data)
    _sh.set_uniform(prog, "u_shadow_size", int(shadow_size))


def render_shadow_atlas(ctx, prog, vao, targets, scene, size, views, slot="shadow"):
    """The shadow-map atlas: one ``size``^2 tile per light, side by side, holding the world
    position seen from the light (w = valid) -> the texture (``shadow.glsl`` reads it).

    ``prog``/``vao`` as in :func:`render_maps`; also used by the dipole rivals (``dipole_gl``).
    """
    ctx.disable(ctx.BLEND)
    ctx.enable(ctx.DEPTH_TEST)
    s, n = int(size), len(scene.lights)
    shadow = targets.get(slot, (s * n, s), 1)
    shadow.fbo.use()
    shadow.fbo.viewport = (0, 0, s * n, s)
    shadow.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
    for i, (light, view) in enumerate(zip(scene.lights, views)):
        shadow.fbo.viewport = (i * s, 0, s, s)
        _draw_light(prog, vao, ctx, light, view, (i * s, 0, s, s))
    return shadow.textures[0]


def read_texels(maps):
    """The injection RSMs of :func:`render_maps` -> list of ``(M, 10)`` float32, top row first.

    Columns ``[px, py, pz, nx, ny, nz, phi_r, phi_g, phi_b, valid]`` (conventions).
    """
    out = []
    for pos, nrm, flux in maps:
        arrs = [np.frombuffer(t.read(), dtype="f4").reshape(t.height, t.width, 4)[::-1] for t in (pos, nrm, flux)]
        tex = np.concatenate([arrs[0][..., :3], arrs[1][..., :3], arrs[2][..., :3], arrs[0][..., 3:4]], axis=-1)
        out.append(np.ascontiguousarray(tex.reshape(-1, 10), dtype=np.float32))
    return out
