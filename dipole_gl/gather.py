"""Host side of the gathers: ``gather_dense.comp``, ``gather_vertex.comp`` and ``display.comp``.

Both gathers share the kernels of ``kernels.glsl`` and the exit-point material of
``medium.glsl`` (three 3D textures of the medium, :class:`MediumTextures`); the kernel is a
define of the program (``KERNEL_DIRPOLE``), so each (gather, kernel) is its own program.
"""

from __future__ import annotations

import numpy as np

from sslpv_gl import shaders as _sh

from . import budget, kernels
from .glsl import DIRS, MAX_LIGHTS
from .sampling import N_PHI, NEAR_RADIUS, radial_nodes

__all__ = ["build_dense", "build_vertex", "build_display", "MediumTextures", "set_boundary", "dense_chunk_size", "run_dense",
           "VertexBuffers", "run_vertex", "run_display"]

_BOUNDARY = ("u_A", "u_c_phi", "u_c_e", "u_c_phi_out", "u_A_dir")


def _defines(kernel):
    return {"MAX_LIGHTS": MAX_LIGHTS, "KERNEL_DIRPOLE": int(kernel == "dirpole"), "N_RAD": len(radial_nodes()[0])}


def _medium_units(prog):
    for unit, name in enumerate(("u_sp", "u_sa", "u_st")):
        if name in prog:
            prog[name].value = unit


def build_dense(ctx, kernel, warnings):
    prog = _sh.compute(ctx, "gather_dense.comp", _defines(kernel), dirs=DIRS)
    names = ["u_count", "u_first", "u_end", "u_last", "u_eta", "u_cam_pos", "u_size", "u_sp", "u_sa", "u_bbox_min", "u_bbox_size",
             "u_res", "u_gpos", "u_gnrm", "u_grefl", "u_gvis0", "u_rho", "u_n_rad", "u_rad_t", "u_rad_w",
             "u_light_pos", "u_light_I"]
    # the standard dipole needs neither the unreduced sigma_t nor the light directions
    names += ["u_st", "u_c_phi", "u_c_e", "u_c_phi_out", "u_A_dir", "u_n_phi"] if kernel == "dirpole" else ["u_A"]
    _sh.check_uniforms(prog, names, f"gather_dense[{kernel}]", warnings)
    _medium_units(prog)
    for unit, name in ((3, "u_gpos"), (4, "u_gnrm"), (5, "u_grefl"), (6, "u_gvis0"), (7, "u_gvis1")):
        if name in prog:
            prog[name].value = unit
    t, w = radial_nodes()
    _sh.set_uniform(prog, "u_n_rad", len(t))
    _sh.set_uniform(prog, "u_n_phi", N_PHI)
    for name, data in (("u_rad_t", t), ("u_rad_w", w)):
        if name in prog:
            prog[name].write(np.asarray(data, dtype="f4").tobytes())
    return prog


def build_vertex(ctx, kernel, warnings):
    prog = _sh.compute(ctx, "gather_vertex.comp", _defines(kernel), dirs=DIRS)
    names = ["u_count", "u_k0", "u_k1"] + (["u_n_lights", "u_c_phi", "u_c_e", "u_c_phi_out", "u_A_dir", "u_sp", "u_sa", "u_st",
                            "u_bbox_min", "u_bbox_size", "u_res"] if kernel == "dirpole" else [])
    _sh.check_uniforms(prog, names, f"gather_vertex[{kernel}]", warnings)
    _medium_units(prog)
    return prog


def build_display(ctx, warnings):
    prog = _sh.compute(ctx, "display.comp", dirs=DIRS)
    _sh.check_uniforms(prog, ["u_count"], "display", warnings)
    return prog


