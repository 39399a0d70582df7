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
:class:`sslpv_gl.params.SSLPVParams` (defaults in one place). One propagation shaded
at its step counts (snapshots, ``steps = auto``, ``steps = steady``) is
:func:`sslpv_gl.steps.propagate_and_shade`; the stage timers are :mod:`sslpv_gl.timing`,
the light's whereabouts :mod:`sslpv_gl.diagnostics`.

Limits
------
* At most :data:`MAX_LIGHTS` point lights; cubic LPV cells.
* Direct reflection is the GGX reflection half of a rough dielectric; a smooth
  one (roughness 0) reflects nothing a pinhole camera sees from point lights.
* The medium outside the mesh follows ``params.outside``.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, field

import numpy as np

from harness.errors import InputError
from harness.scene.geometry import grid_inside

from . import inject as injection
from . import propagate as propagation
from . import reflect, rsm
from . import shade as shading
from .diagnostics import _flux
from .grids import LOCAL_SIZE, GridSet, band0, read_grid, read_layers, support, write_grid, write_layers
from .material import lpv_material, resample_medium
from .params import STEP_MODES, SSLPVParams
from .shade import MAX_LIGHTS
from .steps import propagate_and_shade
from .targets import Targets
from .timing import _gpu_ms, stage_timer

__all__ = ["SSLPVRenderer", "RenderResult", "MAX_LIGHTS", "LOCAL_SIZE"]

#: program key[0] -> the stage's builder, called as ``builder(ctx, *key[1:], warnings)``
_BUILDERS = {
    "rsm": rsm.build_program,                   # ("rsm",)
    "inject": injection.build_program,          # ("inject",)
    "unflatten": injection.build_unflatten,     # ("unflatten", precision)
    "propagate": propagation.build_program,     # ("propagate", precision, acc)
    "shade": shading.build_program,             # ("shade", lookup)
    "scale": propagation.build_scale_program,   # ("scale", precision)
}


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
    steps_used: int | None = None        # propagation steps run (None for steps=steady)
    diagnostics: dict | None = None      # steps_used, injected_flux, remaining_fraction, outside_share
    calibration: dict | None = None      # path, sha256 and budget of a calibrated mapping


