"""Injection (Sec. 3.1, Eq. 1): RSM texels into the first propagation grid.

.. list-table::
   :header-rows: 1

   * - function
     - paper
     - shaders
     - what
   * - :func:`run`
     - Sec. 3.1, Eq. 1
     - ``inject.vert/frag``, ``unflatten.comp``
     - one point per RSM texel, refracted clamped-cosine lobe times
       ``(1/pi) T Phi_p``, summed per cell by additive blending into the
       atlas; the atlas copied into the destination grid
   * - :func:`depth_offsets`
     - --
     - --
     - ``inject_depth`` (an extension) in scene units per cell: that many
       reduced mean free paths ``1 / sigma_t'`` of the cell's medium, Eq. (J1)
   * - :func:`texel_textures`
     - --
     - --
     - given ``(M, 10)`` texels (conventions, "RSM texels") as the three
       textures that :func:`run` reads, for injecting texels from the host

Injection at depth (an extension)
---------------------------------
The paper injects each texel into the cell that holds its surface point. Next to a
boundary that takes light out, a walk that starts one cell from it rarely reaches the far
side (``docs/diffusion_mapping.md`` Sec. 7, term 2); diffusion theory puts the source
of a normally incident beam one reduced mean free path deep. ``inject_depth = d`` moves
each texel ``d`` reduced mean free paths inwards along ``-n_p``, read in the cell that
holds ``x_p``::

    offset(x_p) = inject_offset + d * mean_c 1 / sigma_t'_c(cell(x_p)),
    sigma_t'_c = sigma_t,c (1 - a_c g_c)                                    (J1)

with the medium resampled onto the LPV grid as the propagation resamples it
(:func:`sslpv_gl.material.resample_medium`), before any calibration's ``sigma_scale``:
the depth is the physical medium's. A cell with no medium (``sigma_t' = 0``) takes the
mean of the cells that have one.

Limits: one depth per cell, the mean over colours (the grid holds one position per point
light, not one per colour); the move is along the normal, not along the refracted
direction; a move deeper than the object (a thin part, a large ``d``) lands in a cell
outside it, clamped into the grid, not reflected back.

Why a 2D atlas
--------------
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
"""

from __future__ import annotations

import math

import numpy as np

from . import shaders as _sh
from .grids import FORMATS, LOCAL_SIZE

__all__ = ["build_program", "build_unflatten", "run", "texel_textures", "depth_offsets"]

_TEXEL_ROW = 256        # texels per row of an uploaded texel texture


def build_program(ctx, warnings):
    """The injection program; its three texel samplers sit on units 0-2 for good, the depth grid on unit 3."""
    prog = _sh.program(ctx, "inject.vert", "inject.frag")
    names = ["u_pos", "u_nrm", "u_flux", "u_width", "u_light", "u_bbox_min", "u_dx", "u_N",
             "u_eta", "u_offset", "u_depth", "u_depth_on", "u_tiles_x", "u_atlas_size"]
    present = _sh.check_uniforms(prog, names, "inject", warnings)
    for unit, name in enumerate(("u_pos", "u_nrm", "u_flux", "u_depth")):
        if name in present:
            prog[name].value = unit
    return prog


def build_unflatten(ctx, precision, warnings):
    """The atlas -> 3D grid copy for a grid ``precision``; the atlas samplers sit on units 0-2."""
    fmt = FORMATS[precision][0]
    prog = _sh.compute(ctx, "unflatten.comp", {"FORMAT": fmt, "LOCAL": LOCAL_SIZE})
    names = ["u_atlas_r", "u_atlas_g", "u_atlas_b", "u_N", "u_tiles_x", "u_dst_r", "u_dst_g", "u_dst_b"]
    present = _sh.check_uniforms(prog, names, "unflatten", warnings)
    for unit, name in enumerate(names[:3]):
        if name in present:
            prog[name].value = unit
    return prog


