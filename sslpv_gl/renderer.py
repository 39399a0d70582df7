"""GLSL SSLPV renderer (Borlum et al., "Subsurface Light Propagation Volumes", HPG 2011).

``SSLPVRenderer(ctx=None).render(scene, params) -> RenderResult`` runs the
paper's four stages on an OpenGL 4.3 context (headless EGL; llvmpipe works):

.. list-table::
   :header-rows: 1

   * - stage
     - paper
     - shaders
     - what
   * - RSM
     - Sec. 3.1
     - ``rsm.vert/frag``
     - per light: injection RSM (``inject_size``^2: position, normal,
       ``Phi_p = I dOmega_p``) and shadow map (``rsm_size``^2), same frustum
   * - injection
     - Sec. 3.1, Eq. 1
     - ``inject.vert/frag``, ``unflatten.comp``
     - one point per RSM texel, refracted clamped-cosine lobe times
       ``(1/pi) T Phi_p``, summed per cell by additive blending
   * - propagation
     - Sec. 3.2, Eq. 3, Sec. 4
     - ``propagate.comp``
     - six-neighbour gather with ``sh.propagation_matrices()``, Beer
       attenuation, Eq. 3 scattering of the SOURCE cell, ping-pong,
       accumulation of steps ``k > skip``
   * - shading
     - Sec. 3.3, Eqs. 4-7
     - ``shade.vert/frag``
     - area-light radiance from the accumulation grid (times ``1/eta^2``
       with ``params.eta2``; not in the paper), plus GGX reflection of each
       light (shadow-mapped) for a dielectric boundary

Parameters are :class:`sslpv_gl.params.SSLPVParams` (defaults in one place).

Injection, why a 2D atlas
-------------------------
Eq. 1 sums the lobes of all texels that fall into a cell. Float atomics are
not core GL, and a gather over all texels per cell costs ``N^3 M``. Points
rasterised with additive blending (``ONE, ONE``) are summed in primitive order
(GL's blending order guarantee), so the sum is deterministic. moderngl cannot
attach one layer of a 3D texture to a framebuffer, so the grid is flattened
into a 2D atlas of ``N x N`` tiles (z slice ``k`` at tile ``(k % tx, k // tx)``,
``tx = ceil(sqrt(N))``, at most 4096^2 for ``N = 256``) with three RGBA32F
attachments (R, G, B, four coefficients each); ``unflatten.comp`` copies it into
the first propagation grid. The atlas is always fp32; ``precision`` applies to
the propagation and accumulation grids (the paper stores 16-bit floats).

Limits
------
* At most :data:`MAX_LIGHTS` point lights; cubic LPV cells.
* Direct reflection is the GGX reflection half of a rough dielectric; the
  smooth limit (roughness 0) is not representable with point lights.
* The medium outside the mesh follows ``params.outside``.
"""

from __future__ import annotations

import contextlib
import math
import time
from dataclasses import dataclass, field

import numpy as np

from harness.errors import InputError
from harness.scene.geometry import grid_inside

from . import shaders as _sh
from .material import lpv_material
from .params import SSLPVParams
from .rsm import bounding_sphere, camera_view_proj, gl_bytes, light_view
from .sh import propagation_matrices

__all__ = ["SSLPVRenderer", "RenderResult", "MAX_LIGHTS", "LOCAL_SIZE"]

MAX_LIGHTS = 8
LOCAL_SIZE = 8          # compute work-group edge: 8^3 measured ~25 % faster than 4^3 on llvmpipe
_FORMATS = {"fp32": ("rgba32f", "f4", np.float32), "fp16": ("rgba16f", "f2", np.float16)}
_ACC_NONE, _ACC_FIRST, _ACC_ADD = 0, 1, 2
_QUERY_INVALID = 0xFFFFFFFF      # what llvmpipe returns for an unavailable time query