class MediumTextures:
    """sigma_s', sigma_a and sigma_t of the medium as three RGBA32F 3D textures (NEAREST, texelFetch)."""

    def __init__(self, ctx, mat):
        nz, ny, nx = mat.inside.shape
        self.res = (nx, ny, nz)
        self.bbox_min, self.bbox_size = mat.bbox_min, mat.bbox_max - mat.bbox_min
        self.textures = []
        for grid in (mat.sigma_s_prime, mat.sigma_a, mat.sigma_t):
            data = np.concatenate([grid, np.zeros(grid.shape[:3] + (1,))], axis=-1).astype("f4")
            t = ctx.texture3d((nx, ny, nz), 4, np.ascontiguousarray(data).tobytes(), dtype="f4")
            t.filter = (ctx.NEAREST, ctx.NEAREST)
            self.textures.append(t)

    def use(self, prog):
        for unit, t in enumerate(self.textures):
            t.use(unit)
        _sh.set_uniform(prog, "u_bbox_min", tuple(map(float, self.bbox_min)))
        _sh.set_uniform(prog, "u_bbox_size", tuple(map(float, self.bbox_size)))
        _sh.set_uniform(prog, "u_res", tuple(int(v) for v in self.res))

    def release(self):
        for t in self.textures:
            t.release()


def set_boundary(prog, eta):
    """The eta-dependent terms of both kernels (quadratures of ``sslpv_gl.boundary``)."""
    m = kernels.material(np.ones(3), np.ones(3), eta)
    for name, key in zip(_BOUNDARY, ("A", "c_phi", "c_e", "c_phi_out", "A_dir")):
        _sh.set_uniform(prog, name, float(m[key]))


def dense_chunk_size(kernel, n_lights):
    """Surface samples per dispatch of ``gather_dense.comp`` (:func:`dipole_gl.budget.dense_chunk`)."""
    return budget.dense_chunk(kernel, n_lights, len(radial_nodes()[0]), N_PHI)


