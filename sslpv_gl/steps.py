"""One SSLPV propagation shaded at its step counts: snapshots, the ``auto`` convergence check, the ``steady`` solve.

The injected grid is propagated once (Sec. 3.2, Eq. 3) with the material of a group of
step counts that share a mapping family and ``sigma_scale``; the shading pass (Sec. 3.3)
runs as each count passes, with that count's own radiance scale (a calibrated mapping has
one per budget), so every image equals a render of its count alone. ``steps = auto`` stops
at the first check (every 8 steps) where the propagating flux falls below
``converge_tol`` of the injected one; ``steps = steady`` solves the accumulation on the
host (:func:`sslpv_gl.steady.steady_state`, matrix-free from ``STENCIL_MIN_N`` on, so that
``N = 128`` fits in memory), whose wall time is its propagation time.
The propagation's GL time excludes the shading passes and the convergence checks.
"""

import time

import numpy as np

from . import propagate as propagation
from . import shade as shading
from .diagnostics import _diagnostics, _flux
from .grids import read_c00, write_grid
from .params import STEP_MODES
from .timing import _gpu_ms


def propagate_and_shade(renderer, scene, params, ks, resolved, grid, dx, c0, bounds, inj, want_diag, light,
                        shared, stage, stage_wall, warnings):
    """One propagation from the injected ``grid.prop_a`` with the material of ``ks`` (step counts that share
    ``resolved[k]``'s family and sigma_scale), shaded at each count with its own radiance scale.

    Returns ``[(buffers, timings, steps_used, diagnostics, resolved), ...]`` in the order shaded.
    """
    ctx = renderer.ctx
    views, shadow_tex, centre, radius = light
    mode = params.steps if params.steps in STEP_MODES else None
    t0 = time.perf_counter()
    first = params.replace(steps=ks[0]) if mode is None else params
    material = renderer.lpv_material(scene, first)
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
            acc = renderer._scale(grid) if scaled else None
            target = renderer._shade(scene, params, grid, views, shadow_tex, centre, radius, acc)
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
                                 skip=params.skip, emit=material["emit"], empty=material.get("empty"),
                                 r_dr=material.get("r_dr", 0.0), inside=material["inside"],
                                 operator="auto")        # matrix-free from STENCIL_MIN_N on: N = 128 fits
        write_grid(grid.accum, acc, params.precision)
        ctx.finish()
        prop_ms = (time.perf_counter_ns() - t) / 1e6       # a host solve: its wall time is its cost
        warnings.append(f"steps=steady: accumulation solved on the host ({info.get('method', 'krylov')}, "
                        f"{info.get('operator')} operator, {info.get('iterations')} iterations); its propagation "
                        "time is host wall time")
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
        renderer._propagate(grid, last, params.skip, on_step, bounds)
    return outputs


def _with_global_scale(material, r):
    """The material with the resolved global radiance scale ``r`` folded into its per-cell one, and with
    a calibrated form's per-cell ``radiance_factor`` (Eq. F1 of :mod:`sslpv_gl.material_form`)."""
    factor = material.get("radiance_factor")
    if r == 1.0 and factor is None:
        return material
    out = dict(material)
    out["radiance_scale"] = np.asarray(material.get("radiance_scale", 1.0), dtype=np.float64) * r
    if factor is not None:
        out["radiance_scale"] = out["radiance_scale"] * factor
    return out
