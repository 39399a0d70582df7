"""Host side of ``gather_tree.comp``: the hierarchical gather (Jensen & Buhler 2002) on the GPU.

Per frame, after the irradiance pass over the octree's samples (:mod:`dipole_gl.octree`, the
samples in Morton order):

1. ``aggregate`` (host, NumPy): the flux is read back and the internal nodes' aggregates
   (:func:`dipole_gl.octree.aggregate`) are summed and uploaded, as Jensen & Buhler build their
   octree on the CPU after the irradiance pass (a GPU version would reduce level by level);
2. ``gather`` (:func:`run_tree`): the descent of ``gather_tree.comp`` per pixel, at most
   :func:`dipole_gl.budget.tree_chunk` nodes per invocation and dispatch, dispatched again while
   any pixel has nodes left (the count of unfinished pixels is read back after each dispatch),
   then the dense gather's last dispatch over the accumulated far field (near field, exit Fresnel,
   images: :func:`dipole_gl.gather.run_dense` with ``far``).

Limits: the aggregates cross the bus each frame (``(3 + 2 L) x 16`` bytes per internal node), and
the number of dispatches is that of the pixel with the most node visits.
"""

from __future__ import annotations

import math

import numpy as np

from sslpv_gl import shaders as _sh

from . import budget
from . import gather as gathers
from .glsl import DIRS, MAX_LIGHTS
from .sampling import NEAR_RADIUS

__all__ = ["build_program", "TreeBuffers", "upload_aggregates", "largest_buffer", "storage_limit", "run_tree",
           "tree_chunk_size"]


def build_program(ctx, kernel, warnings):
    defines = {"MAX_LIGHTS": MAX_LIGHTS, "KERNEL_DIRPOLE": int(kernel == "dirpole")}
    prog = _sh.compute(ctx, "gather_tree.comp", defines, dirs=DIRS)
    names = ["u_nodes", "u_steps", "u_epsilon", "u_rho", "u_size", "u_sp", "u_sa", "u_bbox_min",
             "u_bbox_size", "u_res", "u_gpos", "u_gnrm"]
    names += ["u_count", "u_st", "u_c_phi", "u_c_e", "u_c_phi_out", "u_A_dir", "u_internal", "u_n_lights", "u_eta"] \
        if kernel == "dirpole" else ["u_A"]
    _sh.check_uniforms(prog, names, f"gather_tree[{kernel}]", warnings)
    for unit, name in enumerate(("u_sp", "u_sa", "u_st")):
        if name in prog:
            prog[name].value = unit
    for unit, name in ((3, "u_gpos"), (4, "u_gnrm")):
        if name in prog:
            prog[name].value = unit
    return prog


def tree_chunk_size(kernel, n_lights):
    """Nodes per invocation and dispatch (:func:`dipole_gl.budget.tree_chunk`)."""
    return budget.tree_chunk(kernel, n_lights)


class TreeBuffers:
    """The octree's nodes (static) and its internal nodes' aggregates (per frame) on the GPU."""

    def __init__(self, ctx, tree, n_lights):
        self.nodes, self.internal = tree.nodes, max(tree.internal_count, 1)
        self.n_lights = n_lights
        self.cell = ctx.buffer(np.ascontiguousarray(tree.cell, dtype="f4").tobytes())
        link = np.stack([tree.first, tree.end, tree.skip, tree.internal], axis=1)
        self.link = ctx.buffer(np.ascontiguousarray(link, dtype="i4").tobytes())
        self.geom = ctx.buffer(reserve=self.internal * 3 * 16)
        self.lights = ctx.buffer(reserve=max(n_lights, 1) * self.internal * 2 * 16)

    def bind(self):
        for i, b in ((6, self.cell), (7, self.link), (8, self.geom), (9, self.lights)):
            b.bind_to_storage_buffer(i)

    def release(self):
        for b in (self.cell, self.link, self.geom, self.lights):
            b.release()