def run_dense(prog, kernel, points, medium, gbuf, out_sub, out_full, scene, spacing, far=None):
    """The dense gather over ``points`` (sample spacing ``spacing``, scene units) for every G-buffer
    pixel -> writes ``out_sub`` and ``out_full``; returns the number of dispatches.

    The far field runs in chunks of :func:`dense_chunk_size` samples, one dispatch each, the
    partial sums accumulating per pixel in a storage buffer; the last dispatch adds the near
    field and writes the images. ``far``: a buffer holding the far field per pixel already
    (the hierarchical gather's, :mod:`dipole_gl.tree_gather`): only the last dispatch runs, over no sample.
    """
    cam = scene.camera
    points.bind()
    medium.use(prog)
    for unit, t in zip((3, 4, 5, 6, 7), gbuf.textures):
        t.use(unit)
    pos = np.zeros((MAX_LIGHTS, 3), dtype="f4")
    inten = np.zeros((MAX_LIGHTS, 3), dtype="f4")
    for i, light in enumerate(scene.lights):
        pos[i], inten[i] = light.position, light.intensity
    for name, data in (("u_light_pos", pos), ("u_light_I", inten)):
        if name in prog:
            prog[name].write(data.tobytes())
    _sh.set_uniform(prog, "u_rho", float(NEAR_RADIUS * spacing))
    out_sub.bind_to_image(0, read=False, write=True)
    out_full.bind_to_image(1, read=False, write=True)
    set_boundary(prog, float(scene.boundary.eta))
    _sh.set_uniform(prog, "u_count", points.count)
    _sh.set_uniform(prog, "u_n_lights", len(scene.lights))
    _sh.set_uniform(prog, "u_eta", float(scene.boundary.eta))
    _sh.set_uniform(prog, "u_cam_pos", tuple(map(float, cam.origin)))
    _sh.set_uniform(prog, "u_size", (cam.width, cam.height))
    accum = prog.ctx.buffer(reserve=cam.width * cam.height * 16) if far is None else far
    accum.bind_to_storage_buffer(5)
    pieces = budget.chunks(points.count, dense_chunk_size(kernel, len(scene.lights))) if far is None else [(1, 1)]
    for k, (first, end) in enumerate(pieces):
        _sh.set_uniform(prog, "u_first", first)
        _sh.set_uniform(prog, "u_end", end)
        _sh.set_uniform(prog, "u_last", int(k == len(pieces) - 1))
        prog.run((cam.width + 7) // 8, (cam.height + 7) // 8)
        prog.ctx.memory_barrier()
    if far is None:
        accum.release()
    return len(pieces)


class VertexBuffers:
    """The neighbourhood table, the display weights and the outputs of the vertex gather on the GPU."""

    def __init__(self, ctx, pre):
        self.count, self.display_count = len(pre.positions), len(pre.display_index)
        self.longest_row = int(np.diff(pre.offsets).max()) if self.count else 0
        self.offsets = ctx.buffer(np.asarray(pre.offsets, dtype="i4").tobytes())
        nbr = pre.neighbours if len(pre.neighbours) else np.zeros(1, np.int32)
        self.nbrs = ctx.buffer(np.asarray(nbr, dtype="i4").tobytes())
        if pre.factors is not None and len(pre.factors):
            f = np.concatenate([pre.factors, np.zeros((len(pre.factors), 1), np.float32)], axis=1)
        else:
            f = np.zeros((1, 4), np.float32)
        self.factors = ctx.buffer(np.ascontiguousarray(f, dtype="f4").tobytes())
        self.b = ctx.buffer(reserve=self.count * 16)
        idx = np.concatenate([pre.display_index, np.zeros((self.display_count, 1), np.int32)], axis=1)
        w = np.concatenate([pre.display_weights, np.zeros((self.display_count, 1))], axis=1)
        self.index = ctx.buffer(np.ascontiguousarray(idx, dtype="i4").tobytes())
        self.weights = ctx.buffer(np.ascontiguousarray(w, dtype="f4").tobytes())
        self.b_display = ctx.buffer(reserve=self.display_count * 16)

    def read_b(self):
        return np.frombuffer(self.b.read(), dtype="f4").reshape(self.count, 4)[:, :3]

    def read_display(self):
        return np.frombuffer(self.b_display.read(), dtype="f4").reshape(self.display_count, 4)[:, :3]

    def release(self):
        for b in (self.offsets, self.nbrs, self.factors, self.b, self.index, self.weights, self.b_display):
            b.release()


def run_vertex(prog, kernel, points, vbufs, medium, scene):
    """``B`` per scattering vertex (``vbufs.b``) from the irradiance in ``points``; returns the number of dispatches.

    Each row of the neighbourhood table runs in chunks of :func:`dipole_gl.budget.vertex_chunk`
    neighbours, one dispatch per chunk index (as many as the longest row needs), the partial
    sums accumulating in ``vbufs.b``.
    """
    points.bind()
    for i, b in zip((5, 6, 7, 8), (vbufs.offsets, vbufs.nbrs, vbufs.factors, vbufs.b)):
        b.bind_to_storage_buffer(i)
    medium.use(prog)
    set_boundary(prog, float(scene.boundary.eta))
    _sh.set_uniform(prog, "u_count", vbufs.count)
    _sh.set_uniform(prog, "u_n_lights", len(scene.lights))
    pieces = budget.chunks(vbufs.longest_row, budget.vertex_chunk(kernel, len(scene.lights)))
    for k0, k1 in pieces:
        _sh.set_uniform(prog, "u_k0", k0)
        _sh.set_uniform(prog, "u_k1", k1)
        prog.run((vbufs.count + 63) // 64)
        prog.ctx.memory_barrier()
    return len(pieces)


def run_display(prog, vbufs):
    """``B`` at the display vertices (``vbufs.b_display``)."""
    for i, b in enumerate((vbufs.b, vbufs.index, vbufs.weights, vbufs.b_display)):
        b.bind_to_storage_buffer(i)
    _sh.set_uniform(prog, "u_count", vbufs.display_count)
    prog.run((vbufs.display_count + 63) // 64)
