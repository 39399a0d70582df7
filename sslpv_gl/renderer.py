"""GLSL SSLPV renderer (Borlum et al., "Subsurface Light Propagation Volumes", HPG 2011).

``SSLPVRenderer(ctx=None).render(scene, params) -> RenderResult`` runs the
paper's four stages on an OpenGL 4.3 context (headless EGL; llvmpipe works).
Each stage's host code lives in a module beside its shaders; this one keeps the
context, the programs (built once per variant, constant uniforms set then), the
mesh, the grids and the render targets, and runs the stages in order:

.. list-table::
   :header-rows: 1

   * - stage
     - paper
     - module
     - shaders
     - what
   * - RSM
     - Sec. 3.1
     - :mod:`sslpv_gl.rsm`
     - ``rsm.vert/frag``
     - per light: injection RSM (``inject_size``^2: position, normal,
       ``Phi_p = I dOmega_p``) and shadow map (``rsm_size``^2), same frustum
   * - injection
     - Sec. 3.1, Eq. 1
     - :mod:`sslpv_gl.inject`
     - ``inject.vert/frag``, ``unflatten.comp``
     - one point per RSM texel, refracted clamped-cosine lobe times
       ``(1/pi) T Phi_p``, summed per cell by additive blending
   * - propagation
     - Sec. 3.2, Eq. 3, Sec. 4
     - :mod:`sslpv_gl.propagate`
     - ``propagate.comp``
     - six-neighbour gather with ``sh.propagation_matrices()``, Beer
       attenuation, Eq. 3 scattering of the SOURCE cell, ping-pong,
       accumulation of steps ``k > skip``
   * - shading
     - Sec. 3.3, Eqs. 4-7
     - :mod:`sslpv_gl.shade`
     - ``shade.vert/frag``
     - area-light radiance from the accumulation grid (times ``1/eta^2``
       with ``params.eta2``; not in the paper), plus GGX reflection of each
       light (shadow-mapped) for a dielectric boundary

The LPV grid textures are :class:`sslpv_gl.grids.GridSet` (one per ``N`` and
precision); the framebuffers of the raster passes are
:class:`sslpv_gl.targets.Targets`. Parameters are
:class:`sslpv_gl.params.SSLPVParams` (defaults in one place).

Limits
------
* At most :data:`MAX_LIGHTS` point lights; cubic LPV cells.
* Direct reflection is the GGX reflection half of a rough dielectric; the
  smooth limit (roughness 0) is not representable with point lights.
* The medium outside the mesh follows ``params.outside``.
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass, field

import numpy as np

from harness.errors import InputError
from harness.scene.geometry import grid_inside

from . import inject as injection
from . import propagate as propagation
from . import rsm
from . import shade as shading
from .grids import LOCAL_SIZE, GridSet, read_grid, write_grid
from .material import lpv_material
from .params import SSLPVParams
from .shade import MAX_LIGHTS
from .targets import Targets

__all__ = ["SSLPVRenderer", "RenderResult", "MAX_LIGHTS", "LOCAL_SIZE"]

_QUERY_INVALID = 0xFFFFFFFF      # what llvmpipe returns for an unavailable time query

#: program key[0] -> the stage's builder, called as ``builder(ctx, *key[1:], warnings)``
_BUILDERS = {
    "rsm": rsm.build_program,                   # ("rsm",)
    "inject": injection.build_program,          # ("inject",)
    "unflatten": injection.build_unflatten,     # ("unflatten", precision)
    "propagate": propagation.build_program,     # ("propagate", precision, acc)
    "shade": shading.build_program,             # ("shade", lookup)
}


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


class SSLPVRenderer:
    """See the module docstring. ``ctx`` defaults to :func:`sslpv_gl.context.create_context`."""

    def __init__(self, ctx=None):
        from .context import create_context

        self.ctx = ctx if ctx is not None else create_context()
        self.gl_renderer = str(self.ctx.info.get("GL_RENDERER", "unknown"))
        self.warnings = []               # uniforms optimised away, collected once per program
        self._programs = {}
        self._grids = {}
        self._targets = Targets(self.ctx)
        self._meshes = {}
        self._points = None              # empty vertex array: injection points fetch their texel by id
        self._material_cache = {}
        # Mesa llvmpipe answers the first GL_TIME_ELAPSED query of a context with
        # 0xFFFFFFFF ns (measured here); spend that one on a 1x1 clear.
        warm_fbo = self.ctx.simple_framebuffer((1, 1))
        warm = self.ctx.query(time=True)
        with warm:
            warm_fbo.use()
            warm_fbo.clear(0.0, 0.0, 0.0, 0.0)
        _ = warm.elapsed
        warm_fbo.release()

    # ------------------------------------------------------------ resources

    def _program(self, key):
        """Programs are built lazily once per variant by their stage, which sets the constant uniforms."""
        prog = self._programs.get(key)
        if prog is None:
            prog = _BUILDERS[key[0]](self.ctx, *key[1:], self.warnings)
            self._programs[key] = prog
        return prog

    def _grid(self, N, precision):
        key = (N, precision)
        if key not in self._grids:
            self._grids[key] = GridSet(self.ctx, N, precision)
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

    # ------------------------------------------------------------ stage 1: RSM (Sec. 3.1)

    def _render_rsm(self, scene, params, views):
        prog = self._program(("rsm",))
        vao = self._mesh_vao(scene, prog, "rsm")
        return rsm.render_maps(self.ctx, prog, vao, self._targets, scene, params, views)

    def rsm_texels(self, scene, params=None):
        """Injection-resolution RSM of each light read back -> list of (M, 10) float32, top row first.

        Columns ``[px, py, pz, nx, ny, nz, phi_r, phi_g, phi_b, valid]`` (conventions).
        """
        params = params or SSLPVParams()
        self._check_scene(scene)
        views, _, _, _ = rsm.light_views(scene)
        maps, _ = self._render_rsm(scene, params, views)
        return rsm.read_texels(maps)

    # ------------------------------------------------------------ stage 2: injection (Sec. 3.1, Eq. 1)

    def _inject(self, grid, sources, scene, offset):
        prog = self._program(("inject",))
        if self._points is None:
            self._points = self.ctx.vertex_array(prog, [])
        unflatten = self._program(("unflatten", grid.precision))
        med = scene.medium
        injection.run(self.ctx, prog, self._points, unflatten, grid, sources, med.bbox_min, med.bbox_max,
                      scene.boundary.eta, offset, grid.prop_a)

    def inject(self, texels_list, light_positions, scene, params=None):
        """GL injection of given RSM texels (one (M,10) array per light) -> (N,N,N,3,4) float32."""
        params = params or SSLPVParams()
        grid = self._grid(params.N, params.precision)
        sources = []
        for texels, lp in zip(texels_list, light_positions):
            parts, m = injection.texel_textures(self.ctx, texels)
            sources.append((parts, m, lp))
        self._inject(grid, sources, scene, params.inject_offset)
        for parts, _, _ in sources:
            for t in parts:
                t.release()
        return read_grid(grid.prop_a, params.precision)

    # ------------------------------------------------------------ stage 3: propagation (Sec. 3.2, Sec. 4)

    def _propagate(self, grid, steps, skip):
        progs = {acc: self._program(("propagate", grid.precision, acc)) for acc in propagation.ACC_MODES}
        return propagation.run(self.ctx, progs, grid, steps, skip)

    def propagate(self, c0, material, dx, steps, skip=2, precision="fp32"):
        """GL propagation of ``c0`` (N,N,N,3,4) with a material dict -> ``(prop, accum)`` float32."""
        c0 = np.asarray(c0, dtype=np.float32)
        N = c0.shape[0]
        SSLPVParams(N=N, steps=int(steps), skip=int(skip), precision=precision)   # validates
        grid = self._grid(N, precision)
        propagation.upload_material(grid, material, dx)
        write_grid(grid.prop_a, c0, precision)
        final = self._propagate(grid, int(steps), int(skip))
        return read_grid(final, precision), read_grid(grid.accum, precision)

    def read_accumulation(self, params):
        """The accumulation grid of the last render/propagate with ``params.N``/``precision`` -> (N,N,N,3,4)."""
        return read_grid(self._grid(params.N, params.precision).accum, params.precision)

    # ------------------------------------------------------------ stage 4: shading (Sec. 3.3)

    def _shade(self, scene, params, grid, views, shadow_tex, centre, radius):
        prog = self._program(("shade", params.lookup))
        vao = self._mesh_vao(scene, prog, ("shade", params.lookup))
        cam = scene.camera
        target = self._targets.get("shade", (cam.width, cam.height), 4)
        shading.run(self.ctx, prog, vao, target, scene, params, grid, views, shadow_tex, centre, radius)
        return target

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
        views, centre, radius, w = rsm.light_views(scene)
        warnings += w
        grid = self._grid(params.N, params.precision)
        med = scene.medium
        dx = float((np.asarray(med.bbox_max, float) - np.asarray(med.bbox_min, float))[0] / params.N)
        propagation.upload_material(grid, material, dx)
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
            maps, shadow_tex = self._render_rsm(scene, params, views)
        with stage("injection"):
            size = params.inject_size
            sources = [(texs, size * size, light.position) for texs, light in zip(maps, scene.lights)]
            self._inject(grid, sources, scene, params.inject_offset)
        with stage("propagation"):
            self._propagate(grid, params.steps, params.skip)
        with stage("shading"):
            target = self._shade(scene, params, grid, views, shadow_tex, centre, radius)

        bufs = shading.read_images(target, scene.camera.width, scene.camera.height)   # outside the stage timers
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
