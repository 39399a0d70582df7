"""Per-stage GPU times of the GL SSLPV renderer next to the NumPy twin and the paper's Table 1;
``--against REV``: one propagation step of this checkout against ``propagate.comp`` at another commit.

Run: ``.venv/bin/python benchmarks/bench_sslpv.py [--scene jade_veins] [--repeat 3] [--gpu] [--write]``

``--gpu`` refuses a software renderer (llvmpipe, softpipe, SwiftShader) in one line, exit 2, and names the page
``bench_sslpv_gpu``: the stage times that can stand beside the paper's GTX 580.

* GL stage times come from GL timer queries (``GL_TIME_ELAPSED``), median of
  ``--repeat`` renders at 256x256 after one warm-up render (shader JIT).
* "twin" is the wall time of :func:`sslpv_gl.twin.propagate` (float64 NumPy)
  for the same grid, material, steps and skip.
* Paper: Borlum et al. 2011, Table 1, GTX 580, heterogeneous column.
* Finally the wall time of one full 256x256 render at 32^3 / 32 steps once the
  context and shaders are ready (material cached, and with the material built
  from scratch); the requirement is < 2 s on a CPU-only machine.

``--against REV [--N 64,128] [--steps 8] [--rounds 5]`` times one propagation step
(``propagate.comp``) of this checkout against the same stage file at commit REV instead. Both
kernels run in one process on one GL context, on the same random grid and material
(``sslpv_gl.propagate.upload_material``, heterogeneous sigma_lpv, s' and g), in interleaved rounds:
each round times ``--steps`` steps of one kernel, then of the other (the order alternating between
rounds, ABBA), each from the same random grid, so that a change in the machine's load falls on
both. It prints the median ms per step of each, the median of the per-round ratios (this checkout /
the other), and the largest difference between their grids after three steps relative to the
largest coefficient (float rounding only, for a change that keeps the arithmetic). The other
commit's ``propagate.comp`` must take this checkout's uniforms and image units
(``sslpv_gl.propagate.build_program``); ``git show REV:sslpv_gl/shaders/propagate.comp`` supplies
it. ``LP_NUM_THREADS`` as in the environment.

``--write`` writes the printout to ``docs/benchmarks/bench_sslpv.md`` (``bench_sslpv_against.md``
with ``--against``; ``benchmarks/page.py``).
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from harness.errors import InputError


PAPER = {  # Table 1, heterogeneous timings (ms), GTX 580, 1 light
    (32, 8): {"rsm": "0.18-0.45", "injection": "0.12-0.32", "propagation": "1.66-1.67", "shading": "0.14-0.81"},
    (32, 32): {"rsm": "0.21-0.47", "injection": "0.23-0.41", "propagation": "6.68-6.78", "shading": "0.21-0.79"},
    (64, 32): {"rsm": "0.89 (2 lights)", "injection": "0.25 (2 lights)", "propagation": "14.95 (2 lights)",
               "shading": "1.38 (2 lights)"},
}
STAGES = ("rsm", "injection", "propagation", "shading")
#: GL_RENDERER substrings of the software rasterisers that ``--gpu`` refuses.
SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swiftshader", "software")


REPO = Path(__file__).resolve().parents[1]
STAGE = "sslpv_gl/shaders/propagate.comp"


def _other_source(rev):
    proc = subprocess.run(["git", "-C", str(REPO), "show", f"{rev}:{STAGE}"], capture_output=True, text=True)
    if proc.returncode != 0:
        raise InputError("--against", "against", f"git has no {STAGE} at {rev!r}",
                         "pass a commit of this repository that has the stage file")
    return proc.stdout


def _programs(ctx, dirs):
    """The three ACCUMULATE variants of ``propagate.comp`` from the first of ``dirs`` that has it."""
    from sslpv_gl import propagate as P

    return {acc: P.build_program(ctx, "fp32", acc, [], dirs) for acc in P.ACC_MODES}


def bench_against(ctx, N, kernels, steps, rounds):
    from sslpv_gl import propagate as P
    from sslpv_gl.grids import GridSet, read_grid, write_grid

    grid = GridSet(ctx, N, "fp32")
    rng = np.random.default_rng(N)
    shape = (N, N, N, 3)
    P.upload_material(grid, {"sigma_s_prime": rng.uniform(0.2, 1.0, shape), "g": rng.uniform(-0.5, 0.9, shape),
                             "sigma_lpv": rng.uniform(0.0, 4.0, shape)}, 2.0 / N)
    c = rng.standard_normal((N, N, N, 3, 4)).astype(np.float32)
    grids = {}
    for name, progs in kernels.items():
        write_grid(grid.prop_a, c, "fp32")
        out, _ = P.run(ctx, progs, grid, 3, 0)          # also the shaders' first-use compilation
        grids[name] = read_grid(out, "fp32")
    names = list(kernels)
    diff = float(np.abs(grids[names[0]] - grids[names[1]]).max() / np.abs(grids[names[1]]).max())
    ms = {name: [] for name in names}
    for r in range(rounds):
        for name in (names if r % 2 == 0 else names[::-1]):      # ABBA: no kernel always runs first
            write_grid(grid.prop_a, c, "fp32")                   # the same start each time: no drift of the
            ctx.finish()                                         # values (towards denormals) between runs
            t0 = time.perf_counter()
            P.run(ctx, kernels[name], grid, steps, 0)
            ctx.finish()
            ms[name].append((time.perf_counter() - t0) / steps * 1e3)
    ratio = statistics.median(a / b for a, b in zip(ms[names[0]], ms[names[1]]))
    return {"N": N, "ms": ms, "ratio": ratio, "max_rel_diff": diff}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="jade_veins")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--gpu", action="store_true", help="refuse a software renderer; page bench_sslpv_gpu")
    ap.add_argument("--against", help="time propagate.comp against this commit's instead of the stages")
    ap.add_argument("--N", default="64,128", help="--against: grid resolutions")
    ap.add_argument("--steps", type=int, default=8, help="--against: steps per timed run")
    ap.add_argument("--rounds", type=int, default=5, help="--against: interleaved rounds per N")
    args = ap.parse_args(argv)
    if args.against:
        return against(args)

    from harness.scene import load_scene
    from sslpv_gl import twin
    from sslpv_gl.params import SSLPVParams
    from sslpv_gl.renderer import SSLPVRenderer

    t0 = time.perf_counter()
    r = SSLPVRenderer()
    t_ctx = time.perf_counter() - t0
    if args.gpu and any(s in r.gl_renderer.lower() for s in SOFTWARE_RENDERERS):
        print(f"error: --gpu: GL_RENDERER: {r.gl_renderer!r} is a software renderer; run where EGL finds a GPU, "
              "or leave out --gpu", file=sys.stderr)
        return 2
    scene = load_scene(args.scene).with_resolution(args.size, args.size)
    print(f"GL renderer: {r.gl_renderer}   context {t_ctx * 1e3:.0f} ms   scene {scene.name} "
          f"{args.size}x{args.size}, {len(scene.lights)} light(s)")
    print("GL stage times in ms (paper Table 1, GTX 580, heterogeneous, in brackets)")
    print(f"{'config':>10} | " + " | ".join(f"{s:>26}" for s in STAGES) + " | twin prop (ms) | twin/GL")
    print("-" * 150)
    for N, K in ((32, 8), (32, 32), (64, 32)):
        p = SSLPVParams(N=N, steps=K)
        r.render(scene, p)                                   # warm-up: shader JIT, material cache
        runs = [r.render(scene, p).timings_ms for _ in range(args.repeat)]
        gl = {s: statistics.median(t[s] for t in runs) for s in STAGES}
        # the twin on the same propagation work
        mat = r.lpv_material(scene, p)
        c0 = r.inject(r.rsm_texels(scene, p), [l.position for l in scene.lights], scene, p)
        dx = float((scene.medium.bbox_max - scene.medium.bbox_min)[0] / N)
        t0 = time.perf_counter()
        twin.propagate(c0, mat["sigma_lpv"], mat["sigma_s_prime"], mat["g"], dx, K, p.skip)
        t_twin = (time.perf_counter() - t0) * 1e3
        cells = " | ".join(f"{gl[s]:8.2f} [{PAPER[(N, K)][s]}]".rjust(26) for s in STAGES)
        print(f"{N:>4}^3/{K:<3} | {cells} | {t_twin:14.1f} | {t_twin / gl['propagation']:6.1f}x")

    # ---- full render wall time, 32^3 / 32 steps, context and shaders ready
    p = SSLPVParams(N=32, steps=32)
    r.render(scene, p)
    walls = []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        r.render(scene, p)
        walls.append(time.perf_counter() - t0)
    r._material_cache.clear()
    t0 = time.perf_counter()
    res = r.render(scene, p)
    cold = time.perf_counter() - t0
    print(f"\nfull {args.size}x{args.size} render, 32^3 / 32 steps: {statistics.median(walls) * 1e3:.0f} ms "
          f"(median of {args.repeat}, material cached); {cold * 1e3:.0f} ms with the material rebuilt "
          f"(host material {res.timings_ms['host_material']:.0f} ms); requirement < 2000 ms")
    return 0


def against(args):
    try:
        try:
            sizes = [int(n) for n in args.N.split(",")]
        except ValueError:
            raise InputError("--N", "N", f"{args.N!r} is not a comma-separated list of integers",
                             "pass e.g. --N 64,128") from None
        if any(n < 2 for n in sizes) or args.steps < 1 or args.rounds < 1:
            raise InputError("--N/--steps/--rounds", "value", "N must be >= 2, steps and rounds >= 1",
                             "raise the value")
        other = _other_source(args.against)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None

    from sslpv_gl import shaders as S
    from sslpv_gl.context import create_context

    ctx = create_context()
    print(f"GL renderer: {ctx.info['GL_RENDERER']}; this checkout against {args.against}")
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "propagate.comp").write_text(other)
        kernels = {"this": _programs(ctx, (S.SHADER_DIR,)), args.against: _programs(ctx, (Path(tmp), S.SHADER_DIR))}
        for n in sizes:
            r = bench_against(ctx, n, kernels, args.steps, args.rounds)
            med = {k: statistics.median(v) for k, v in r["ms"].items()}
            print(f"N = {n}: this {med['this']:.1f} ms/step, {args.against} {med[args.against]:.1f} ms/step, "
                  f"median ratio this/{args.against} {r['ratio']:.3f} over {args.rounds} rounds of {args.steps} "
                  f"steps; grids after 3 steps differ by {r['max_rel_diff']:.1e} of the largest coefficient",
                  flush=True)

    return 0


if __name__ == "__main__":
    from page import run

    raise SystemExit(run(main, lambda argv: ("bench_sslpv_against" if "--against" in argv else
                                             "bench_sslpv_gpu" if "--gpu" in argv else "bench_sslpv"),
                         lambda argv: ("SSLPV's stage times on a GPU's OpenGL" if "--gpu" in argv and
                                       "--against" not in argv else "SSLPV's stage times on this machine's OpenGL")))
