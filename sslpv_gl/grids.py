"""The LPV grid textures of one ``(N, precision)``, shared by injection, propagation and shading.

.. list-table::
   :header-rows: 1

   * - textures
     - paper
     - written by
     - read by
   * - ``atlas`` (3 x 2D RGBA32F) and ``atlas_fbo``
     - Sec. 3.1, Eq. 1
     - ``inject.vert/frag`` (additive blending)
     - ``unflatten.comp``
   * - ``prop_a``, ``prop_b`` (3 x 3D each, ping-pong)
     - Sec. 3.2
     - ``unflatten.comp``, ``propagate.comp``
     - ``propagate.comp``
   * - ``accum`` (3 x 3D)
     - Sec. 4 (steps ``k > skip``)
     - ``propagate.comp``
     - ``shade.frag``
   * - ``material`` (2 x 3D RGBA32F)
     - Sec. 3.2.1, Eq. 3
     - the host (:func:`sslpv_gl.propagate.upload_material`)
     - ``propagate.comp``

Each SH grid is three RGBA 3D textures, one per colour, four coefficients each
(``docs/conventions.md``, "SSLPV grids"). ``precision`` applies to the
propagation and accumulation grids (the paper stores 16-bit floats); the atlas
and the material are always fp32.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["FORMATS", "LOCAL_SIZE", "GridSet", "band0", "read_c00", "read_grid", "read_layers", "support",
           "write_grid", "write_layers"]

LOCAL_SIZE = 8          # compute work-group edge: 8^3 measured ~25 % faster than 4^3 on llvmpipe
#: precision -> (GLSL image format, moderngl dtype, NumPy dtype)
FORMATS = {"fp32": ("rgba32f", "f4", np.float32), "fp16": ("rgba16f", "f2", np.float16)}


class GridSet:
    """GL objects for one (N, precision): ping-pong, accumulation, material, injection atlas."""

    def __init__(self, ctx, N, precision):
        _, dt, _ = FORMATS[precision]
        self.N = N
        self.precision = precision
        nearest = (ctx.NEAREST, ctx.NEAREST)

        def tex3(dtype):
            t = ctx.texture3d((N, N, N), 4, dtype=dtype)
            t.filter = nearest
            t.repeat_x = t.repeat_y = t.repeat_z = False
            return t

        self.prop_a = [tex3(dt) for _ in range(3)]
        self.prop_b = [tex3(dt) for _ in range(3)]
        self.accum = [tex3(dt) for _ in range(3)]
        # h = exp(-sigma_lpv dx / 2) (destination), h k1 emit (Eq. 3, source), h emit (source),
        # and h k1 without emit (step 1, when every cell passes on its injected light)
        self.material = [tex3("f4") for _ in range(4)]
        self.r_dr = 0.0                                       # R_dr of boundary_reflect = rdr (u_R), set by upload_material
        self.scale = tex3("f4")                               # per-cell radiance scale (rgb)
        self.scaled = [tex3(dt) for _ in range(3)]            # accumulation x scale: what shading reads
        # The injection atlas: z slice k is the N x N tile (k % tiles_x, k // tiles_x)
        # (why a 2D atlas: sslpv_gl.inject).
        self.tiles_x = int(math.ceil(math.sqrt(N)))
        tiles_y = int(math.ceil(N / self.tiles_x))
        self.atlas_size = (self.tiles_x * N, tiles_y * N)
        self.atlas = [ctx.texture(self.atlas_size, 4, dtype="f4") for _ in range(3)]
        for t in self.atlas:
            t.filter = nearest
        self.atlas_fbo = ctx.framebuffer(color_attachments=self.atlas)
        self.groups = (int(math.ceil(N / LOCAL_SIZE)),) * 3


def write_grid(texs, c, precision):
    """Upload an ``(N, N, N, 3, 4)`` SH grid into three colour textures."""
    dtype = FORMATS[precision][2]
    for col, t in enumerate(texs):
        t.write(np.ascontiguousarray(c[..., col, :], dtype=dtype).tobytes())


def write_layers(texs, layers):
    """Upload :func:`read_layers`' arrays back into three colour textures, byte for byte.

    What a step group uses to restore the injected grid before a second propagation:
    the bytes read are written unchanged, so the restored grid is the injected one exactly.
    """
    for t, layer in zip(texs, layers):
        t.write(np.ascontiguousarray(layer).tobytes())


def read_layers(texs, precision):
    """Three colour textures -> their ``(N, N, N, 4)`` arrays ``[z, y, x, coeff]``, one readback each.

    In the grid's own dtype (views of the bytes read). :func:`read_grid`, :func:`band0`
    and :func:`support` work on them, so that a caller needing two of them reads once.
    """
    dtype = FORMATS[precision][2]
    N = texs[0].width
    return [np.frombuffer(t.read(), dtype=dtype).reshape(N, N, N, 4) for t in texs]


def read_grid(texs, precision):
    """Three colour textures -> ``(N, N, N, 3, 4)`` float32 ``[z, y, x, colour, coeff]``."""
    return np.stack(read_layers(texs, precision), axis=3).astype(np.float32)


def band0(layers):
    """:func:`read_layers`' arrays -> ``(N, N, N, 3)`` float32 ``[z, y, x, colour]``: the band-0 coefficient only.

    What the renderer's diagnostics need (flux, Eq. 1's ``c00``). At N = 128 a whole grid
    (:func:`read_grid`) is 100 MB and its stacked float32 copy cost more than the read
    itself, once per step count of a step group; this slices each texture's first channel.
    """
    out = np.empty(layers[0].shape[:3] + (3,), dtype=np.float32)
    for col, layer in enumerate(layers):
        out[..., col] = layer[..., 0]
    return out


def read_c00(texs, precision):
    """Three colour textures -> their :func:`band0` ``(N, N, N, 3)`` float32."""
    return band0(read_layers(texs, precision))


def support(layers):
    """The bounds of an SH grid's non-zero cells (:func:`read_layers`' arrays): ``(lo, hi)``, inclusive
    ``(x, y, z)`` int arrays, or None.

    A cell counts when any coefficient of any colour is non-zero. None when the
    whole grid is 0 (then nothing bounds it usefully). What
    :func:`sslpv_gl.propagate.region` dilates, step by step.
    """
    nz = np.zeros(layers[0].shape[:3], dtype=bool)
    for layer in layers:
        nz |= layer.any(axis=-1)
    if not nz.any():
        return None
    zyx = [np.flatnonzero(nz.any(axis=tuple(a for a in range(3) if a != axis))) for axis in range(3)]
    lo = np.array([zyx[2][0], zyx[1][0], zyx[0][0]])       # (x, y, z): the textures are [z, y, x]
    hi = np.array([zyx[2][-1], zyx[1][-1], zyx[0][-1]])
    return lo, hi