def upload_aggregates(tbufs, agg):
    """Write :class:`dipole_gl.octree.Aggregates` into ``tbufs`` (float32)."""
    K = len(agg.area)
    geom = np.zeros((max(K, 1), 3, 4), np.float32)
    geom[:K, 0, :3], geom[:K, 0, 3] = agg.centroid, agg.area
    geom[:K, 1, :3], geom[:K, 1, 3] = agg.normal, agg.weight
    geom[:K, 2, :3] = agg.total
    tbufs.geom.write(geom.tobytes())
    lights = np.zeros((max(tbufs.n_lights, 1), max(K, 1), 2, 4), np.float32)
    if K and tbufs.n_lights:
        lights[:, :K, 0, :3], lights[:, :K, 1, :3] = agg.flux, agg.to_light
    tbufs.lights.write(lights.tobytes())


def largest_buffer(tree, n_lights):
    """Bytes of the largest storage buffer the hierarchical gather binds (nodes, aggregates, per-light flux)."""
    L, K = max(n_lights, 1), max(tree.internal_count, 1)
    return max(tree.nodes * 16, K * 3 * 16, L * K * 2 * 16, L * len(tree.positions) * 16)


def storage_limit(ctx):
    """The GL's largest shader storage block (bytes); 2^27, the value OpenGL 4.3 guarantees, if unknown."""
    return int(ctx.info.get("GL_MAX_SHADER_STORAGE_BLOCK_SIZE") or 2 ** 27)


def run_tree(prog, dense_prog, kernel, points, tbufs, medium, gbuf, out_sub, out_full, scene, spacing, epsilon):
    """The hierarchical gather for every G-buffer pixel -> writes ``out_sub`` and ``out_full``.

    Returns ``(dispatches, state)``: the descent's dispatches (the last pass not counted) and the
    per-pixel ``(cursor, node visits, kernel evaluations)`` (H, W, 3) int array.
    """
    cam = scene.camera
    W, H = cam.width, cam.height
    ctx = prog.ctx
    points.bind()
    tbufs.bind()
    medium.use(prog)
    for unit, t in zip((3, 4), gbuf.textures[:2]):
        t.use(unit)
    gathers.set_boundary(prog, float(scene.boundary.eta))
    rho = NEAR_RADIUS * spacing
    steps = tree_chunk_size(kernel, len(scene.lights))
    for name, value in (("u_count", points.count), ("u_nodes", tbufs.nodes), ("u_internal", tbufs.internal),
                        ("u_steps", steps), ("u_n_lights", len(scene.lights)), ("u_eta", float(scene.boundary.eta)),
                        ("u_epsilon", float(epsilon)), ("u_rho", float(rho)), ("u_size", (W, H))):
        _sh.set_uniform(prog, name, value)
    accum = ctx.buffer(reserve=W * H * 16)
    accum.clear()
    state = ctx.buffer(reserve=W * H * 16)
    state.clear()
    pending = ctx.buffer(reserve=4)
    accum.bind_to_storage_buffer(5)
    state.bind_to_storage_buffer(10)
    pending.bind_to_storage_buffer(11)
    limit = math.ceil(tbufs.nodes / steps) + 1
    dispatches = 0
    try:
        while True:
            pending.clear()
            prog.run((W + 7) // 8, (H + 7) // 8)
            ctx.memory_barrier()
            dispatches += 1
            left = int(np.frombuffer(pending.read(), dtype="u4")[0])
            if left == 0:
                break
            if dispatches >= limit:
                raise RuntimeError(f"gather_tree: {left} pixels unfinished after {dispatches} dispatches of {steps} "
                                   f"nodes ({tbufs.nodes} nodes)")
        gathers.run_dense(dense_prog, kernel, points, medium, gbuf, out_sub, out_full, scene, spacing, far=accum)
        st = np.frombuffer(state.read(), dtype="i4").reshape(H, W, 4)[..., :3].copy()
    finally:
        for b in (accum, state, pending):
            b.release()
    return dispatches, st
