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
* Direct reflection is the GGX reflection half of a rough dielectric; a smooth
  one (roughness 0) reflects nothing a pinhole camera sees from point lights.
* The medium outside the mesh follows ``params.outside``.
"""

from __future__ import annotations

import contextlib
import functools
import time
from dataclasses import dataclass, field

import numpy as np

from harness.errors import InputError
from harness.scene.geometry import grid_inside

from . import inject as injection
from . import propagate as propagation
from . import rsm
from . import shade as shading
from .grids import LOCAL_SIZE, GridSet, band0, read_c00, read_grid, read_layers, support, write_grid, write_layers
from .material import lpv_material, resample_medium
from .params import STEP_MODES, SSLPVParams
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
    "scale": propagation.build_scale_program,   # ("scale", precision)
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
        self._geometry_cache = {}        # (scene hash, N, resample) -> (inside mask, resampled medium)
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
        key = (scene.content_hash, params.N, res.family, res.sigma_scale, params.resample, params.outside, eta)
        mat = self._material_cache.get(key)
        if mat is None:
            med = scene.medium
            # The voxelised mesh and the resampled medium do not depend on the mapping or
            # sigma_scale: a calibration scan over sigma_scale reuses them (bit-identical).
            geo_key = (scene.content_hash, params.N, params.resample)
            geo = self._geometry_cache.get(geo_key)
            if geo is None:
                geo = (grid_inside(scene.mesh, med.bbox_min, med.bbox_max, params.N),
                       resample_medium(med, params.N, params.resample))
                _put(self._geometry_cache, geo_key, geo, 4)
            inside, resampled = geo
            mat = lpv_material(med, inside, params.N, res.family, params.resample, params.outside, eta=eta,
                               sigma_scale=res.sigma_scale, resampled=resampled)
            mat["inside"] = inside
            # A few entries: a sweep worker interleaves mappings and step counts of one grid.
            _put(self._material_cache, key, mat, 8)
        return mat

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

    def _inject(self, grid, sources, scene, offset):
        prog = self._program(("inject",))
        if self._points is None:
            self._points = self.ctx.vertex_array(prog, [])
        unflatten = self._program(("unflatten", grid.precision))
        med = scene.medium
        injection.run(self.ctx, prog, self._points, unflatten, grid, sources, med.bbox_min, med.bbox_max,
                      scene.boundary.eta, offset, grid.prop_a)

    @_current
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
        self._check_scene(scene)
        ctx = self.ctx
        t_wall = time.perf_counter()
        warnings = []
        mode = params.steps if params.steps in STEP_MODES else None
        # What each step count renders with: a calibrated mapping has its own sigma_scale and
        # radiance_scale per budget (Resolved). Counts that share the mapping family and
        # sigma_scale share one propagation; the radiance scale acts after it (grid.scale).
        resolved = {k: params.replace(steps=k).resolved() for k in sorted(set(steps_list))} if mode is None \
            else {params.steps: params.resolved()}
        groups = {}
        for k, res in resolved.items():
            groups.setdefault((res.family, res.sigma_scale), []).append(k)
        views, centre, radius, w = rsm.light_views(scene)
        warnings += w
        grid = self._grid(params.N, params.precision)
        med = scene.medium
        dx = float((np.asarray(med.bbox_max, float) - np.asarray(med.bbox_min, float))[0] / params.N)
        queries = {k: ctx.query(time=True) for k in ("rsm", "injection")}
        stage_wall = {}

        @contextlib.contextmanager
        def stage(name, query=None):
            # A host clock around each stage (after a finish) beside the GL timer query:
            # moderngl reads GL_TIME_ELAPSED as 32 bits, which wraps after 4.29 s.
            ctx.finish()
            t = time.perf_counter_ns()
            with (query if query is not None else queries[name]):
                yield
            ctx.finish()
            stage_wall[name] = stage_wall.get(name, 0) + time.perf_counter_ns() - t

        with stage("rsm"):
            maps, shadow_tex = self._render_rsm(scene, params, views)
        with stage("injection"):
            size = params.inject_size
            sources = [(texs, size * size, light.position) for texs, light in zip(maps, scene.lights)]
            self._inject(grid, sources, scene, params.inject_offset)
        shared = {k: _gpu_ms(queries[k].elapsed, stage_wall[k], k, warnings) for k in ("rsm", "injection")}

        want_diag = diagnostics or mode is not None
        # Outside the stage timers. The steady solve needs the whole injected grid; the
        # diagnostics and the convergence check only its band-0 coefficient (read_c00).
        c0 = read_grid(grid.prop_a, params.precision) if mode == "steady" else None
        # Where the injected light is (propagate.region) comes from the same readback: it spares
        # each step the cells light cannot reach yet; a second propagation restores the grid from it.
        layers = read_layers(grid.prop_a, params.precision) if want_diag or mode != "steady" else None
        inj = _flux(band0(layers)) if want_diag else None
        bounds = support(layers) if mode != "steady" else None
        outputs = []
        for i, ks in enumerate(groups.values()):
            if i:                                          # the propagation overwrote the injected grid
                write_layers(grid.prop_a, layers)
            outputs += self._propagate_and_shade(scene, params, ks, resolved, grid, dx, c0, bounds, inj, want_diag,
                                                 (views, shadow_tex, centre, radius), shared, stage, stage_wall,
                                                 warnings)
        outputs.sort(key=lambda o: -1 if o[2] is None else o[2])

        results = []
        for bufs, timings, steps_used, diag, res in outputs:
            timings["wall"] = (time.perf_counter() - t_wall) * 1e3
            if len(outputs) > 1:
                timings["shared"] = ["rsm", "injection", "host_material"] if len(groups) == 1 else ["rsm", "injection"]
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

    def _propagate_and_shade(self, scene, params, ks, resolved, grid, dx, c0, bounds, inj, want_diag, light,
                             shared, stage, stage_wall, warnings):
        """One propagation from the injected ``grid.prop_a`` with the material of ``ks`` (step counts that share
        ``resolved[k]``'s family and sigma_scale), shaded at each count with its own radiance scale.

        Returns ``[(buffers, timings, steps_used, diagnostics, resolved), ...]`` in the order shaded.
        """
        ctx = self.ctx
        views, shadow_tex, centre, radius = light
        mode = params.steps if params.steps in STEP_MODES else None
        t0 = time.perf_counter()
        first = params.replace(steps=ks[0]) if mode is None else params
        material = self.lpv_material(scene, first)
        scaled = propagation.upload_material(grid, _with_global_scale(material, resolved[ks[0]].radiance_scale), dx)
        uploaded = resolved[ks[0]].radiance_scale
        host_ms = (time.perf_counter() - t0) * 1e3
        outside_mask = ~np.asarray(material["inside"], dtype=bool) if want_diag else None
        prop_ms = 0.0                                     # GL time of the propagation so far
        outputs = []

        def shade_now(steps_used, final):
            nonlocal scaled, uploaded
            res = resolved[steps_used if mode is None else params.steps]
            if res.radiance_scale != uploaded:            # a budget of this group with its own radiance scale
                scaled = propagation.upload_scale(grid, _with_global_scale(material, res.radiance_scale))
                uploaded = res.radiance_scale
            q = ctx.query(time=True)
            with stage("shading", q):
                acc = self._scale(grid) if scaled else None
                target = self._shade(scene, params, grid, views, shadow_tex, centre, radius, acc)
            bufs = shading.read_images(target, scene.camera.width, scene.camera.height)  # outside the timers
            timings = dict(shared)
            timings["propagation"] = prop_ms
            timings["shading"] = _gpu_ms(q.elapsed, stage_wall.pop("shading"), "shading", warnings)
            timings["host_material"] = host_ms
            diag = None
            if want_diag:
                diag = _diagnostics(inj, None if final is None else read_c00(final, params.precision),
                                    read_c00(grid.accum, params.precision), outside_mask, steps_used)
            outputs.append((bufs, timings, steps_used, diag, res))

        if mode == "steady":
            t = time.perf_counter_ns()
            from .steady import steady_state

            acc, info = steady_state(c0, material["sigma_lpv"], material["sigma_s_prime"], material["g"], dx,
                                     skip=params.skip, emit=material["emit"], empty=material.get("empty"))
            write_grid(grid.accum, acc, params.precision)
            ctx.finish()
            prop_ms = (time.perf_counter_ns() - t) / 1e6       # a host solve: its wall time is its cost
            warnings.append(f"steps=steady: accumulation solved on the host ({info.get('method', 'krylov')}, "
                            f"{info.get('iterations')} iterations); its propagation time is host wall time")
            shade_now(None, None)
            return outputs

        targets = sorted(ks) if mode is None else []
        last = targets[-1] if targets else params.max_steps
        if targets and targets[0] <= params.skip:
            propagation.clear(grid.accum, grid)        # a snapshot before the first accumulated step
        check_every = 8
        injected = inj if mode == "auto" else None
        seg = {"q": None, "t": 0}                      # the running propagation segment

        def begin():
            ctx.finish()
            seg["q"] = ctx.query(time=True)
            seg["t"] = time.perf_counter_ns()
            seg["q"].__enter__()

        def end():
            nonlocal prop_ms
            seg["q"].__exit__(None, None, None)
            ctx.finish()
            prop_ms += _gpu_ms(seg["q"].elapsed, time.perf_counter_ns() - seg["t"], "propagation", warnings)

        def on_step(step, src):
            if mode == "auto":
                if step % check_every and step != last:
                    return False
                end()                                  # the convergence check is not propagation work
                done = step == last or _flux(read_c00(src, params.precision)).max() < \
                    params.converge_tol * max(float(injected.max()), 1e-300)
                if done:
                    shade_now(step, src)
                    if step == last:
                        warnings.append(f"steps=auto: not converged after max_steps={last}")
                    return True
                begin()
                return False
            if step in targets:
                end()
                shade_now(step, src)
                if step == last:
                    return True
                begin()
            return False

        begin()
        if last == 0 or (targets and targets[0] == 0):
            end()
            shade_now(0, grid.prop_a)
            if last > 0:
                begin()
        if last > 0:
            self._propagate(grid, last, params.skip, on_step, bounds)
        return outputs

    def _scale(self, grid):
        prog = self._program(("scale", grid.precision))
        return propagation.scale_accumulation(self.ctx, prog, grid)


def _put(cache, key, value, size):
    """Insert into a small FIFO cache of at most ``size`` entries."""
    if len(cache) >= size:
        cache.pop(next(iter(cache)))
    cache[key] = value


def _with_global_scale(material, r):
    """The material with the resolved global radiance scale ``r`` folded into its per-cell one."""
    if r == 1.0:
        return material
    out = dict(material)
    out["radiance_scale"] = np.asarray(material.get("radiance_scale", 1.0), dtype=np.float64) * r
    return out


def _flux(c00):
    """Total flux per colour of an SH grid's band-0 coefficients ``(..., 3)``: ``sum sqrt(4 pi) |c00|``.

    abs: a lattice grid may dip below 0.
    """
    return np.sqrt(4.0 * np.pi) * np.abs(np.asarray(c00)).reshape(-1, 3).sum(axis=0, dtype=np.float64)


def _diagnostics(inj, final, accum, outside_mask, steps_used):
    """Where the light is: injected flux, what is still propagating, and the accumulated share outside the mesh.

    ``inj`` is the injected flux per colour (:func:`_flux` of the injected grid, once per render);
    ``final`` and ``accum`` are band-0 coefficients ``(N, N, N, 3)`` (:func:`read_c00`) of the last
    propagation and the accumulation grid; ``outside_mask`` is True for the cells outside the mesh.
    """
    acc = np.abs(np.asarray(accum))                                     # (N, N, N, 3), sums in float64
    total = acc.reshape(-1, 3).sum(axis=0, dtype=np.float64)
    outside = acc[outside_mask].sum(axis=0, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        remaining = None if final is None else float(np.max(np.where(inj > 0, _flux(final) / inj, 0.0)))
        share = float(np.sum(outside) / np.sum(total)) if np.sum(total) > 0 else 0.0
    return {"steps_used": steps_used, "injected_flux": inj.tolist(), "remaining_fraction": remaining,
            "outside_share": share}
