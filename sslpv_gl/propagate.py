"""Propagation (Sec. 3.2, Eq. 3, Sec. 4): the ping-pong of the LPV grid and its accumulation.

.. list-table::
   :header-rows: 1

   * - function
     - paper
     - shaders
     - what
   * - :func:`upload_material`
     - Sec. 3.2.1, Eq. 3
     - --
     - per-cell factors of the transfer rule: half a cell of Beer
       attenuation ``h = exp(-sigma_lpv dx / 2)``, and ``h k1 emit``, ``h emit``
       with Eq. 3's band-1 factor and the emit mask of the SOURCE cell
       (:mod:`sslpv_gl.boundary`)
   * - :func:`run`
     - Sec. 3.2, Sec. 4
     - ``propagate.comp``
     - six-neighbour gather with ``sh.propagation_matrices()`` (their six
       non-zero entries each, ``sh.AXIAL_PATTERN``), ping-pong,
       accumulation of steps ``k > skip``; each step only over
       :func:`region`, the injected support dilated by one cell per step;
       a callback after each step lets the renderer shade snapshots or stop
       at convergence (``steps = auto``)
   * - :func:`scale_accumulation`
     - Sec. 3.3
     - ``scale.comp``
     - the accumulation grid times the per-cell radiance scale, into the grid
       that shading reads

The transfer rule is ``docs/conventions.md``, "SSLPV grids"; the NumPy twin
(:mod:`sslpv_gl.twin`) implements the same rule in float64.

``propagate.comp`` is compiled in three variants per precision (``ACCUMULATE``
define): no accumulation (steps ``k <= skip``), the first accumulated step
(writes the accumulation grid, so it need not be cleared) and later steps
(adds to it).
"""

from __future__ import annotations

import numpy as np

from . import shaders as _sh
from .grids import FORMATS, LOCAL_SIZE
from .rsm import gl_bytes
from .sh import check_axial, propagation_matrices, scatter_factors

__all__ = ["ACC_NONE", "ACC_FIRST", "ACC_ADD", "ACC_MODES", "build_program", "build_scale_program",
           "upload_material", "upload_scale", "region", "run", "scale_accumulation"]

ACC_NONE, ACC_FIRST, ACC_ADD = 0, 1, 2
ACC_MODES = (ACC_NONE, ACC_FIRST, ACC_ADD)
_SAMPLERS = ["u_src_r", "u_src_g", "u_src_b", "u_half", "u_hk1", "u_h0"]     # texture units 0-5


def build_program(ctx, precision, acc, warnings, dirs=(_sh.SHADER_DIR,)):
    """``propagate.comp`` (from the first of ``dirs`` that has it) for a grid ``precision`` and accumulation mode ``acc``.

    The constant uniforms are set here: the sampler units (source grid 0-2,
    material 3-5) and the six propagation matrices ``u_M``, after checking that they
    have the axial pattern whose six entries per matrix the shader multiplies by
    (:func:`sslpv_gl.sh.check_axial`).
    """
    matrices = propagation_matrices()
    check_axial(matrices)
    fmt = FORMATS[precision][0]
    prog = _sh.compute(ctx, "propagate.comp", {"FORMAT": fmt, "LOCAL": LOCAL_SIZE, "ACCUMULATE": acc}, dirs)
    images = ["u_dst_r", "u_dst_g", "u_dst_b"] + (["u_acc_r", "u_acc_g", "u_acc_b"] if acc else [])
    present = _sh.check_uniforms(prog, _SAMPLERS + images + ["u_M", "u_N", "u_lo", "u_hi", "u_R"],
                                 f"propagate[{precision},acc={acc}]", warnings)
    for unit, name in enumerate(_SAMPLERS):
        if name in present:
            prog[name].value = unit
    if "u_M" in present:
        prog["u_M"].write(gl_bytes(matrices))     # (6,4,4) -> 6 column-major mat4
    return prog


