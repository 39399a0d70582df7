"""The atlas gather's frame (``gather = "atlas"``): Carr, Hall & Hart 2003's three GL passes (Sec. 4.2).

Precomputation (host, timed apart from the frame, cached per scene and setting; Sec. 4.2.1): the
multiresolution meshed atlas (``atlas``, :func:`dipole_gl.atlas.build`) and its links (``links``,
:mod:`dipole_gl.links`: ``link_level`` given, the non-adaptive scheme; otherwise the adaptive
one with ``links`` per texel). Frame stages after the renderer's ``shadow``:

* ``irradiance`` (pass 1, Sec. 4.2.2): ``irradiance.comp`` over the texels' surface points (the
  paper's geometry-image variant), ``atlas_radiosity.comp`` into level 0 of the radiosity map;
* ``mipmap``: ``glGenerateMipmap`` of that map (the paper's automatic MIP-mapping): a texel of
  level ``l`` is the mean over its face cluster's block;
* ``gather`` (pass 2, Sec. 4.2.3): ``gather_atlas.comp``, every texel over its links, in chunks of
  :func:`dipole_gl.budget.atlas_chunk` links per dispatch;
* ``shading`` (pass 3, Sec. 4.2.4): ``atlas_shade.vert/frag``, the model with its atlas coordinates,
  ``T(w_o)/pi B`` bilinear at level 0, plus the direct reflection.

Every render recomputes :data:`dipole_gl.check.CHECK_POINTS` pixels with the twin
(:func:`dipole_gl.check.check_atlas`: passes 1-3 at the texels those pixels read).

Refused with one line before any frame work: the directional dipole (its kernel depends on the
light's direction, which a precomputed throughput factor cannot hold); a link table over
:data:`dipole_gl.links.MAX_LINK_BYTES` or the GL's storage block limit (the setting that fits is
named); more triangles than texels, a non-manifold mesh (:mod:`dipole_gl.atlas`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from harness.errors import InputError
from sslpv_gl import shaders as _sh

from . import atlas as atlas_mod
from . import budget, check, gbuffer, irradiance
from . import links as links_mod
from .glsl import DIRS
from .tree_gather import storage_limit
from .twin import exit_coefficients

__all__ = ["AtlasData", "atlas_data", "render", "build_radiosity", "build_gather", "build_shade", "STAGES"]

STAGES = ("shadow", "irradiance", "mipmap", "gather", "shading", "gbuffer", "single")
LOCAL = 8


def build_radiosity(ctx, warnings):
    prog = _sh.compute(ctx, "atlas_radiosity.comp", {}, dirs=DIRS)
    _sh.check_uniforms(prog, ["u_n"], "atlas_radiosity", warnings)
    return prog


def build_gather(ctx, warnings):
    prog = _sh.compute(ctx, "gather_atlas.comp", {}, dirs=DIRS)
    _sh.check_uniforms(prog, ["u_n", "u_slots", "u_first", "u_end", "u_last", "u_radiosity"], "gather_atlas",
                       warnings)
    if "u_radiosity" in prog:
        prog["u_radiosity"].value = 0
    return prog


def build_shade(ctx, warnings):
    prog = gbuffer.camera_program(ctx, "atlas_shade.vert", "atlas_shade.frag", "atlas_shade", warnings)
    if "u_scatter" in prog:
        prog["u_scatter"].value = 1
    return prog


@dataclass
class AtlasData:
    atlas: atlas_mod.Atlas
    links: links_mod.Links
    points: irradiance.PointBuffers
    node_buf: object
    g_buf: object
    accum: object
    radiosity: object
    scatter: object
    vbo: object
    atlas_ms: float
    links_ms: float

    def release(self):
        self.points.release()
        for obj in (self.node_buf, self.g_buf, self.accum, self.radiosity, self.scatter, self.vbo):
            obj.release()


def atlas_data(renderer, scene, mat, params):
    """The atlas, its links and their GPU objects, cached per scene and setting."""
    ctx = renderer.ctx
    c = renderer._cache(scene)
    key = ("atlas", params.atlas_size, params.links, params.link_level)
    if key not in c:
        N = params.atlas_size
        links_mod.check_table(N, params.links, params.link_level, storage_limit(ctx))
        t0 = time.perf_counter()
        at = atlas_mod.build(scene.mesh, N)
        t1 = time.perf_counter()
        blk = links_mod.blocks(at)
        P = at.texels
        m = exit_coefficients(mat, at.position.reshape(P, 3), at.normal.reshape(P, 3), float(scene.boundary.eta))
        lk = (links_mod.non_adaptive(at, blk, m, params.link_level) if params.link_level is not None
              else links_mod.adaptive(at, blk, m, params.links))
        t2 = time.perf_counter()
        points = irradiance.PointBuffers(ctx, at.position.reshape(P, 3), at.normal.reshape(P, 3), at.area.reshape(P),
                                         len(scene.lights))
        g4 = np.concatenate([lk.g, np.zeros(lk.g.shape[:2] + (1,))], axis=-1).astype("f4")
        radiosity = ctx.texture((N, N), 4, dtype="f4")
        radiosity.build_mipmaps(0, at.levels - 1)
        radiosity.filter = (ctx.NEAREST_MIPMAP_NEAREST, ctx.NEAREST)
        scatter = ctx.texture((N, N), 4, dtype="f4")
        scatter.filter = (ctx.LINEAR, ctx.LINEAR)
        scatter.repeat_x = scatter.repeat_y = False
        F = np.asarray(scene.mesh.faces)
        rect = np.repeat(at.face_rect[:, None], 3, axis=1)
        corner = np.concatenate([scene.mesh.vertices[F], scene.mesh.normals[F], at.uv, rect], axis=-1).astype("f4")
        c[key] = AtlasData(at, lk, points, ctx.buffer(np.ascontiguousarray(lk.node, "i4").tobytes()),
                           ctx.buffer(g4.tobytes()), ctx.buffer(reserve=P * 16), radiosity, scatter,
                           ctx.buffer(corner.tobytes()), (t1 - t0) * 1e3, (t2 - t1) * 1e3)
    return c[key]


def run_passes(renderer, data, scene, views, shadow_tex, shadow_size, timer):
    """Passes 1 and 2 -> the gather's dispatches."""
    ctx, at, N = renderer.ctx, data.atlas, data.atlas.size
    groups = ((N + LOCAL - 1) // LOCAL, (N + LOCAL - 1) // LOCAL)
    with timer.stage("irradiance"):
        irradiance.run(renderer._program(("irradiance",)), data.points, scene, views, shadow_tex, shadow_size)
        ctx.memory_barrier()
        prog = renderer._program(("atlas_radiosity",))
        data.points.total.bind_to_storage_buffer(4)
        data.radiosity.bind_to_image(0, read=False, write=True, level=0)
        _sh.set_uniform(prog, "u_n", N)
        prog.run(*groups)
        ctx.memory_barrier()
    with timer.stage("mipmap"):
        data.radiosity.build_mipmaps(0, at.levels - 1)
        data.radiosity.filter = (ctx.NEAREST_MIPMAP_NEAREST, ctx.NEAREST)
    pieces = budget.chunks(data.links.slots, budget.atlas_chunk())
    with timer.stage("gather"):
        prog = renderer._program(("atlas_gather",))
        data.node_buf.bind_to_storage_buffer(0)
        data.g_buf.bind_to_storage_buffer(1)
        data.accum.bind_to_storage_buffer(2)
        data.radiosity.use(0)
        data.scatter.bind_to_image(0, read=False, write=True)
        _sh.set_uniform(prog, "u_n", N)
        _sh.set_uniform(prog, "u_slots", data.links.slots)
        for i, (first, end) in enumerate(pieces):
            _sh.set_uniform(prog, "u_first", first)
            _sh.set_uniform(prog, "u_end", end)
            _sh.set_uniform(prog, "u_last", int(i == len(pieces) - 1))
            prog.run(*groups)
            ctx.memory_barrier()
    return len(pieces)


def render(renderer, scene, kernel, params, mat, views, shadow_tex, centre, radius, timer, work, info, pre_ms,
           pre_work, dbg):
    """One frame of the atlas gather -> ``(subsurface, full, mask, out)``: (H, W, 4) images, the pass-3 target."""
    if kernel != "dipole":
        raise InputError("--gather", "gather", "the atlas gather precomputes throughput factors of the standard "
                         "dipole R_d(r) (Carr et al. 2003, Eq. 10); the directional dipole depends on the light's "
                         "direction", "use --method dipole, or another gather for dirpole")
    ctx = renderer.ctx
    cam = scene.camera
    L, W, H, s = len(scene.lights), cam.width, cam.height, params.shadow_size
    data = atlas_data(renderer, scene, mat, params)
    at, lk, N = data.atlas, data.links, data.atlas.size
    pre_ms.update(atlas=data.atlas_ms, links=data.links_ms)
    pre_work.update(atlas=at.texels, links=int(lk.count.sum()))
    dispatches = run_passes(renderer, data, scene, views, shadow_tex, s, timer)
    out = renderer._targets.get("dipole_atlas_out", (W, H), 4)
    with timer.stage("shading"):
        prog = renderer._program(("atlas_shade",))
        data.scatter.use(1)
        vao = renderer._cache(scene).get(("vao", "atlas", N))
        if vao is None:
            vao = ctx.vertex_array(prog, [(data.vbo, "3f 3f 2f 4f", "in_pos", "in_nrm", "in_uv", "in_rect")])
            renderer._cache(scene)[("vao", "atlas", N)] = vao
        gbuffer.camera_pass(ctx, prog, vao, out, scene, views, shadow_tex, s, centre, radius)
    full = gbuffer.read(out.textures[0], W, H)
    sub = gbuffer.read(out.textures[1], W, H)
    pos_u, nrm_v = gbuffer.read(out.textures[2], W, H), gbuffer.read(out.textures[3], W, H)
    mask = sub[..., 3] > 0.5
    flux = data.points.read_flux()
    frag = {"position": pos_u[..., :3], "normal": nrm_v[..., :3], "uv": np.stack([pos_u[..., 3], nrm_v[..., 3]], -1),
            "mask": mask}
    info["check"] = check.check_atlas(scene, at, lk, flux, frag, sub[..., :3])
    work.update(irradiance=at.texels * L, mipmap=at.texels // 3, gather=int(lk.count.sum()), shading=W * H)
    info.update(atlas_size=N, texels=at.texels, patches=int((at.area > 0).sum()), link_slots=lk.slots,
                links_per_texel=float(lk.count.mean()), adaptive=lk.adaptive, dispatches=dispatches,
                disconnected_clusters=at.disconnected, not_disc_clusters=at.not_disc)
    if dbg is not None:
        dbg.update(atlas=at, links=lk, flux=flux, fragments=frag,
                   radiosity=[read_level(data.radiosity, N >> lv, lv) for lv in range(at.levels)],
                   scatter=read_level(data.scatter, N, 0))
    return sub, full, mask, out


def read_level(tex, n, level):
    """A level of an atlas texture as (n, n, 3) float32, ``[v, u]`` (row 0 is v = 0, as the atlas arrays)."""
    return np.frombuffer(tex.read(level=level), dtype="f4").reshape(n, n, 4)[..., :3]