def depth_offsets(medium, N, depth, method="box", resampled=None):
    """Eq. (J1) without ``inject_offset``: ``depth`` reduced mean free paths of each cell's medium at grid ``N``
    -> (N,N,N) float64, indexed ``[z, y, x]``, in scene units. ``resampled``: the medium's
    :func:`~sslpv_gl.material.resample_medium` at ``N`` with ``method`` where the caller has it (as
    :func:`~sslpv_gl.material.lpv_material` takes it)."""
    from .material import resample_medium

    st, a, g = resampled if resampled is not None else resample_medium(medium, int(N), method)
    red = st * (1.0 - a * g)
    has = red > 0.0
    count = has.sum(axis=-1)
    total = np.where(has, 1.0 / np.where(has, red, 1.0), 0.0).sum(axis=-1)
    ell = np.where(count > 0, total / np.maximum(count, 1), 0.0)
    if (count > 0).any():
        ell = np.where(count > 0, ell, ell[count > 0].mean())
    return float(depth) * ell


def run(ctx, prog, points, unflatten, grid, sources, bbox_min, bbox_max, eta, offset, dst, depth=None):
    """Inject ``sources`` into ``grid``'s atlas and copy it into ``dst`` (three 3D textures).

    ``depth``: None (the paper), or an (N,N,N) R32F texture of :func:`depth_offsets`, added to ``offset``.

    ``prog`` and ``unflatten`` come from :func:`build_program` and
    :func:`build_unflatten` (for ``grid.precision``); ``points`` is an empty
    vertex array of ``prog`` (the vertex shader fetches its texel by
    ``gl_VertexID``). ``sources``: list of ``((pos, nrm, flux) textures, texel
    count, light position)``.
    """
    set_ = _sh.set_uniform
    N = grid.N
    grid.atlas_fbo.use()
    grid.atlas_fbo.viewport = (0, 0) + grid.atlas_size
    grid.atlas_fbo.clear(0.0, 0.0, 0.0, 0.0)
    ctx.disable(ctx.DEPTH_TEST)
    ctx.enable(ctx.BLEND)
    ctx.enable(ctx.PROGRAM_POINT_SIZE)
    ctx.blend_func = ctx.ONE, ctx.ONE            # Eq. 1's sum, in primitive order
    ctx.blend_equation = ctx.FUNC_ADD
    bmin = np.asarray(bbox_min, dtype=np.float64)
    dx = (np.asarray(bbox_max, dtype=np.float64) - bmin) / N
    set_(prog, "u_bbox_min", tuple(map(float, bmin)))
    set_(prog, "u_dx", tuple(map(float, dx)))
    set_(prog, "u_N", N)
    set_(prog, "u_eta", float(eta))
    set_(prog, "u_offset", float(offset))
    set_(prog, "u_depth_on", int(depth is not None))
    if depth is not None:
        depth.use(3)
    set_(prog, "u_tiles_x", grid.tiles_x)
    set_(prog, "u_atlas_size", tuple(map(float, grid.atlas_size)))
    for texs, count, light_pos in sources:
        for unit, t in enumerate(texs):
            t.use(unit)
        set_(prog, "u_width", texs[0].width)
        set_(prog, "u_light", tuple(map(float, light_pos)))
        points.render(ctx.POINTS, vertices=int(count))
    ctx.disable(ctx.BLEND)
    # ---- atlas -> 3D grid
    set_(unflatten, "u_N", N)
    set_(unflatten, "u_tiles_x", grid.tiles_x)
    for unit, t in enumerate(grid.atlas):
        t.use(unit)
    for unit, t in enumerate(dst):
        t.bind_to_image(unit, read=False, write=True)
    unflatten.run(*grid.groups)
    ctx.memory_barrier()


def texel_textures(ctx, texels):
    """``(M, 10)`` texels -> ``([pos (w = valid), nrm, flux] textures, M)``; the caller releases them."""
    tex = np.asarray(texels, dtype=np.float32).reshape(-1, 10)
    m = tex.shape[0]
    width = _TEXEL_ROW
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
        t = ctx.texture((width, height), 4, data=a.tobytes(), dtype="f4")
        t.filter = (ctx.NEAREST, ctx.NEAREST)
        parts.append(t)
    return parts, m