def _current(method):
    """Run a public method with this renderer's context current (and the previous one restored after).

    Several renderers (several EGL contexts) can live in one process, as in a test
    session or a sweep worker that also renders by hand; GL calls go to whichever
    context is current, so each entry point makes its own current first.
    """
    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        with self.ctx:
            return method(self, *args, **kwargs)
    return wrapper


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
        self._inside_cache = {}          # (scene hash, N) -> inside mask
        self._resampled_cache = {}       # (scene hash, N, resample) -> resample_medium(...)
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
        """Per-cell LPV material for the scene (cached per scene hash and material settings).

        The mapping family and ``sigma_scale`` are the resolved ones
        (:meth:`SSLPVParams.resolved`); the dict also carries the cell-centre
        inside mask under ``"inside"`` (not uploaded; used for diagnostics).
        """
        res = params.resolved()
        eta = float(scene.boundary.eta)
        reflect.check(params.boundary_reflect, params.outside, eta)
        key = (scene.content_hash, params.N, res.family, res.sigma_scale, params.resample, params.outside, eta,
               params.phase_scaling, params.boundary_reflect, res.form, params.exitance)
        mat = self._material_cache.get(key)
        if mat is None:
            med = scene.medium
            # The voxelised mesh and the resampled medium do not depend on the mapping or
            # sigma_scale: a calibration scan over sigma_scale reuses them (bit-identical).
            inside_key = (scene.content_hash, params.N)
            inside = self._inside_cache.get(inside_key)
            if inside is None:
                inside = grid_inside(scene.mesh, med.bbox_min, med.bbox_max, params.N)
                _put(self._inside_cache, inside_key, inside, 4)
            resampled = self._resampled(scene, params.N, params.resample)
            mat = lpv_material(med, inside, params.N, res.family, params.resample, params.outside, eta=eta,
                               sigma_scale=res.sigma_scale, resampled=resampled, phase_scaling=params.phase_scaling,
                               form=res.form, exitance=params.exitance)
            mat["inside"] = inside
            mat["r_dr"] = reflect.reflectance(params.boundary_reflect, eta)   # 0: the paper (sslpv_gl.reflect)
            # A few entries: a sweep worker interleaves mappings and step counts of one grid.
            _put(self._material_cache, key, mat, 8)
        return mat

    def _resampled(self, scene, N, method):
        """:func:`~sslpv_gl.material.resample_medium` of the scene at ``N``, cached: the material and the injection
        depth (Eq. (J1) of :mod:`sslpv_gl.inject`) read the same arrays."""
        key = (scene.content_hash, N, method)
        res = self._resampled_cache.get(key)
        if res is None:
            res = resample_medium(scene.medium, N, method)
            _put(self._resampled_cache, key, res, 4)
        return res

    def _depth_cells(self, scene, params):
        """Eq. (J1)'s per-cell depth for ``params.inject_depth`` (None at 0, the paper), built on the host before
        the injection stage so that its timer holds the GL work alone."""
        if not params.inject_depth:
            return None
        return injection.depth_offsets(scene.medium, params.N, params.inject_depth, params.resample,
                                       resampled=self._resampled(scene, params.N, params.resample))

    # ------------------------------------------------------------ stage 1: RSM (Sec. 3.1)

    def _render_rsm(self, scene, params, views):
        prog = self._program(("rsm",))
        vao = self._mesh_vao(scene, prog, "rsm")
        return rsm.render_maps(self.ctx, prog, vao, self._targets, scene, params, views)

    @_current
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

    def _inject(self, grid, sources, scene, params, cells=None):
        """``cells``: :meth:`_depth_cells` (None: the paper's injection at the surface)."""
        prog = self._program(("inject",))
        if self._points is None:
            self._points = self.ctx.vertex_array(prog, [])
        unflatten = self._program(("unflatten", grid.precision))
        med = scene.medium
        depth = None
        if cells is not None:
            depth = self.ctx.texture3d((grid.N,) * 3, 1, data=cells.astype(np.float32).tobytes(), dtype="f4")
            depth.filter = (self.ctx.NEAREST, self.ctx.NEAREST)
        try:
            injection.run(self.ctx, prog, self._points, unflatten, grid, sources, med.bbox_min, med.bbox_max,
                          scene.boundary.eta, params.inject_offset, grid.prop_a, depth)
        finally:
            if depth is not None:
                depth.release()

    @_current
    def inject(self, texels_list, light_positions, scene, params=None):
        """GL injection of given RSM texels (one (M,10) array per light) -> (N,N,N,3,4) float32."""
        params = params or SSLPVParams()
        grid = self._grid(params.N, params.precision)
        sources = []
        for texels, lp in zip(texels_list, light_positions):
            parts, m = injection.texel_textures(self.ctx, texels)
            sources.append((parts, m, lp))
        self._inject(grid, sources, scene, params, self._depth_cells(scene, params))
        for parts, _, _ in sources:
            for t in parts:
                t.release()
        return read_grid(grid.prop_a, params.precision)

    # ------------------------------------------------------------ stage 3: propagation (Sec. 3.2, Sec. 4)

    def _propagate(self, grid, steps, skip, on_step=None, bounds=None):
        """``bounds``: :func:`~sslpv_gl.grids.support` of ``grid.prop_a``; each step then computes only the
        cells light can have reached (:func:`sslpv_gl.propagate.region`), the same floats as the whole grid."""
        progs = {acc: self._program(("propagate", grid.precision, acc)) for acc in propagation.ACC_MODES}
        return propagation.run(self.ctx, progs, grid, steps, skip, on_step, bounds)

    @_current
    def propagate(self, c0, material, dx, steps, skip=2, precision="fp32"):
        """GL propagation of ``c0`` (N,N,N,3,4) with a material dict -> ``(prop, accum)`` float32."""
        c0 = np.asarray(c0, dtype=np.float32)
        N = c0.shape[0]
        SSLPVParams(N=N, steps=int(steps), skip=int(skip), precision=precision)   # validates
        grid = self._grid(N, precision)
        propagation.upload_material(grid, material, dx)
        write_grid(grid.prop_a, c0, precision)
        final, _ = self._propagate(grid, int(steps), int(skip), bounds=support(read_layers(grid.prop_a, precision)))
        return read_grid(final, precision), read_grid(grid.accum, precision)

    @_current
    def read_accumulation(self, params):
        """The accumulation grid of the last render/propagate with ``params.N``/``precision`` -> (N,N,N,3,4)."""
        return read_grid(self._grid(params.N, params.precision).accum, params.precision)

    # ------------------------------------------------------------ stage 4: shading (Sec. 3.3)

    def _shade(self, scene, params, grid, views, shadow_tex, centre, radius, acc=None):
        prog = self._program(("shade", params.lookup))
        vao = self._mesh_vao(scene, prog, ("shade", params.lookup))
        cam = scene.camera
        target = self._targets.get("shade", (cam.width, cam.height), 4)
        shading.run(self.ctx, prog, vao, target, scene, params, grid, views, shadow_tex, centre, radius, acc)
        return target

    # ------------------------------------------------------------ front door

    @_current
    def render(self, scene, params=None, diagnostics=False):
        """Render ``scene`` with SSLPV -> :class:`RenderResult` (images top row first).

        ``diagnostics=True`` also reads the grids back (outside the stage timers)
        to fill :attr:`RenderResult.diagnostics`; ``steps = auto`` and ``steady``
        always do.
        """
        params = params or SSLPVParams()
        if not isinstance(params, SSLPVParams):
            raise TypeError("params must be an SSLPVParams")
        return self._render(scene, params, [params.steps], diagnostics)[0]

    @_current
    def render_steps(self, scene, params, steps_list, diagnostics=False):
        """One render per step count in ``steps_list``, from ONE propagation -> list of :class:`RenderResult`.

        RSM, injection and the material are made once; the propagation runs to
        ``max(steps_list)`` and the shading pass runs as each step count passes,
        so every image is bit-identical to ``render(scene, params.replace(steps=K))``.
        Each result's ``propagation`` timing is the GL time of the steps up to its
        ``K`` (what a render of ``K`` alone spends); RSM and injection are the
        group's, measured once (``timings_ms["shared"]`` lists them).
        """
        if not isinstance(params, SSLPVParams):
            raise TypeError("params must be an SSLPVParams")
        ks = list(steps_list)
        if not ks or any(isinstance(k, str) or isinstance(k, bool) or not isinstance(k, int) for k in ks):
            raise InputError("--steps", "steps", f"snapshots need step counts, got {ks!r}",
                             "render 'auto' and 'steady' on their own")
        for k in ks:
            params.replace(steps=k)                       # validates each (skip <= steps, budgets)
        return self._render(scene, params, ks, diagnostics)

    def _render(self, scene, params, steps_list, diagnostics):
        """RSM and injection once (Sec. 3.1); then, per group of step counts that share a material, one
        propagation (Sec. 3.2) shaded at each count (Sec. 3.3) -> :class:`RenderResult` s, counts ascending."""
        self._check_scene(scene)
        ctx = self.ctx
        t_wall = time.perf_counter()
        warnings = []
        mode = params.steps if params.steps in STEP_MODES else None
        resolved, groups = _budgets(params, steps_list, mode)
        views, centre, radius, w = rsm.light_views(scene)
        warnings += w
        grid = self._grid(params.N, params.precision)
        med = scene.medium
        dx = float((np.asarray(med.bbox_max, float) - np.asarray(med.bbox_min, float))[0] / params.N)
        queries = {k: ctx.query(time=True) for k in ("rsm", "injection")}
        stage_wall = {}
        stage = stage_timer(ctx, queries, stage_wall)

        shadow_tex = self._rsm_and_inject(scene, params, views, grid, stage)
        shared = {k: _gpu_ms(queries[k].elapsed, stage_wall[k], k, warnings) for k in ("rsm", "injection")}

        want_diag = diagnostics or mode is not None
        c0, layers, inj, bounds = _read_injected(grid, params.precision, mode, want_diag)
        outputs = []
        for i, ks in enumerate(groups.values()):
            if i:                                          # the propagation overwrote the injected grid
                write_layers(grid.prop_a, layers)
            outputs += propagate_and_shade(self, scene, params, ks, resolved, grid, dx, c0, bounds, inj, want_diag,
                                           (views, shadow_tex, centre, radius), shared, stage, stage_wall, warnings)
        outputs.sort(key=lambda o: -1 if o[2] is None else o[2])
        return self._results(outputs, len(groups), t_wall, warnings)

    def _rsm_and_inject(self, scene, params, views, grid, stage):
        """Stages 1 and 2, each timed by ``stage``: every light's RSM and shadow map, then the injection of
        their texels into ``grid.prop_a``. Returns the shadow maps (the shading pass reads them)."""
        with stage("rsm"):
            maps, shadow_tex = self._render_rsm(scene, params, views)
        cells = self._depth_cells(scene, params)
        with stage("injection"):
            size = params.inject_size
            sources = [(texs, size * size, light.position) for texs, light in zip(maps, scene.lights)]
            self._inject(grid, sources, scene, params, cells)
        return shadow_tex

    def _results(self, outputs, n_groups, t_wall, warnings):
        """The :class:`RenderResult` of each shaded output ``(buffers, timings, steps_used, diagnostics, resolved)``."""
        results = []
        for bufs, timings, steps_used, diag, res in outputs:
            timings["wall"] = (time.perf_counter() - t_wall) * 1e3
            if len(outputs) > 1:
                timings["shared"] = ["rsm", "injection", "host_material"] if n_groups == 1 else ["rsm", "injection"]
            mask = bufs[1][..., 3] > 0.5
            results.append(RenderResult(
                full=np.ascontiguousarray(bufs[0][..., :3]),
                subsurface=np.ascontiguousarray(bufs[1][..., :3]),
                mask=mask,
                timings_ms=timings,
                gl_renderer=self.gl_renderer,
                warnings=list(self.warnings) + warnings,
                position=np.ascontiguousarray(bufs[2][..., :3]),
                normal=np.ascontiguousarray(bufs[3][..., :3]),
                steps_used=steps_used,
                diagnostics=diag,
                calibration=res.calibration,
            ))
        return results

    def _scale(self, grid):
        prog = self._program(("scale", grid.precision))
        return propagation.scale_accumulation(self.ctx, prog, grid)


