"""One propagation step (``propagate.comp``) of this checkout against the same stage file at another commit.

Both kernels run in one process on one GL context, on the same random grid and material
(``sslpv_gl.propagate.upload_material``, heterogeneous sigma_lpv, s' and g), in interleaved
rounds: each round times ``--steps`` steps of one kernel, then of the other (the order
alternating between rounds), each from the same random grid, so that a change in the
machine's load falls on both. It prints the median ms per step of each, the
median of the per-round ratios (this checkout / the other), and the largest difference
between their grids after three steps relative to the largest coefficient (float rounding
only, for a change that keeps the arithmetic).

The other commit's ``propagate.comp`` must take this checkout's uniforms and image units
(``sslpv_gl.propagate.build_program``); ``git show REV:sslpv_gl/shaders/propagate.comp``
supplies it, so nothing but this checkout's git history is needed.

Run: ``.venv/bin/python benchmarks/bench_propagate.py --against beac0de [--N 64,128] [--rounds 5]``
(``LP_NUM_THREADS`` as in the environment; one llvmpipe thread per core by default).
"""

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from harness.errors import InputError

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


def bench(ctx, N, kernels, steps, rounds):
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
    ap.add_argument("--against", required=True, help="a commit whose propagate.comp to time against")
    ap.add_argument("--N", default="64,128", help="grid resolutions")
    ap.add_argument("--steps", type=int, default=8, help="steps per timed run")
    ap.add_argument("--rounds", type=int, default=5, help="interleaved rounds per N")
    args = ap.parse_args(argv)
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
            r = bench(ctx, n, kernels, args.steps, args.rounds)
            med = {k: statistics.median(v) for k, v in r["ms"].items()}
            print(f"N = {n}: this {med['this']:.1f} ms/step, {args.against} {med[args.against]:.1f} ms/step, "
                  f"median ratio this/{args.against} {r['ratio']:.3f} over {args.rounds} rounds of {args.steps} "
                  f"steps; grids after 3 steps differ by {r['max_rel_diff']:.1e} of the largest coefficient",
                  flush=True)


if __name__ == "__main__":
    main()
