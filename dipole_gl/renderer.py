"""GLSL renderer of SSLPV's classical rivals: the standard and the directional dipole, gathered densely, per vertex,
through a cubemap, down an octree or over a texture atlas's links.

``DipoleRenderer(ctx=None).render(scene, kernel, params) -> DipoleResult`` (``kernel`` is
``"dipole"`` or ``"dirpole"``, ``params`` a :class:`dipole_gl.params.DipoleParams`) runs on an
OpenGL 4.3 context made as SSLPV's (:func:`sslpv_gl.context.create_context`: headless EGL,
llvmpipe works). Every public entry point makes its own context current, so it can live in
one process beside an :class:`sslpv_gl.renderer.SSLPVRenderer`.

.. list-table::
   :header-rows: 1

   * - stage (per frame)
     - gather
     - module / shaders
     - what
   * - ``shadow``
     - both
     - :func:`sslpv_gl.rsm.render_shadow_atlas` (``rsm.vert/frag``)
     - one shadow map per light, ``shadow_size``^2, the frustum of SSLPV's RSM
   * - ``gbuffer``
     - dense, hierarchical
     - :mod:`dipole_gl.gbuffer` (``shade.vert``, ``gbuffer.frag``)
     - exit points (position, normal) per pixel, direct reflection (dielectric)
   * - ``irradiance``
     - both
     - :mod:`dipole_gl.irradiance` (``irradiance.comp``)
     - transmitted flux ``T I cos / d^2 V dA`` per surface point and light
   * - ``aggregate``
     - hierarchical
     - :mod:`dipole_gl.octree` (host)
     - the octree's internal nodes summed from the irradiance (:mod:`dipole_gl.hierarchical`)
   * - ``gather``
     - all
     - :mod:`dipole_gl.gather` (``gather_dense.comp`` / ``gather_vertex.comp``),
       :mod:`dipole_gl.tree_gather` (``gather_tree.comp``)
     - dense: per pixel over every surface sample; vertex: per scattering vertex over its
       precomputed neighbourhood; hierarchical: per pixel down the octree
   * - ``shading``
     - vertex
     - :mod:`dipole_gl.gather` (``display.comp``), :mod:`dipole_gl.shade` (``shade_vertex.*``)
     - per-vertex result to the display mesh, Gouraud raster, exit Fresnel, reflection
   * - ``single``
     - both (``terms`` = ``both`` or ``single``)
     - :mod:`dipole_gl.single` (``rsm.vert/frag``, ``single.comp``)
     - Jensen et al. 2001's single-scattering term per pixel, added to the image (the vertex
       gather first runs the ``gbuffer`` stage for its exit points); ``terms = single`` runs only
       ``shadow``, ``gbuffer`` and ``single``

Precomputation (host, timed apart from the frame, once per scene and setting): the
medium's coefficients (``material``), the dense samples (``sampling``,
:mod:`dipole_gl.sampling`), for the hierarchical gather their ``octree`` (:mod:`dipole_gl.octree`), for the atlas
gather the ``atlas`` and its ``links`` (:mod:`dipole_gl.atlas`, :mod:`dipole_gl.links`; its frame stages
are in :mod:`dipole_gl.atlas_gather`), and for the vertex gather ``remesh``, ``neighbourhoods`` and
``display`` (:mod:`dipole_gl.vertex`). Each result also carries a device-independent *work
count* per stage (:data:`WORK_UNITS`).

Limits
------
* At most :data:`MAX_LIGHTS` point lights, each outside the mesh's bounding sphere for a
  complete shadow map (SSLPV's frustum; a light inside gets a capped field of view).
* Single scattering (``terms``) is Jensen et al.'s estimate, with its limits (:mod:`dipole_gl.single`).
* A heterogeneous medium is seen through the material at the exit point (:mod:`dipole_gl.medium`).
* No shader invocation runs more than :data:`dipole_gl.budget.ITERATION_BUDGET` loop iterations:
  the gathers run in chunks (llvmpipe ends longer loops silently).
* Every render checks a few points against the NumPy twin and refuses a result that disagrees
  (:mod:`dipole_gl.check`; ``info["check"]`` records the cost); ``fit = coarsen`` sizes the
  gather to its budget per scene (:mod:`dipole_gl.sizing`; ``info["spacing_used"]`` or
  ``info["density_used"]``).
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, field

import numpy as np

from harness.errors import InputError
from sslpv_gl import rsm
from sslpv_gl.targets import Targets

from . import (atlas_gather, check, cubemap, gbuffer, hierarchical, irradiance, shade, single, single_pass, sizing,
               tree_gather)
from . import gather as gathers
from .glsl import MAX_LIGHTS
from .medium import scene_material
from .params import KERNELS, DipoleParams
from .sampling import MAX_FRAME_PAIRS, N_PHI, radial_nodes, surface_samples
from .timing import StageTimer, warm_up_queries
from .vertex import precompute as vertex_precompute

__all__ = ["DipoleRenderer", "DipoleResult", "STAGES", "WORK_UNITS", "MAX_LIGHTS"]

N_RAD = len(radial_nodes()[0])

#: Frame stages per gather, in order.
STAGES = {"dense": ("shadow", "gbuffer", "irradiance", "gather", "single"),
          "vertex": ("shadow", "irradiance", "gather", "shading", "gbuffer", "single"),
          "cubemap": (*cubemap.STAGES, "single"),
          "hierarchical": ("shadow", "gbuffer", "irradiance", "aggregate", "gather", "single"),
          "atlas": atlas_gather.STAGES}
#: What one unit of each stage's work count is.
WORK_UNITS = {"shadow": "shadow-map texels", "gbuffer": "pixels", "irradiance": "point-light pairs",
              "gather": "kernel evaluations (dipole + vertex: precomputed factors applied)",
              "aggregate": "octree nodes aggregated", "octree": "octree nodes",
              "shading": "pixels + display vertices", "single": "march nodes x lights (covered pixels)",
              "material": "voxels", "sampling": "surface samples",
              "remesh": "scattering vertices", "neighbourhoods": "neighbour pairs", "display": "display vertices",
              "lightbuffer": "light-buffer texels", "cubemap": "cube-face texels", "combine": "pixels",
              "mipmap": "MIP texels written", "atlas": "atlas texels", "links": "links"}


@dataclass
class DipoleResult:
    full: np.ndarray                 # (H, W, 3) float32, row 0 at the top: subsurface + reflection
    subsurface: np.ndarray           # (H, W, 3) float32
    mask: np.ndarray                 # (H, W) bool: pixel covered by the mesh
    timings_ms: dict                 # frame stage -> GL ms
    precompute_ms: dict              # precomputation step -> host ms (measured when it was made)
    work: dict                       # frame stage -> work count (WORK_UNITS)
    precompute_work: dict            # precomputation step -> work count
    gl_renderer: str
    warnings: list = field(default_factory=list)
    info: dict = field(default_factory=dict)       # samples, vertices, pairs, radius, edge, ...
    debug: dict | None = None                      # read-backs for the twin tests (debug=True)


def _current(method):
    """Run a public method with this renderer's context current (as :mod:`sslpv_gl.renderer` does)."""
    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        with self.ctx:
            return method(self, *args, **kwargs)
    return wrapper