def _budgets(params, steps_list, mode):
    """``(resolved, groups)``: each step count's resolved parameters, and the counts grouped by what one
    propagation can serve."""
    # What each step count renders with: a calibrated mapping has its own sigma_scale and
    # radiance_scale per budget (Resolved), and a version 3 file a per-cell form per budget.
    # Counts that share the mapping family, sigma_scale and form share one propagation; the
    # radiance scale acts after it (grid.scale).
    resolved = {k: params.replace(steps=k).resolved() for k in sorted(set(steps_list))} if mode is None \
        else {params.steps: params.resolved()}
    groups = {}
    for k, res in resolved.items():
        groups.setdefault((res.family, res.sigma_scale, res.form), []).append(k)
    return resolved, groups


def _read_injected(grid, precision, mode, want_diag):
    """``(c0, layers, injected flux, bounds)``: what the later stages read back of the injected grid, outside
    the stage timers (None where the mode does not need it)."""
    # The steady solve needs the whole injected grid; the
    # diagnostics and the convergence check only its band-0 coefficient (read_c00).
    c0 = read_grid(grid.prop_a, precision) if mode == "steady" else None
    # Where the injected light is (propagate.region) comes from the same readback: it spares
    # each step the cells light cannot reach yet; a second propagation restores the grid from it.
    layers = read_layers(grid.prop_a, precision) if want_diag or mode != "steady" else None
    inj = _flux(band0(layers)) if want_diag else None
    bounds = support(layers) if mode != "steady" else None
    return c0, layers, inj, bounds


def _put(cache, key, value, size):
    """Insert into a small FIFO cache of at most ``size`` entries."""
    if len(cache) >= size:
        cache.pop(next(iter(cache)))
    cache[key] = value