def _gpu_ms(query_ns, wall_ns, stage, warnings):
    """GL time of one stage in ms.

    moderngl reads GL_TIME_ELAPSED as an unsigned 32-bit value, which saturates at
    0xFFFFFFFF ns (4.29 s; llvmpipe also answers that for a query it could not time).
    A saturated query of a stage whose host time (between two ``finish`` calls)
    exceeds 4.29 s is replaced by that host time, with a warning; otherwise NaN.
    """
    if query_ns < _QUERY_INVALID:
        return query_ns / 1e6
    if wall_ns >= _QUERY_INVALID:
        warnings.append(f"GL timer query for '{stage}' saturated at 4.29 s; the host time between glFinish "
                        "calls is reported instead")
        return wall_ns / 1e6
    warnings.append(f"GL timer query for '{stage}' returned no valid value ({query_ns} ns)")
    return float("nan")


@dataclass
class RenderResult:
    full: np.ndarray                 # (H, W, 3) float32, row 0 at the top: subsurface + reflection
    subsurface: np.ndarray           # (H, W, 3) float32
    mask: np.ndarray                 # (H, W) bool: pixel covered by the mesh
    timings_ms: dict                 # rsm, injection, propagation, shading (GL timer queries) + host
    gl_renderer: str
    warnings: list = field(default_factory=list)
    position: np.ndarray | None = None   # (H, W, 3) world position used for shading (debug)
    normal: np.ndarray | None = None     # (H, W, 3) unit normal used for shading (debug)


class _GridSet:
    """GL objects for one (N, precision): ping-pong, accumulation, material, injection atlas."""

    def __init__(self, ctx, N, precision):
        _, dt, _ = _FORMATS[precision]
        self.N = N

        def tex3(dtype):
            t = ctx.texture3d((N, N, N), 4, dtype=dtype)
            t.filter = (_nearest(), _nearest())
            t.repeat_x = t.repeat_y = t.repeat_z = False
            return t

        self.prop_a = [tex3(dt) for _ in range(3)]
        self.prop_b = [tex3(dt) for _ in range(3)]
        self.accum = [tex3(dt) for _ in range(3)]
        self.material = [tex3("f4") for _ in range(2)]      # h = exp(-sigma_lpv dx / 2), h * k1 (Eq. 3)
        self.tiles_x = int(math.ceil(math.sqrt(N)))
        tiles_y = int(math.ceil(N / self.tiles_x))
        self.atlas_size = (self.tiles_x * N, tiles_y * N)
        self.atlas = [ctx.texture(self.atlas_size, 4, dtype="f4") for _ in range(3)]
        for t in self.atlas:
            t.filter = (_nearest(), _nearest())
        self.atlas_fbo = ctx.framebuffer(color_attachments=self.atlas)
        self.groups = (int(math.ceil(N / LOCAL_SIZE)),) * 3


def _nearest():
    import moderngl
    return moderngl.NEAREST