class DipoleRenderer:
    """See the module docstring. ``ctx`` defaults to :func:`sslpv_gl.context.create_context`."""

    def __init__(self, ctx=None):
        from sslpv_gl.context import create_context

        self.ctx = ctx if ctx is not None else create_context()
        self.gl_renderer = str(self.ctx.info.get("GL_RENDERER", "unknown"))
        self.warnings = []
        self._programs = {}
        self._targets = Targets(self.ctx)
        self._scene_key = None
        self._scene_cache = {}
        self._last_single = None                 # the single stage's read-backs of the last render (debug)
        with self.ctx:
            warm_up_queries(self.ctx)

    # ------------------------------------------------------------ resources

    def _program(self, key):
        prog = self._programs.get(key)
        if prog is None:
            build = {"rsm": lambda w: rsm.build_program(self.ctx, w),
                     "gbuffer": lambda w: gbuffer.build_program(self.ctx, w),
                     "irradiance": lambda w: irradiance.build_program(self.ctx, w),
                     "dense": lambda w: gathers.build_dense(self.ctx, key[1], w),
                     "tree": lambda w: tree_gather.build_program(self.ctx, key[1], w),
                     "vertex": lambda w: gathers.build_vertex(self.ctx, key[1], w),
                     "display": lambda w: gathers.build_display(self.ctx, w),
                     "shade": lambda w: shade.build_program(self.ctx, w),
                     "single": lambda w: single.build_program(self.ctx, w),
                     "cube_face": lambda w: cubemap.build_face(self.ctx, w),
                     "cube_gather": lambda w: cubemap.build_gather(self.ctx, key[1], w),
                     "cube_combine": lambda w: cubemap.build_combine(self.ctx, w),
                     "atlas_radiosity": lambda w: atlas_gather.build_radiosity(self.ctx, w),
                     "atlas_gather": lambda w: atlas_gather.build_gather(self.ctx, w),
                     "atlas_shade": lambda w: atlas_gather.build_shade(self.ctx, w)}[key[0]]
            prog = build(self.warnings)
            self._programs[key] = prog
        return prog

    def _cache(self, scene):
        """Per-scene GPU resources, kept for the last scene only (a sweep renders one scene many times)."""
        key = scene.content_hash or id(scene)
        if key != self._scene_key:
            self._release_scene()
            self._scene_key = key
        return self._scene_cache

    def _release_scene(self):
        for entry in self._scene_cache.values():
            for obj in (entry if isinstance(entry, tuple) else (entry,)):
                if hasattr(obj, "release"):
                    obj.release()
        self._scene_cache = {}

    def _material(self, scene, kernel):
        c = self._cache(scene)
        if "material" not in c:
            t = time.perf_counter()
            mat = scene_material(scene, kernel)
            ms = (time.perf_counter() - t) * 1e3
            c["material"] = _Entry(mat, ms, int(mat.inside.size))
            c["medium"] = gathers.MediumTextures(self.ctx, mat)
        return c["material"], c["medium"]

    def _mesh_vao(self, scene, prog, slot, extra=None):
        c = self._cache(scene)
        if "mesh" not in c:
            mesh = scene.mesh
            data = np.hstack([mesh.vertices, mesh.normals]).astype("f4")
            c["mesh"] = (self.ctx.buffer(data.tobytes()), self.ctx.buffer(np.asarray(mesh.faces, "i4").tobytes()))
        vbo, ibo = c["mesh"]
        key = ("vao", slot)
        if key not in c:
            content = [(vbo, "3f 3f", "in_pos", "in_nrm")] + ([(extra, "4f", "in_b")] if extra is not None else [])
            c[key] = self.ctx.vertex_array(prog, content, index_buffer=ibo, index_element_size=4)
        return c[key]

    def _gbuffer_pass(self, scene, views, shadow_tex, shadow_size, centre, radius, timer):
        """The camera's G-buffer (:mod:`dipole_gl.gbuffer`) into the shared ``dipole_gbuffer`` target, timed as the
        ``gbuffer`` stage -> that target."""
        W, H = scene.camera.width, scene.camera.height
        gb = self._targets.get("dipole_gbuffer", (W, H), 5)
        with timer.stage("gbuffer"):
            prog = self._program(("gbuffer",))
            gbuffer.run(self.ctx, prog, self._mesh_vao(scene, prog, "gbuffer"), gb, scene, views, shadow_tex,
                        shadow_size, centre, radius)
        return gb

    def _dense_points(self, scene, mat, spacing):
        c = self._cache(scene)
        key = ("dense", spacing)
        if key not in c:
            t = time.perf_counter()
            pos, nrm, area = surface_samples(scene.mesh, spacing * mat.mfp)
            ms = (time.perf_counter() - t) * 1e3
            c[key] = _Entry(irradiance.PointBuffers(self.ctx, pos, nrm, area, len(scene.lights)), ms, len(area),
                            host=(pos, nrm, area))
        return c[key]

    def _vertex_data(self, scene, mat, kernel, density, range_):
        c = self._cache(scene)
        key = ("vertex", kernel, density, range_)
        if key not in c:
            pre = vertex_precompute(scene, mat, kernel, density, range_, float(scene.boundary.eta))
            pts = irradiance.PointBuffers(self.ctx, pre.positions, pre.normals, pre.areas, len(scene.lights))
            c[key] = (pre, pts, gathers.VertexBuffers(self.ctx, pre))
        return c[key]

    # ------------------------------------------------------------ front door

    @_current
    def render(self, scene, kernel, params=None, debug=False):
        """Render ``scene`` with ``kernel`` -> :class:`DipoleResult` (images top row first)."""
        params = params or DipoleParams()
        if kernel not in KERNELS:
            raise ValueError(f"unknown kernel {kernel!r}; use one of {', '.join(KERNELS)}")
        if not isinstance(params, DipoleParams):
            raise TypeError("params must be a DipoleParams")
        self._check_scene(scene)
        mat_entry, medium = self._material(scene, kernel)
        mat = mat_entry.value
        pre_ms, pre_work = {"material": mat_entry.ms}, {"material": mat_entry.work}
        views, centre, radius, warnings = rsm.light_views(scene)
        cam = scene.camera
        L, W, H = len(scene.lights), cam.width, cam.height
        timer = StageTimer(self.ctx)
        s = params.shadow_size
        with timer.stage("shadow"):
            prog = self._program(("rsm",))
            shadow_tex = rsm.render_shadow_atlas(self.ctx, prog, self._mesh_vao(scene, prog, "rsm"), self._targets,
                                                 scene, s, views, slot="dipole_shadow")
        work = {"shadow": s * s * L}
        info = {"kernel": kernel, "gather": params.gather, "terms": params.terms, "mfp": mat.mfp, "diffusion_length": mat.diffusion_length,
                "homogeneous": mat.homogeneous}
        dbg = {} if debug else None
        if params.terms == "single":
            return self._render_single_only(scene, params, mat, medium, views, shadow_tex, centre, radius, timer,
                                            work, info, pre_ms, pre_work, warnings, dbg)
        if params.gather == "cubemap":
            sub, full, mask, more, extra, dbg = cubemap.render(self, scene, kernel, params, mat, medium, views,
                                                                shadow_tex, centre, radius, timer, debug)
            work.update(more)
            info.update(extra)
            if params.terms == "both":           # S^(1) on the cubemap's G-buffer, added to its (checked) output
                sub, full = single_pass.added(self, "dipole_cubemap_out", scene, params, medium, views, timer, work,
                                              info, dbg)
        elif params.gather == "dense":
            spacing = params.spacing
            if params.fit == "coarsen":
                spacing = sizing.dense_spacing(scene.mesh, mat.mfp, params.spacing, W * H)
            entry = self._dense_points(scene, mat, spacing)
            points = entry.value
            if W * H * points.count > MAX_FRAME_PAIRS:
                raise InputError("--spacing", "spacing", f"the dense gather would pair {W * H:,} pixels with "
                                 f"{points.count:,} surface samples (over {MAX_FRAME_PAIRS:,} per frame)",
                                 "raise --spacing or render a smaller image")
            pre_ms["sampling"], pre_work["sampling"] = entry.ms, entry.work
            gb = self._gbuffer_pass(scene, views, shadow_tex, s, centre, radius, timer)
            with timer.stage("irradiance"):
                irradiance.run(self._program(("irradiance",)), points, scene, views, shadow_tex, s)
            out = self._targets.get("dipole_out", (W, H), 2)
            with timer.stage("gather"):
                dispatches = gathers.run_dense(self._program(("dense", kernel)), kernel, points, medium, gb,
                                               out.textures[0], out.textures[1], scene, spacing * mat.mfp)
            if params.terms == "both":
                s1 = single_pass.run(self, scene, params, medium, views, timer, work, info, gb, out.textures[0],
                                     out.textures[1], add=True)
            sub = gbuffer.read(out.textures[0], W, H)
            full = gbuffer.read(out.textures[1], W, H)
            gpos = gbuffer.read(gb.textures[0], W, H)
            mask = gpos[..., 3] > 0.5
            flux = points.read_flux()                                   # outside the timers
            vis = np.concatenate([gbuffer.read(gb.textures[3], W, H), gbuffer.read(gb.textures[4], W, H)], -1)
            gview = {"position": gpos[..., :3], "normal": gbuffer.read(gb.textures[1], W, H)[..., :3],
                     "visibility": vis[..., :L], "mask": mask}
            diffusion = sub[..., :3] - s1 if params.terms == "both" else sub[..., :3]
            info["check"] = check.check_dense(kernel, scene, mat, entry.host, flux, gview, diffusion,
                                              spacing * mat.mfp)
            lit = (flux[..., 3] > 0).sum(axis=1)                        # lit samples per light
            per_pixel = int(lit.sum()) if kernel == "dirpole" else int(np.any(flux[..., 3] > 0, axis=0).sum())
            # far field: the lit samples; near field: the quadrature, counted for every covered pixel and light
            near = N_RAD * (N_PHI * L if kernel == "dirpole" else 1)
            work.update(gbuffer=W * H, irradiance=points.count * L, gather=int(mask.sum()) * (per_pixel + near))
            info.update(samples=points.count, spacing=spacing * mat.mfp, spacing_used=spacing, dispatches=dispatches)
            if debug:
                if params.terms == "both":
                    dbg["single_pass"] = self._last_single
                dbg.update(position=gview["position"], normal=gview["normal"],
                           reflection=gbuffer.read(gb.textures[2], W, H)[..., :3], flux=flux,
                           samples=entry.host, visibility=gview["visibility"], spacing=spacing * mat.mfp)
        elif params.gather == "hierarchical":
            sub, full, mask = hierarchical.render(self, scene, kernel, params, mat, medium, views, shadow_tex, centre,
                                                  radius, timer, work, info, pre_ms, pre_work, dbg)
            if params.terms == "both":           # S^(1) on the gather's G-buffer, added to its (checked) output
                sub, full = single_pass.added(self, "dipole_out", scene, params, medium, views, timer, work, info,
                                              dbg)
        elif params.gather == "atlas":
            sub, full, mask, out = atlas_gather.render(self, scene, kernel, params, mat, views, shadow_tex, centre,
                                                       radius, timer, work, info, pre_ms, pre_work, dbg)
            if params.terms == "both":           # S^(1) on the G-buffer, added to the (checked) pass-3 images
                gb = self._gbuffer_pass(scene, views, shadow_tex, s, centre, radius, timer)
                work["gbuffer"] = W * H
                single_pass.run(self, scene, params, medium, views, timer, work, info, gb, out.textures[1],
                                out.textures[0], add=True)
                full, sub = gbuffer.read(out.textures[0], W, H), gbuffer.read(out.textures[1], W, H)
                if debug:
                    dbg["single_pass"] = self._last_single
        else:
            pre, points, vbufs = self._fitted_vertex_data(scene, mat, kernel, params)
            for k, v in pre.times_ms.items():
                pre_ms[k] = v
            pre_work.update(remesh=len(pre.positions), neighbourhoods=pre.pairs, display=len(pre.display_index))
            with timer.stage("irradiance"):
                irradiance.run(self._program(("irradiance",)), points, scene, views, shadow_tex, s)
            with timer.stage("gather"):
                dispatches = gathers.run_vertex(self._program(("vertex", kernel)), kernel, points, vbufs, medium,
                                                scene)
            out = self._targets.get("dipole_vertex_out", (W, H), 2)
            with timer.stage("shading"):
                gathers.run_display(self._program(("display",)), vbufs)
                prog = self._program(("shade",))
                shade.run(self.ctx, prog, self._mesh_vao(scene, prog, ("shade_vertex", kernel, pre.edge, params.range),
                                                          vbufs.b_display), out, scene,
                          views, shadow_tex, s, centre, radius)
            if params.terms == "both":
                gb = self._gbuffer_pass(scene, views, shadow_tex, s, centre, radius, timer)
                work["gbuffer"] = W * H
                s1 = single_pass.run(self, scene, params, medium, views, timer, work, info, gb, out.textures[1],
                                     out.textures[0], add=True)
                if debug:
                    dbg["single_pass"] = self._last_single
            full = gbuffer.read(out.textures[0], W, H)
            sub = gbuffer.read(out.textures[1], W, H)
            mask = sub[..., 3] > 0.5
            flux = points.read_flux()
            if kernel == "dirpole":
                lit = flux[..., 3] > 0                                  # (L, V)
                per_vertex = lit[:, pre.neighbours].sum() if pre.pairs else 0
                gwork = int(per_vertex)
            else:
                gwork = pre.pairs
            work.update(irradiance=points.count * L, gather=gwork, shading=W * H + len(pre.display_index))
            b = vbufs.read_b()
            info["check"] = check.check_vertex(kernel, scene, mat, pre, flux, b)
            info.update(vertices=len(pre.positions), pairs=pre.pairs, radius=pre.radius, edge=pre.edge,
                        display_vertices=len(pre.display_index), density_used=pre.density, dispatches=dispatches)
            if debug:
                dbg.update(flux=flux, b=b, b_display=vbufs.read_display(), pre=pre)
        return DipoleResult(
            full=np.ascontiguousarray(full[..., :3]), subsurface=np.ascontiguousarray(sub[..., :3]), mask=mask,
            timings_ms=dict(timer.ms), precompute_ms=pre_ms, work=work, precompute_work=pre_work,
            gl_renderer=self.gl_renderer, warnings=list(self.warnings) + warnings + timer.warnings, info=info,
            debug=dbg)

    def _render_single_only(self, scene, params, mat, medium, views, shadow_tex, centre, radius, timer, work, info,
                            pre_ms, pre_work, warnings, dbg):
        """``terms = single``: the G-buffer and S^(1) alone (no irradiance, no gather)."""
        cam = scene.camera
        W, H, s = cam.width, cam.height, params.shadow_size
        gb = self._gbuffer_pass(scene, views, shadow_tex, s, centre, radius, timer)
        work["gbuffer"] = W * H
        out = self._targets.get("dipole_out", (W, H), 2)
        single_pass.run(self, scene, params, medium, views, timer, work, info, gb, out.textures[0], out.textures[1],
                        add=False)
        sub = gbuffer.read(out.textures[0], W, H)
        full = gbuffer.read(out.textures[1], W, H)
        if dbg is not None:
            dbg.update(self._last_single)
        return DipoleResult(
            full=np.ascontiguousarray(full[..., :3]), subsurface=np.ascontiguousarray(sub[..., :3]),
            mask=sub[..., 3] > 0.5, timings_ms=dict(timer.ms), precompute_ms=pre_ms, work=work,
            precompute_work=pre_work, gl_renderer=self.gl_renderer,
            warnings=list(self.warnings) + warnings + timer.warnings, info=info, debug=dbg)

    def _fitted_vertex_data(self, scene, mat, kernel, params):
        """:meth:`_vertex_data` at the density of ``params``, or with ``fit = coarsen`` at the density of
        :func:`dipole_gl.sizing.vertex_density`, lowered by ``sizing.RETRY_FACTOR`` while the table is refused."""
        if params.fit != "coarsen":
            return self._vertex_data(scene, mat, kernel, params.density, params.range)
        density = sizing.vertex_density(scene.mesh, mat.mfp, mat.diffusion_length, params.density, params.range)
        for attempt in range(sizing.RETRIES + 1):
            try:
                return self._vertex_data(scene, mat, kernel, density, params.range)
            except InputError as exc:
                if exc.field != "range" or attempt == sizing.RETRIES:      # only the table's size is retried
                    raise
                density = sizing.check_density(round(density * sizing.RETRY_FACTOR, 6))

    @_current
    def vertex_b(self, scene, kernel, pre):
        """The vertex gather's ``B`` (V, 3) and the flux (L, V, 4) for a given precomputation ``pre``
        (:class:`dipole_gl.vertex.VertexPrecomp`): shadow maps, irradiance and the gather of :meth:`render`."""
        self._check_scene(scene)
        _, medium = self._material(scene, kernel)
        views, _, _, _ = rsm.light_views(scene)
        prog = self._program(("rsm",))
        s = DipoleParams().shadow_size
        shadow_tex = rsm.render_shadow_atlas(self.ctx, prog, self._mesh_vao(scene, prog, "rsm"), self._targets, scene,
                                             s, views, slot="dipole_shadow")
        points = irradiance.PointBuffers(self.ctx, pre.positions, pre.normals, pre.areas, len(scene.lights))
        vbufs = gathers.VertexBuffers(self.ctx, pre)
        try:
            irradiance.run(self._program(("irradiance",)), points, scene, views, shadow_tex, s)
            gathers.run_vertex(self._program(("vertex", kernel)), kernel, points, vbufs, medium, scene)
            return vbufs.read_b().copy(), points.read_flux().copy()
        finally:
            points.release()
            vbufs.release()

    @_current
    def gather_at(self, scene, kernel, params, positions, normals, visibility=None):
        """The dense gather's radiance at given exit points (H, W, 3) -> (H, W, 3) float32, and the flux (L, S, 4).

        The same passes as :meth:`render` (shadow maps, irradiance, gather) with the G-buffer
        filled from ``positions``/``normals`` instead of the camera; the camera position still
        gives the exit direction of the Fresnel transmittance.
        """
        if params.gather != "dense":
            raise ValueError("gather_at evaluates the dense gather")
        self._check_scene(scene)
        mat_entry, medium = self._material(scene, kernel)
        views, _, _, _ = rsm.light_views(scene)
        H, W = positions.shape[:2]
        prog = self._program(("rsm",))
        shadow_tex = rsm.render_shadow_atlas(self.ctx, prog, self._mesh_vao(scene, prog, "rsm"), self._targets, scene,
                                             params.shadow_size, views, slot="dipole_shadow")
        mat = mat_entry.value
        points = self._dense_points(scene, mat, params.spacing).value
        gb = self._targets.get("dipole_points", (W, H), 5)
        gbuffer.from_points(gb, positions, normals, visibility)
        irradiance.run(self._program(("irradiance",)), points, scene, views, shadow_tex, params.shadow_size)
        out = self._targets.get("dipole_points_out", (W, H), 2)
        gathers.run_dense(self._program(("dense", kernel)), kernel, points, medium, gb, out.textures[0],
                          out.textures[1], scene.with_resolution(W, H), params.spacing * mat.mfp)
        return gbuffer.read(out.textures[0], W, H)[..., :3].copy(), points.read_flux()

    def _check_scene(self, scene):
        n = len(scene.lights)
        if n > MAX_LIGHTS:
            raise InputError(scene.path, "lights", f"{n} point lights, the dipole renderer supports at most "
                             f"{MAX_LIGHTS}", "remove lights")

    def release(self):
        """Release every GL object and the context."""
        with self.ctx:
            self._release_scene()
        self.ctx.release()


@dataclass
class _Entry:
    value: object
    ms: float
    work: int
    host: object = None

    def release(self):
        if hasattr(self.value, "release"):
            self.value.release()