def upload_material(grid, material, dx):
    """Write ``material`` (``lpv_material``'s dict, ``(N, N, N, 3)`` each) into ``grid.material``.

    Returns True when the material carries a radiance scale other than 1
    (``radiance_scale`` key), which is then written to ``grid.scale``. A material with
    ``r_dr > 0`` (``boundary_reflect = rdr``, :mod:`sslpv_gl.reflect`) also needs ``inside``
    (``(N, N, N)`` bool): it goes into the alpha of the ``h k1`` textures and ``r_dr`` into
    ``grid.r_dr``, which :func:`run` sets as ``u_R``.
    """
    # Per-cell factors of the transfer rule, formed once here instead of per step
    # and neighbour: h = exp(-sigma dx / 2), half a cell of absorption (Sec. 3.2.1),
    # h * k1 with Eq. 3's band-1 factor k1 = (1 - sp) + sp g of the source, and the
    # source's emit (0 in sink cells, sslpv_gl.boundary) on both source factors.
    N = grid.N
    shape = (N, N, N, 3)
    k1 = scatter_factors(np.asarray(material["sigma_s_prime"], dtype=np.float64).reshape(shape),
                         np.asarray(material["g"], dtype=np.float64).reshape(shape))[..., 1]
    sigma = np.asarray(material["sigma_lpv"], dtype=np.float64).reshape(shape)
    emit = np.broadcast_to(np.asarray(material.get("emit", 1.0), dtype=np.float64), shape)
    half = np.exp(-0.5 * sigma * float(dx))
    # alpha of u_half and u_h0 (textures 0 and 2; 0 is also step 1's u_h0): 1 in empty cells
    # (outside = interior: no transfer between two of them, propagate.comp); 0 otherwise
    empty = material.get("empty")
    alpha = None if empty is None else np.asarray(empty, dtype=np.float64).reshape(shape)[..., 0]
    # alpha of u_hk1 (textures 1 and 3, the latter step 1's): 1 in inside cells where the surface
    # reflects (boundary_reflect = rdr, propagate.comp); 0 otherwise
    r_dr = float(material.get("r_dr", 0.0))
    inside = None if r_dr == 0.0 else np.asarray(material["inside"], dtype=np.float64).reshape(shape[:3])
    grid.r_dr = r_dr
    for i, (tex, arr) in enumerate(zip(grid.material, (half, half * k1 * emit, half * emit, half * k1))):
        tex.write(_rgba(arr, alpha if i in (0, 2) else inside))
    return upload_scale(grid, material)


def upload_scale(grid, material):
    """Write ``material``'s per-cell ``radiance_scale`` (default 1) into ``grid.scale``.

    Returns True when it is other than 1 anywhere (shading then reads the accumulation
    through :func:`scale_accumulation`); nothing is written otherwise. The scale acts
    after propagation, so a step group whose budgets differ only in their radiance scale
    shares one propagation and calls this before each shading pass.
    """
    N = grid.N
    scale = np.broadcast_to(np.asarray(material.get("radiance_scale", 1.0), dtype=np.float64), (N, N, N, 3))
    scaled = bool(np.any(scale != 1.0))
    if scaled:
        grid.scale.write(_rgba(scale))
    return scaled


def _rgba(rgb, alpha=None):
    a = np.zeros(rgb.shape[:3] + (4,), dtype=np.float32)
    a[..., :3] = rgb
    if alpha is not None:
        a[..., 3] = alpha
    return a.tobytes()


def region(support, step, N):
    """The cells that step ``step`` (1, 2, ...) computes: ``support`` dilated by ``step`` cells, within the grid.

    ``support`` is ``(lo, hi)``, the inclusive (x, y, z) bounds of the source grid's
    non-zero cells (:func:`sslpv_gl.grids.support`), or None for the whole grid. A step
    gathers from the six axial neighbours only, so after ``k`` steps nothing has moved
    more than ``k`` cells from where it was injected: every cell beyond the region holds
    exactly 0 (and the accumulation too), which the full-grid step would compute as
    well. ``lo`` is rounded down to a multiple of the work-group edge, so that the
    work groups keep the full-grid dispatch's alignment. Returns ``(lo, hi)`` arrays.
    """
    if support is None:
        return np.zeros(3, dtype=int), np.full(3, N - 1, dtype=int)
    lo, hi = (np.asarray(b, dtype=int) for b in support)
    lo = np.maximum(lo - step, 0) // LOCAL_SIZE * LOCAL_SIZE
    return lo, np.minimum(hi + step, N - 1)


