"""The hierarchical gather's frame (``gather = "hierarchical"``), run by :class:`dipole_gl.renderer.DipoleRenderer`.

Precomputation (host, timed apart from the frame, cached per scene and spacing): the dense
gather's surface samples (``sampling``, :func:`dipole_gl.sampling.surface_samples`) and their
octree (``octree``, :func:`dipole_gl.octree.build`). Frame stages: ``shadow`` (the renderer's),
``gbuffer``, ``irradiance`` over the octree's samples, ``aggregate`` (host) and ``gather``
(:mod:`dipole_gl.tree_gather`). Every render recomputes :data:`dipole_gl.check.CHECK_POINTS`
pixels with the twin (:func:`dipole_gl.check.check_tree`).

An octree whose largest storage buffer exceeds the GL's limit (``GL_MAX_SHADER_STORAGE_BLOCK_SIZE``) is
refused with one line before any frame work. ``fit = coarsen`` keeps the spacing where the samples fit :data:`dipole_gl.sampling.MAX_SAMPLES`
and coarsens it just enough otherwise (:func:`dipole_gl.sizing.dense_spacing` with no pixel-pair
budget: the descent's cost does not grow as pixels x samples).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from harness.errors import InputError

from . import check, gbuffer, irradiance, octree, sizing, tree_gather
from .sampling import N_PHI, radial_nodes, surface_samples

__all__ = ["TreeData", "tree_data", "render"]

N_RAD = len(radial_nodes()[0])


@dataclass
class TreeData:
    tree: octree.Octree
    points: irradiance.PointBuffers
    buffers: tree_gather.TreeBuffers
    sampling_ms: float
    octree_ms: float

    def release(self):
        self.points.release()
        self.buffers.release()


def tree_data(renderer, scene, mat, spacing):
    """The samples at ``spacing`` (in ``l'``), their octree and its GPU buffers, cached per scene."""
    c = renderer._cache(scene)
    key = ("tree", spacing)
    if key not in c:
        t0 = time.perf_counter()
        pos, nrm, area = surface_samples(scene.mesh, spacing * mat.mfp)
        t1 = time.perf_counter()
        tree = octree.build(pos, nrm, area)
        t2 = time.perf_counter()
        L = len(scene.lights)
        need, limit = tree_gather.largest_buffer(tree, L), tree_gather.storage_limit(renderer.ctx)
        if need > limit:
            raise InputError("--spacing", "spacing", f"the hierarchical gather's octree of {len(pos):,} samples "
                             f"needs a storage buffer of {need:,} bytes, over this GL's {limit:,}",
                             "raise --spacing (the buffers shrink as its square)")
        c[key] = TreeData(tree, irradiance.PointBuffers(renderer.ctx, tree.positions, tree.normals, tree.areas, L),
                          tree_gather.TreeBuffers(renderer.ctx, tree, L), (t1 - t0) * 1e3, (t2 - t1) * 1e3)
    return c[key]


def render(renderer, scene, kernel, params, mat, medium, views, shadow_tex, centre, radius, timer, work, info, pre_ms,
           pre_work, dbg):
    """One frame of the hierarchical gather -> ``(subsurface, full, mask)`` (H, W, 4) images; fills the dicts."""
    ctx = renderer.ctx
    cam = scene.camera
    L, W, H, s = len(scene.lights), cam.width, cam.height, params.shadow_size
    spacing = params.spacing
    if params.fit == "coarsen":
        spacing = sizing.dense_spacing(scene.mesh, mat.mfp, params.spacing)
    data = tree_data(renderer, scene, mat, spacing)
    tree, points = data.tree, data.points
    pre_ms.update(sampling=data.sampling_ms, octree=data.octree_ms)
    pre_work.update(sampling=points.count, octree=tree.nodes)
    gb = renderer._gbuffer_pass(scene, views, shadow_tex, s, centre, radius, timer)
    with timer.stage("irradiance"):
        irradiance.run(renderer._program(("irradiance",)), points, scene, views, shadow_tex, s)
    ctx.finish()
    t = time.perf_counter()
    flux = points.read_flux()
    agg = octree.aggregate(tree, flux, octree.to_lights(tree, scene.lights))
    tree_gather.upload_aggregates(data.buffers, agg)
    ctx.finish()
    timer.ms["aggregate"] = (time.perf_counter() - t) * 1e3          # host work: no GL query
    out = renderer._targets.get("dipole_out", (W, H), 2)
    h = spacing * mat.mfp
    with timer.stage("gather"):
        dispatches, state = tree_gather.run_tree(renderer._program(("tree", kernel)), renderer._program(("dense", kernel)),
                                                 kernel, points, data.buffers, medium, gb, out.textures[0],
                                                 out.textures[1], scene, h, params.epsilon)
    sub = gbuffer.read(out.textures[0], W, H)
    full = gbuffer.read(out.textures[1], W, H)
    gpos = gbuffer.read(gb.textures[0], W, H)
    mask = gpos[..., 3] > 0.5
    state = state[::-1]                                              # row 0 at the top, as the images
    vis = np.concatenate([gbuffer.read(gb.textures[3], W, H), gbuffer.read(gb.textures[4], W, H)], -1)
    gview = {"position": gpos[..., :3], "normal": gbuffer.read(gb.textures[1], W, H)[..., :3],
             "visibility": vis[..., :L], "mask": mask}
    info["check"] = check.check_tree(kernel, scene, mat, tree, flux, gview, sub[..., :3], h, params.epsilon)
    visits, evals = state[..., 1][mask], state[..., 2][mask]
    near = N_RAD * (N_PHI * L if kernel == "dirpole" else 1)
    work.update(gbuffer=W * H, irradiance=points.count * L, aggregate=tree.internal_count,
                gather=int(evals.sum()) * (L if kernel == "dirpole" else 1) + int(mask.sum()) * near)
    info.update(samples=points.count, spacing=h, spacing_used=spacing, epsilon=params.epsilon, nodes=tree.nodes,
                internal_nodes=tree.internal_count, dispatches=dispatches,
                visits_per_pixel=float(visits.mean()) if len(visits) else 0.0,
                max_visits=int(visits.max()) if len(visits) else 0,
                evaluations_per_pixel=float(evals.mean()) if len(evals) else 0.0)
    if dbg is not None:
        dbg.update(position=gview["position"], normal=gview["normal"], flux=flux, tree=tree, aggregates=agg,
                   visibility=gview["visibility"], spacing=h, state=state)
    return sub, full, mask