class SSLPVRenderer:
    """See the module docstring. ``ctx`` defaults to :func:`sslpv_gl.context.create_context`."""

    def __init__(self, ctx=None):
        import moderngl

        from .context import create_context

        self._mgl = moderngl
        self.ctx = ctx if ctx is not None else create_context()
        self.gl_renderer = str(self.ctx.info.get("GL_RENDERER", "unknown"))
        self.warnings = []               # uniforms optimised away, collected once per program
        self._programs = {}
        self._grids = {}
        self._rsm_targets = {}
        self._shadow = {}
        self._shade_fbo = {}
        self._meshes = {}
        self._material_cache = {}
        self._mats_bytes = gl_bytes(propagation_matrices())    # (6,4,4) -> 6 column-major mat4
        # Mesa llvmpipe answers the first GL_TIME_ELAPSED query of a context with
        # 0xFFFFFFFF ns (measured here); spend that one on a 1x1 clear.
        warm_fbo = self.ctx.simple_framebuffer((1, 1))
        warm = self.ctx.query(time=True)
        with warm:
            warm_fbo.use()
            warm_fbo.clear(0.0, 0.0, 0.0, 0.0)
        _ = warm.elapsed
        warm_fbo.release()

    # ------------------------------------------------------------ programs

    def _program(self, key):
        """Programs are built lazily once per variant; constant uniforms are set here."""
        prog = self._programs.get(key)
        if prog is not None:
            return prog
        kind = key[0]
        ctx, warn = self.ctx, self.warnings
        if kind == "rsm":
            prog = _sh.program(ctx, "rsm.vert", "rsm.frag")
            _sh.check_uniforms(prog, ["u_view_proj", "u_intensity", "u_tan_half", "u_viewport"], "rsm", warn)
        elif kind == "inject":
            prog = _sh.program(ctx, "inject.vert", "inject.frag")
            names = ["u_pos", "u_nrm", "u_flux", "u_width", "u_light", "u_bbox_min", "u_dx", "u_N",
                     "u_eta", "u_offset", "u_tiles_x", "u_atlas_size"]
            present = _sh.check_uniforms(prog, names, "inject", warn)
            for unit, name in enumerate(("u_pos", "u_nrm", "u_flux")):
                if name in present:
                    prog[name].value = unit
        elif kind == "unflatten":
            fmt = _FORMATS[key[1]][0]
            prog = _sh.compute(ctx, "unflatten.comp", {"FORMAT": fmt, "LOCAL": LOCAL_SIZE})
            names = ["u_atlas_r", "u_atlas_g", "u_atlas_b", "u_N", "u_tiles_x", "u_dst_r", "u_dst_g", "u_dst_b"]
            present = _sh.check_uniforms(prog, names, "unflatten", warn)
            for unit, name in enumerate(names[:3]):
                if name in present:
                    prog[name].value = unit
        elif kind == "propagate":
            fmt, acc = _FORMATS[key[1]][0], key[2]
            prog = _sh.compute(ctx, "propagate.comp", {"FORMAT": fmt, "LOCAL": LOCAL_SIZE, "ACCUMULATE": acc})
            samplers = ["u_src_r", "u_src_g", "u_src_b", "u_half", "u_hk1"]
            images = ["u_dst_r", "u_dst_g", "u_dst_b"] + (["u_acc_r", "u_acc_g", "u_acc_b"] if acc else [])
            present = _sh.check_uniforms(prog, samplers + images + ["u_M", "u_N"],
                                         f"propagate[{key[1]},acc={acc}]", warn)
            for unit, name in enumerate(samplers):
                if name in present:
                    prog[name].value = unit
            if "u_M" in present:
                prog["u_M"].write(self._mats_bytes)
        elif kind == "shade":
            lookup = key[1]
            prog = _sh.program(ctx, "shade.vert", "shade.frag",
                               {"LOOKUP_TRILINEAR": int(lookup == "trilinear"), "MAX_LIGHTS": MAX_LIGHTS})
            names = ["u_view_proj", "u_acc_r", "u_acc_g", "u_acc_b", "u_bbox_min", "u_bbox_size", "u_N",
                     "u_area", "u_eta", "u_sub_scale", "u_alpha", "u_cam_pos", "u_n_lights", "u_light_pos", "u_light_I",
                     "u_light_vp", "u_shadow", "u_shadow_size", "u_shadow_texel"]
            if lookup == "trilinear":
                names.remove("u_N")                     # only the cell lookup needs N
            present = _sh.check_uniforms(prog, names, f"shade[{lookup}]", warn)
            for unit, name in enumerate(("u_acc_r", "u_acc_g", "u_acc_b", "u_shadow")):
                if name in present:
                    prog[name].value = unit
        else:  # pragma: no cover
            raise KeyError(key)
        self._programs[key] = prog
        return prog

    @staticmethod
    def _set(prog, name, value):
        if name in prog:                 # absence was reported once in check_uniforms
            prog[name].value = value

    # ------------------------------------------------------------ resources

    def _grid(self, N, precision):
        key = (N, precision)
        if key not in self._grids:
            self._grids[key] = _GridSet(self.ctx, N, precision)
        return self._grids[key]

    def _mesh(self, scene):
        key = scene.content_hash or id(scene)
        m = self._meshes.get(key)
        if m is None:
            mesh = scene.mesh
            data = np.hstack([mesh.vertices, mesh.normals]).astype("f4")
            vbo = self.ctx.buffer(data.tobytes())
            ibo = self.ctx.buffer(np.asarray(mesh.faces, dtype="i4").tobytes())
            m = {"vbo": vbo, "ibo": ibo, "vaos": {}}
            self._meshes = {key: m}                       # keep one mesh
        return m

    def _mesh_vao(self, scene, prog, key):
        m = self._mesh(scene)
        vao = m["vaos"].get(key)
        if vao is None:
            vao = self.ctx.vertex_array(prog, [(m["vbo"], "3f 3f", "in_pos", "in_nrm")], index_buffer=m["ibo"],
                                        index_element_size=4)
            m["vaos"][key] = vao
        return vao

    def _rsm_target(self, size, index):
        key = (size, index)
        t = self._rsm_targets.get(key)
        if t is None:
            texs = [self.ctx.texture((size, size), 4, dtype="f4") for _ in range(3)]
            for tex in texs:
                tex.filter = (_nearest(), _nearest())
            depth = self.ctx.depth_renderbuffer((size, size))
            t = (texs, self.ctx.framebuffer(color_attachments=texs, depth_attachment=depth))
            self._rsm_targets[key] = t
        return t

    def _shadow_target(self, size, n_lights):
        key = (size, n_lights)
        t = self._shadow.get(key)
        if t is None:
            tex = self.ctx.texture((size * n_lights, size), 4, dtype="f4")
            tex.filter = (_nearest(), _nearest())
            depth = self.ctx.depth_renderbuffer((size * n_lights, size))
            t = (tex, self.ctx.framebuffer(color_attachments=[tex], depth_attachment=depth))
            self._shadow = {key: t}
        return t

    def _shade_target(self, w, h):
        key = (w, h)
        t = self._shade_fbo.get(key)
        if t is None:
            texs = [self.ctx.texture((w, h), 4, dtype="f4") for _ in range(4)]
            t = self.ctx.framebuffer(color_attachments=texs, depth_attachment=self.ctx.depth_renderbuffer((w, h)))
            self._shade_fbo = {key: t}
        return t

    # ------------------------------------------------------------ inputs

    def _check_scene(self, scene):
        n = len(scene.lights)
        if n > MAX_LIGHTS:
            raise InputError(scene.path, "lights", f"{n} point lights, the GL renderer supports at most {MAX_LIGHTS}",
                             "remove lights or raise MAX_LIGHTS")

    def lpv_material(self, scene, params):
        """Per-cell LPV material for the scene (cached per scene hash and material settings)."""
        key = (scene.content_hash, params.N, params.mapping, params.resample, params.outside)
        mat = self._material_cache.get(key)
        if mat is None:
            med = scene.medium
            inside = grid_inside(scene.mesh, med.bbox_min, med.bbox_max, params.N)
            mat = lpv_material(med, inside, params.N, params.mapping, params.resample, params.outside)
            # A few entries: a sweep worker interleaves mappings and step counts of one grid.
            if len(self._material_cache) >= 8:
                self._material_cache.pop(next(iter(self._material_cache)))
            self._material_cache[key] = mat
        return mat

    def _upload_material(self, grid, material, dx):
        # Per-cell factors of the transfer rule, formed once here instead of per step
        # and neighbour: h = exp(-sigma dx / 2), half a cell of absorption (Sec. 3.2.1),
        # and h * k1 with Eq. 3's band-1 factor k1 = (1 - sp) + sp g of the source.
        N = grid.N
        sp = np.asarray(material["sigma_s_prime"], dtype=np.float64).reshape(N, N, N, 3)
        k1 = (1.0 - sp) + sp * np.asarray(material["g"], dtype=np.float64).reshape(N, N, N, 3)
        sigma = np.asarray(material["sigma_lpv"], dtype=np.float64).reshape(N, N, N, 3)
        half = np.exp(-0.5 * sigma * float(dx))
        for tex, arr in zip(grid.material, (half, half * k1)):
            a = np.zeros((N, N, N, 4), dtype=np.float32)
            a[..., :3] = arr
            tex.write(a.tobytes())

    # ------------------------------------------------------------ stage 1: RSM (Sec. 3.1)

    def _render_rsm(self, scene, params, views):
        """Injection RSMs (one per light) and the shadow-map atlas."""
        mgl, ctx = self._mgl, self.ctx
        prog = self._program(("rsm",))
        vao = self._mesh_vao(scene, prog, "rsm")
        ctx.disable(mgl.BLEND)
        ctx.enable(mgl.DEPTH_TEST)
        targets = []
        size = params.inject_size
        for i, (light, view) in enumerate(zip(scene.lights, views)):
            texs, fbo = self._rsm_target(size, i)
            fbo.use()
            fbo.viewport = (0, 0, size, size)
            fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
            prog["u_view_proj"].write(gl_bytes(view.view_proj))
            self._set(prog, "u_intensity", tuple(map(float, light.intensity)))
            self._set(prog, "u_tan_half", (view.tan_half, view.tan_half))
            self._set(prog, "u_viewport", (0.0, 0.0, float(size), float(size)))
            vao.render(mgl.TRIANGLES)
            targets.append(texs)
        s = params.rsm_size
        shadow_tex, shadow_fbo = self._shadow_target(s, len(scene.lights))
        shadow_fbo.use()
        shadow_fbo.viewport = (0, 0, s * len(scene.lights), s)
        shadow_fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        for i, (light, view) in enumerate(zip(scene.lights, views)):
            shadow_fbo.viewport = (i * s, 0, s, s)
            prog["u_view_proj"].write(gl_bytes(view.view_proj))
            self._set(prog, "u_intensity", tuple(map(float, light.intensity)))
            self._set(prog, "u_tan_half", (view.tan_half, view.tan_half))
            self._set(prog, "u_viewport", (float(i * s), 0.0, float(s), float(s)))
            vao.render(mgl.TRIANGLES)
        return targets, shadow_tex

    def _views(self, scene):
        centre, radius = bounding_sphere(scene.mesh)
        views = [light_view(l.position, centre, radius) for l in scene.lights]
        warnings = [f"light {i} lies inside the mesh's bounding sphere: RSM field of view capped, part of the "
                    "mesh may receive no injected light" for i, v in enumerate(views) if v.clipped]
        return views, centre, radius, warnings

    def rsm_texels(self, scene, params=None):
        """Injection-resolution RSM of each light read back -> list of (M, 10) float32, top row first.

        Columns ``[px, py, pz, nx, ny, nz, phi_r, phi_g, phi_b, valid]`` (conventions).
        """
        params = params or SSLPVParams()
        self._check_scene(scene)
        views, _, _, _ = self._views(scene)
        targets, _ = self._render_rsm(scene, params, views)
        out = []
        for pos, nrm, flux in targets:
            arrs = [np.frombuffer(t.read(), dtype="f4").reshape(t.height, t.width, 4)[::-1] for t in (pos, nrm, flux)]
            tex = np.concatenate([arrs[0][..., :3], arrs[1][..., :3], arrs[2][..., :3], arrs[0][..., 3:4]], axis=-1)
            out.append(np.ascontiguousarray(tex.reshape(-1, 10), dtype=np.float32))
        return out

    # ------------------------------------------------------------ stage 2: injection (Sec. 3.1, Eq. 1)

    def _inject(self, grid, sources, bbox_min, bbox_max, eta, offset, dst):
        """``sources``: list of ((pos, nrm, flux) textures, texel count, light position)."""
        mgl, ctx = self._mgl, self.ctx
        N = grid.N
        prog = self._program(("inject",))
        vao = self._programs.get(("inject_vao",))
        if vao is None:
            vao = ctx.vertex_array(prog, [])
            self._programs[("inject_vao",)] = vao
        grid.atlas_fbo.use()
        grid.atlas_fbo.viewport = (0, 0) + grid.atlas_size
        grid.atlas_fbo.clear(0.0, 0.0, 0.0, 0.0)
        ctx.disable(mgl.DEPTH_TEST)
        ctx.enable(mgl.BLEND)
        ctx.enable(mgl.PROGRAM_POINT_SIZE)
        ctx.blend_func = mgl.ONE, mgl.ONE
        ctx.blend_equation = mgl.FUNC_ADD
        bmin = np.asarray(bbox_min, dtype=np.float64)
        dx = (np.asarray(bbox_max, dtype=np.float64) - bmin) / N
        self._set(prog, "u_bbox_min", tuple(map(float, bmin)))
        self._set(prog, "u_dx", tuple(map(float, dx)))
        self._set(prog, "u_N", N)
        self._set(prog, "u_eta", float(eta))
        self._set(prog, "u_offset", float(offset))
        self._set(prog, "u_tiles_x", grid.tiles_x)
        self._set(prog, "u_atlas_size", tuple(map(float, grid.atlas_size)))
        for texs, count, light_pos in sources:
            for unit, t in enumerate(texs):
                t.use(unit)
            self._set(prog, "u_width", texs[0].width)
            self._set(prog, "u_light", tuple(map(float, light_pos)))
            vao.render(mgl.POINTS, vertices=int(count))
        ctx.disable(mgl.BLEND)
        # ---- atlas -> 3D grid
        unf = self._program(("unflatten", self._precision_of(grid)))
        self._set(unf, "u_N", N)
        self._set(unf, "u_tiles_x", grid.tiles_x)
        for unit, t in enumerate(grid.atlas):
            t.use(unit)
        for unit, t in enumerate(dst):
            t.bind_to_image(unit, read=False, write=True)
        unf.run(*grid.groups)
        ctx.memory_barrier()

    def _precision_of(self, grid):
        for (N, prec), g in self._grids.items():
            if g is grid:
                return prec
        raise KeyError("unknown grid")  # pragma: no cover

    def inject(self, texels_list, light_positions, scene, params=None):
        """GL injection of given RSM texels (one (M,10) array per light) -> (N,N,N,3,4) float32."""
        params = params or SSLPVParams()
        grid = self._grid(params.N, params.precision)
        sources = []
        for i, (texels, lp) in enumerate(zip(texels_list, light_positions)):
            tex = np.asarray(texels, dtype=np.float32).reshape(-1, 10)
            m = tex.shape[0]
            width = 256
            height = max(1, int(math.ceil(m / width)))
            pad = np.zeros((width * height, 10), dtype=np.float32)
            pad[:m] = tex
            img = pad.reshape(height, width, 10)
            parts = []
            for cols, w in ((slice(0, 3), img[..., 9:10]), (slice(3, 6), None), (slice(6, 9), None)):
                a = np.zeros((height, width, 4), dtype=np.float32)
                a[..., :3] = img[..., cols]
                if w is not None:
                    a[..., 3:4] = w
                t = self.ctx.texture((width, height), 4, data=a.tobytes(), dtype="f4")
                t.filter = (_nearest(), _nearest())
                parts.append(t)
            sources.append((parts, m, lp))
        med = scene.medium
        self._inject(grid, sources, med.bbox_min, med.bbox_max, scene.boundary.eta, params.inject_offset, grid.prop_a)
        for parts, _, _ in sources:
            for t in parts:
                t.release()
        return self._read_grid(grid.prop_a, params.precision)

    # ------------------------------------------------------------ stage 3: propagation (Sec. 3.2, Sec. 4)

    def _propagate(self, grid, precision, dx, steps, skip):
        """Run ``steps`` steps from ``grid.prop_a``; returns the textures holding the final grid."""
        ctx = self.ctx
        progs = {acc: self._program(("propagate", precision, acc)) for acc in (_ACC_NONE, _ACC_FIRST, _ACC_ADD)}
        for prog in progs.values():
            self._set(prog, "u_N", grid.N)
        for unit, t in enumerate(grid.material):
            t.use(3 + unit)
        if steps <= skip:                                   # nothing accumulated
            zero = np.zeros(grid.N ** 3 * 4, dtype=_FORMATS[precision][2]).tobytes()
            for t in grid.accum:
                t.write(zero)
        for unit, t in enumerate(grid.accum):
            t.bind_to_image(3 + unit, read=True, write=True)
        src, dst = grid.prop_a, grid.prop_b
        for step in range(1, steps + 1):
            acc = _ACC_NONE if step <= skip else (_ACC_FIRST if step == skip + 1 else _ACC_ADD)
            for unit, t in enumerate(src):
                t.use(unit)
            for unit, t in enumerate(dst):
                t.bind_to_image(unit, read=False, write=True)
            progs[acc].run(*grid.groups)
            ctx.memory_barrier()
            src, dst = dst, src                             # ping-pong
        return src

    def propagate(self, c0, material, dx, steps, skip=2, precision="fp32"):
        """GL propagation of ``c0`` (N,N,N,3,4) with a material dict -> ``(prop, accum)`` float32."""
        c0 = np.asarray(c0, dtype=np.float32)
        N = c0.shape[0]
        SSLPVParams(N=N, steps=int(steps), skip=int(skip), precision=precision)   # validates
        grid = self._grid(N, precision)
        self._upload_material(grid, material, dx)
        self._write_grid(grid.prop_a, c0, precision)
        final = self._propagate(grid, precision, dx, int(steps), int(skip))
        return self._read_grid(final, precision), self._read_grid(grid.accum, precision)

    def read_accumulation(self, params):
        """The accumulation grid of the last render/propagate with ``params.N``/``precision`` -> (N,N,N,3,4)."""
        return self._read_grid(self._grid(params.N, params.precision).accum, params.precision)

    def _write_grid(self, texs, c, precision):
        dtype = _FORMATS[precision][2]
        for col, t in enumerate(texs):
            t.write(np.ascontiguousarray(c[..., col, :], dtype=dtype).tobytes())

    def _read_grid(self, texs, precision):
        dtype = _FORMATS[precision][2]
        N = texs[0].width
        cols = [np.frombuffer(t.read(), dtype=dtype).reshape(N, N, N, 4) for t in texs]
        return np.stack(cols, axis=3).astype(np.float32)

    # ------------------------------------------------------------ stage 4: shading (Sec. 3.3)

    def _shade(self, scene, params, grid, views, shadow_tex, centre, radius):
        mgl, ctx = self._mgl, self.ctx
        cam = scene.camera
        prog = self._program(("shade", params.lookup))
        vao = self._mesh_vao(scene, prog, ("shade", params.lookup))
        fbo = self._shade_target(cam.width, cam.height)
        fbo.use()
        fbo.viewport = (0, 0, cam.width, cam.height)
        fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        ctx.disable(mgl.BLEND)
        ctx.enable(mgl.DEPTH_TEST)
        filt = mgl.LINEAR if params.lookup == "trilinear" else mgl.NEAREST
        for unit, t in enumerate(grid.accum):
            t.filter = (filt, filt)
            t.use(unit)
        shadow_tex.use(3)
        med, b = scene.medium, scene.boundary
        bmin = np.asarray(med.bbox_min, dtype=np.float64)
        size = np.asarray(med.bbox_max, dtype=np.float64) - bmin
        dx = float(size[0] / params.N)
        prog["u_view_proj"].write(gl_bytes(camera_view_proj(cam, centre, radius)))
        self._set(prog, "u_bbox_min", tuple(map(float, bmin)))
        self._set(prog, "u_bbox_size", tuple(map(float, size)))
        self._set(prog, "u_N", params.N)
        self._set(prog, "u_area", dx * dx)
        self._set(prog, "u_eta", float(b.eta))
        self._set(prog, "u_sub_scale", 1.0 / (float(b.eta) ** 2) if params.eta2 else 1.0)
        self._set(prog, "u_alpha", float(b.roughness))
        self._set(prog, "u_cam_pos", tuple(map(float, cam.origin)))
        n = len(scene.lights)
        self._set(prog, "u_n_lights", 0 if b.index_matched else n)
        pos = np.zeros((MAX_LIGHTS, 3), dtype="f4")
        inten = np.zeros((MAX_LIGHTS, 3), dtype="f4")
        vps = np.tile(np.eye(4), (MAX_LIGHTS, 1, 1))
        texel = np.zeros(MAX_LIGHTS, dtype="f4")
        for i, (light, view) in enumerate(zip(scene.lights, views)):
            pos[i], inten[i], vps[i] = light.position, light.intensity, view.view_proj
            texel[i] = 2.0 * view.tan_half / params.rsm_size
        for name, data in (("u_light_pos", pos.tobytes()), ("u_light_I", inten.tobytes()),
                           ("u_light_vp", gl_bytes(vps)), ("u_shadow_texel", texel.tobytes())):
            if name in prog:
                prog[name].write(data)
        self._set(prog, "u_shadow_size", params.rsm_size)
        vao.render(mgl.TRIANGLES)
        return fbo

    # ------------------------------------------------------------ front door

    def render(self, scene, params=None):
        """Render ``scene`` with SSLPV -> :class:`RenderResult` (images top row first)."""
        params = params or SSLPVParams()
        if not isinstance(params, SSLPVParams):
            raise TypeError("params must be an SSLPVParams")
        self._check_scene(scene)
        ctx = self.ctx
        t_wall = time.perf_counter()
        warnings = []
        t0 = time.perf_counter()
        material = self.lpv_material(scene, params)
        views, centre, radius, w = self._views(scene)
        warnings += w
        grid = self._grid(params.N, params.precision)
        med = scene.medium
        dx = float((np.asarray(med.bbox_max, float) - np.asarray(med.bbox_min, float))[0] / params.N)
        self._upload_material(grid, material, dx)
        host_ms = (time.perf_counter() - t0) * 1e3
        queries = {k: ctx.query(time=True) for k in ("rsm", "injection", "propagation", "shading")}

        stage_wall = {}

        @contextlib.contextmanager
        def stage(name):
            # A host clock around each stage (after a finish) beside the GL timer query:
            # moderngl reads GL_TIME_ELAPSED as 32 bits, which wraps after 4.29 s.
            ctx.finish()
            t = time.perf_counter_ns()
            with queries[name]:
                yield
            ctx.finish()
            stage_wall[name] = time.perf_counter_ns() - t

        with stage("rsm"):
            targets, shadow_tex = self._render_rsm(scene, params, views)
        with stage("injection"):
            size = params.inject_size
            sources = [(texs, size * size, light.position) for texs, light in zip(targets, scene.lights)]
            self._inject(grid, sources, med.bbox_min, med.bbox_max, scene.boundary.eta, params.inject_offset,
                         grid.prop_a)
        with stage("propagation"):
            self._propagate(grid, params.precision, dx, params.steps, params.skip)
        with stage("shading"):
            fbo = self._shade(scene, params, grid, views, shadow_tex, centre, radius)

        bufs = [np.frombuffer(fbo.read(components=4, attachment=i, dtype="f4"), dtype="f4")
                .reshape(scene.camera.height, scene.camera.width, 4)[::-1] for i in range(4)]
        timings = {}
        for k, q in queries.items():
            timings[k] = _gpu_ms(q.elapsed, stage_wall[k], k, warnings)
        timings["host_material"] = host_ms
        timings["wall"] = (time.perf_counter() - t_wall) * 1e3
        mask = bufs[1][..., 3] > 0.5
        return RenderResult(
            full=np.ascontiguousarray(bufs[0][..., :3]),
            subsurface=np.ascontiguousarray(bufs[1][..., :3]),
            mask=mask,
            timings_ms=timings,
            gl_renderer=self.gl_renderer,
            warnings=list(self.warnings) + warnings,
            position=np.ascontiguousarray(bufs[2][..., :3]),
            normal=np.ascontiguousarray(bufs[3][..., :3]),
        )