def run(ctx, progs, grid, steps, skip, on_step=None, support=None):
    """Run up to ``steps`` steps from ``grid.prop_a``; returns ``(textures of the last grid, steps run)``.

    ``progs`` maps each of :data:`ACC_MODES` to its :func:`build_program`
    variant for ``grid.precision``. The accumulation grid ``grid.accum`` holds
    the sum of the grids after steps ``k > skip``. ``support`` (``(lo, hi)``: the
    (x, y, z) bounds of ``grid.prop_a``'s non-zero cells, :func:`sslpv_gl.grids.support`)
    limits each step to :func:`region`; the other ping-pong grid and the accumulation
    are then zeroed first, as the cells beyond the region must read 0. None computes
    every cell at every step. ``on_step(step, textures)``, if given, is called after
    every step with the propagation grid's textures; it returns True to stop there
    (convergence, ``steps = auto``).
    """
    N = grid.N
    for prog in progs.values():
        _sh.set_uniform(prog, "u_N", N)
        _sh.set_uniform(prog, "u_R", float(getattr(grid, "r_dr", 0.0)))
    if steps <= skip or support is not None:            # nothing accumulated, or cells left out
        clear(grid.accum, grid)
    if support is not None and steps > 0:               # read beyond step 1's region (step 2, or the caller)
        clear(grid.prop_b, grid)
    src, dst = grid.prop_a, grid.prop_b
    step = 0
    for step in range(1, steps + 1):
        acc = ACC_NONE if step <= skip else (ACC_FIRST if step == skip + 1 else ACC_ADD)
        lo, hi = region(support, step, N)
        _sh.set_uniform(progs[acc], "u_lo", tuple(int(v) for v in lo))
        _sh.set_uniform(progs[acc], "u_hi", tuple(int(v) for v in hi))
        # rebound each step: a callback may shade (and scale) in between, using the same units
        # units 3-5: u_half, u_hk1, u_h0; step 1 sends the injected light on from every cell
        # (it has crossed the surface inwards), so it takes the source factors without emit
        first = step == 1
        for unit, t in enumerate((grid.material[0], grid.material[3] if first else grid.material[1],
                                  grid.material[0] if first else grid.material[2])):
            t.use(3 + unit)
        for unit, t in enumerate(grid.accum):
            t.bind_to_image(3 + unit, read=True, write=True)
        for unit, t in enumerate(src):
            t.use(unit)
        for unit, t in enumerate(dst):
            t.bind_to_image(unit, read=False, write=True)
        progs[acc].run(*(int(v) for v in -(-(hi - lo + 1) // LOCAL_SIZE)))
        ctx.memory_barrier()
        src, dst = dst, src                             # ping-pong
        if on_step is not None and on_step(step, src):
            break
    return src, step


def clear(texs, grid):
    """Zero three grid textures."""
    zero = np.zeros(grid.N ** 3 * 4, dtype=FORMATS[grid.precision][2]).tobytes()
    for t in texs:
        t.write(zero)


def build_scale_program(ctx, precision, warnings):
    """``scale.comp`` for a grid ``precision`` (sampler units: accumulation 0-2, scale 3)."""
    fmt = FORMATS[precision][0]
    prog = _sh.compute(ctx, "scale.comp", {"FORMAT": fmt, "LOCAL": LOCAL_SIZE})
    names = ["u_acc_r", "u_acc_g", "u_acc_b", "u_scale"]
    present = _sh.check_uniforms(prog, names + ["u_N", "u_dst_r", "u_dst_g", "u_dst_b"],
                                 f"scale[{precision}]", warnings)
    for unit, name in enumerate(names):
        if name in present:
            prog[name].value = unit
    return prog


def scale_accumulation(ctx, prog, grid):
    """``grid.scaled = grid.accum * grid.scale`` per cell and colour; returns ``grid.scaled``."""
    _sh.set_uniform(prog, "u_N", grid.N)
    for unit, t in enumerate(grid.accum):
        t.use(unit)
    grid.scale.use(3)
    for unit, t in enumerate(grid.scaled):
        t.bind_to_image(unit, read=False, write=True)
    prog.run(*grid.groups)
    ctx.memory_barrier()
    return grid.scaled
