"""Steady-state solve (``sslpv_gl.steady.steady_state``) against iterated propagation, same tolerance.

Scene: a sphere (radius 0.9 of the half box) of a diffusion-like material,
``sigma_lpv * dx`` = 1e-3 / 2e-3 / 4e-3 per step (R, G, B) and ``k1 = 0.3``
(``sigma_s' = 0.7``, ``g = 0``), vacuum outside (``sigma = 0``, ``k1 = 1``:
light still propagates there and leaves at the grid boundary). ``c0``: Eq. 1
lobes ``clamped_cosine_coeffs(-n) / pi`` (unit flux each) in the surface cells
of a cap around the sphere's ``-x`` pole, pointing inwards.

For each N it measures, in one run:

1. ``steady_state`` (operator build + spectral check + BiCGSTAB), total time;
2. K = the smallest step count whose accumulation grid is within ``--tol``
   (1e-4) of max c00 of the steady state, found by iterating the sparse
   operator and comparing every step (the stopping rule is an oracle here:
   it favours the iterated methods); the time of those K sparse steps alone;
3. ``twin.propagate(steps=K)``, the NumPy twin's rule, timed, and its
   difference to the steady state (which must be below ``--tol``). When K
   steps would take longer than ``--twin-budget`` seconds, 20 steps are
   timed and the time is EXTRAPOLATED (marked ``est.``);
4. the steady state's own error against the sparse iteration continued until
   its geometric tail bound ``max|P^k c0| rho / (1 - rho)`` is below 1e-9 of
   max c00 (skipped with ``--no-reference``).

Run: ``.venv/bin/python benchmarks/bench_steady.py [--sizes 16 32 64]``
(about 1.5 min for N = 16 and 32; N = 64 adds about 10 min with the twin
extrapolated at the default ``--twin-budget 900``, 30 min with the twin run).

Measured (2-core shared VM, one run, ``--sizes 16 32 64 --twin-budget 2400``;
the twin's time at N = 64 is measured, not extrapolated):

::

    N   rho(R)   steady  BiCGSTAB it.  K to   twin K   sparse K  speed-up  speed-up   steady err
                 [s]     (R, G, B)     1e-4   steps[s] steps[s]  vs twin   vs sparse  vs ref
    16  0.97916   0.19   19, 19, 19     374      1.9     0.20      10x       1.0x      4.3e-09
    32  0.99374   1.40   37, 37, 34    1180     58.4     7.53      42x       5.4x      9.8e-09
    64  0.99770  15.65   71, 68, 60    3026   1155.8   137.75      74x       8.8x      7.5e-09

The twin's accumulation after K steps differed from the steady state by
1.0e-4 of max c00 at every N (by construction of K). N = 64 steady: operator
1.15 s, spectral check 4.31 s, solve 9.07 s.

``--operator sparse|stencil|auto`` (default ``auto``) is ``steady_state``'s operator
(:mod:`sslpv_gl.stencil`: matrix-free). ``--steady-only`` skips 2-4 (far too slow at
N = 128) and runs each (scene, N, operator) solve in a fresh process of its own
(``--case``), reporting the time split (operator build, spectral check, solve), the
BiCGSTAB iterations, the peak resident memory of that process (``ru_maxrss`` from
``os.wait4`` on that child alone: interpreter, NumPy, SciPy, the scene and the solve; its
resident set when the call began is printed beside it) and, with several operators, the
largest difference between their grids. ``--scenes``: the sphere with its outside as
``vacuum`` (above), ``absorb`` (sink cells), ``interior`` (no transfer between two outside
cells) or ``rdr`` (``boundary_reflect = rdr``, eta 1.4). Figures:
:mod:`sslpv_gl.stencil` ("Memory and time"), from
``benchmarks/bench_steady.py --steady-only --sizes 32 64 128 --operator sparse stencil
[--scenes ...]``: about 6 min for the vacuum sphere with both operators, 4-6 min per further
scene with the stencil alone; ``--write`` puts its printout on ``bench_steady_memory.md``.

``OPENBLAS_NUM_THREADS`` is set to 1 unless already set (``--blas-threads``):
on the 2-core machine, while other jobs were running, OpenBLAS' threads made
the Krylov vector operations of an N = 32 solve 12x slower (5.8 s against
0.46 s).
"""

from __future__ import annotations

import argparse
import os
import sys


def _early_threads(argv):
    # must happen before numpy is imported
    n = "1"
    if "--blas-threads" in argv:
        n = argv[argv.index("--blas-threads") + 1]
    os.environ.setdefault("OPENBLAS_NUM_THREADS", n)


_early_threads(sys.argv)

import json  # noqa: E402
import resource  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from sslpv_gl import steady, twin  # noqa: E402
from sslpv_gl.sh import clamped_cosine_coeffs  # noqa: E402

LOSS = (1e-3, 2e-3, 4e-3)     # sigma_lpv * dx per colour
K1 = 0.3


def scene(N, radius=0.9, cap_deg=25.0, with_inside=False):
    dx = 2.0 / N
    x = (np.arange(N) + 0.5) * dx - 1.0
    Z, Y, X = np.meshgrid(x, x, x, indexing="ij")
    inside = X**2 + Y**2 + Z**2 < radius**2
    sig = np.zeros((N, N, N, 3))
    sp = np.zeros((N, N, N, 3))
    sig[inside] = np.asarray(LOSS) / dx
    sp[inside] = 1.0 - K1                                  # g = 0: k1 = 1 - sp
    g = np.zeros((N, N, N, 3))
    # surface cells: inside with a face neighbour outside
    pad = np.pad(inside, 1)
    outside_nb = np.zeros_like(inside)
    for ax in range(3):
        for sh in (1, -1):
            outside_nb |= ~np.roll(pad, sh, axis=ax)[1:-1, 1:-1, 1:-1]
    surf = inside & outside_nb
    pos = np.stack([X, Y, Z], axis=-1)
    n = pos / np.linalg.norm(pos, axis=-1, keepdims=True)
    cap = surf & (n[..., 0] < -np.cos(np.radians(cap_deg)))
    c0 = np.zeros((N, N, N, 3, 4))
    c0[cap] = (clamped_cosine_coeffs(-n[cap]) / np.pi)[:, None, :]   # inward lobe, unit flux, all colours
    if with_inside:
        return c0, sig, sp, g, dx, int(cap.sum()), inside
    return c0, sig, sp, g, dx, int(cap.sum())


#: ``--steady-only`` scenes: the sphere above with its outside as ``outside`` of sslpv_gl.boundary
#: (``vacuum``, ``absorb``: sink cells, ``interior``: no transfer between two outside cells) or with
#: ``boundary_reflect = rdr`` at ``eta = 1.4`` (vacuum outside; the operator gains diagonal blocks).
SCENES = ("vacuum", "absorb", "interior", "rdr")


def scene_args(N, name):
    """``(c0, sig, sp, g, dx, lobes, steady_state keyword arguments)`` of a ``--steady-only`` scene."""
    from sslpv_gl import boundary, reflect

    c0, sig, sp, g, dx, lobes, inside = scene(N, with_inside=True)
    kw = {}
    if name == "absorb":
        kw["emit"] = boundary.outside_masks(inside, "absorb")[1]
    elif name == "interior":
        kw["empty"] = boundary.empty_mask(inside, "interior")
    elif name == "rdr":
        kw.update(r_dr=reflect.reflectance("rdr", 1.4), inside=inside)
    return c0, sig, sp, g, dx, lobes, kw


def err_c00(a, ref, scale):
    return float((np.abs(a - ref).max(axis=(0, 1, 2, 4)) / scale).max())


def bench(N, tol, twin_budget, reference, max_steps, operator="auto"):
    c0, sig, sp, g, dx, n_lobes = scene(N)
    row = {"N": N, "unknowns": 4 * N**3, "lobes": n_lobes}

    t0 = time.perf_counter()
    accum, info = steady.steady_state(c0, sig, sp, g, dx, skip=2, operator=operator)
    row["t_steady"] = time.perf_counter() - t0
    row["info"] = info
    scale = np.abs(accum[..., 0]).max(axis=(0, 1, 2))                 # max c00 per colour

    # 2. sparse iteration until the accumulation is within tol of the steady state
    ops = steady.transfer_operator(sig, sp, g, dx)
    c = [c0[..., k, :].reshape(-1).copy() for k in range(3)]
    acc = [np.zeros(4 * N**3) for _ in range(3)]
    xs = [accum[..., k, :].reshape(-1) for k in range(3)]
    t_iter, K, k = 0.0, None, 0
    rho = max(info["rho"])
    inj = np.abs(c0[..., 0]).sum(axis=(0, 1, 2))
    while k < max_steps:
        t = time.perf_counter()
        k += 1
        for j in range(3):
            c[j] = ops[j] @ c[j]
            if k > 2:
                acc[j] += c[j]
        t_iter += time.perf_counter() - t
        if K is None:
            e = max(float(np.abs(acc[j] - xs[j]).max() / scale[j]) for j in range(3))
            if e < tol:
                K, row["t_sparse"] = k, t_iter
                row["remaining_at_K"] = max(float(np.abs(c[j][0::4]).sum() / inj[j]) for j in range(3))
                if not reference:
                    break
        if K is not None and reference:
            tail = max(float(np.abs(c[j]).max() / scale[j]) for j in range(3)) * rho / (1 - rho)
            if tail < 1e-9:
                ref = np.stack([a.reshape(N, N, N, 4) for a in acc], axis=3)
                row["err_steady_vs_ref"] = err_c00(accum, ref, scale)
                row["K_ref"] = k
                break
    if K is None:
        raise SystemExit(f"N={N}: not within tol after {max_steps} steps; raise --max-steps")
    row["K"] = K

    # 3. the twin's rule for K steps
    t = time.perf_counter()
    twin.propagate(c0, sig, sp, g, dx, steps=20, skip=2)
    per_step = (time.perf_counter() - t) / 20
    if per_step * K <= twin_budget:
        t = time.perf_counter()
        _, tw = twin.propagate(c0, sig, sp, g, dx, steps=K, skip=2)
        row["t_twin"], row["twin_est"] = time.perf_counter() - t, False
        row["err_twin_vs_steady"] = err_c00(tw, accum, scale)
    else:
        row["t_twin"], row["twin_est"] = per_step * K, True
    return row


def case(N, operator, name, save=None):
    """One ``--steady-only`` solve, run in a fresh process: prints one JSON line (its info and RSS before it)."""
    c0, sig, sp, g, dx, lobes, kw = scene_args(N, name)
    peak0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss       # KiB: imports and building the scene
    with open("/proc/self/statm") as f:                                # resident now (Linux), KiB
        rss0 = int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") // 1024
    t0 = time.perf_counter()
    accum, info = steady.steady_state(c0, sig, sp, g, dx, skip=2, operator=operator, **kw)
    wall = time.perf_counter() - t0
    peak1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    if save:
        np.save(save, accum)
    print(json.dumps({"info": info, "rss_before_kib": rss0, "peak_set_in_solve": peak1 > peak0, "wall": wall,
                      "lobes": lobes}), flush=True)


def run_case(N, operator, name, save=None):
    """:func:`case` in a child process -> its result and its peak RSS (``os.wait4`` on that child alone)."""
    cmd = [sys.executable, os.path.abspath(__file__), "--case", str(N), operator, name]
    cmd += ["--save", save] if save else []
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
    out = p.stdout.read()
    p.stdout.close()
    _, status, usage = os.wait4(p.pid, 0)
    p.returncode = os.waitstatus_to_exitcode(status)
    if p.returncode != 0:
        raise SystemExit(f"N={N} {operator} {name}: the solve's process exited {p.returncode}")
    row = json.loads(out.strip().splitlines()[-1])
    row["peak_kib"] = usage.ru_maxrss
    return row


def steady_only(sizes, operators, scenes, compare):
    """Per scene, N and operator: the steady solve's time split, iterations and peak memory (fresh processes)."""
    print("peak RSS: ru_maxrss of the solve's own process (os.wait4), which builds the scene and makes one "
          "steady_state call; 'at the call': its resident set when the call began (interpreter, NumPy, SciPy, the "
          "scene's arrays), so the solve's own peak is the difference; '*': the peak was set before the call",
          flush=True)
    rows = []
    tmp = tempfile.mkdtemp(prefix="bench_steady-")
    try:
        for name in scenes:
            for N in sizes:
                saved = {}
                for op in operators:
                    path = os.path.join(tmp, f"{name}-{N}-{op}.npy") if compare and len(operators) > 1 else None
                    r = run_case(N, op, name, path)
                    i = r["info"]
                    r.update(scene=name, N=N, op=i["operator"])
                    if path:
                        saved[op] = path
                    t = i["time"]
                    rho = [None if x is None else round(x, 5) for x in i["rho"]]
                    print(f"{name} N={N} {i['operator']}: {r['wall']:.1f} s (operator {t['operator']:.2f}, spectrum "
                          f"{t['spectrum']:.2f}, solve {t['solve']:.2f}); iterations {i['iterations']}, rho {rho}, "
                          f"residual {max(i['residual']):.1e}; peak RSS {r['peak_kib'] / 2**20:.2f} GiB"
                          f"{'' if r['peak_set_in_solve'] else '*'} (at the call {r['rss_before_kib'] / 2**20:.2f})",
                          flush=True)
                    rows.append(r)
                if len(saved) > 1:
                    a, b = (np.load(saved[op]) for op in operators[:2])
                    scale = np.abs(a[..., 0]).max(axis=(0, 1, 2))
                    err = err_c00(a, b, np.where(scale > 0, scale, 1.0))
                    for r in rows[-len(operators):]:
                        r["diff"] = err
                    print(f"{name} N={N}: max |{operators[0]} - {operators[1]}| = {err:.1e} of max c00", flush=True)
                    for path in saved.values():
                        os.remove(path)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print()
    print("| scene | N | operator | total [s] | operator build [s] | spectrum [s] | solve [s] | BiCGSTAB it. (R,G,B) "
          "| peak RSS [GiB] | RSS at the call [GiB] | max diff between operators |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        t = r["info"]["time"]
        diff = f"{r['diff']:.1e}" if "diff" in r else ""
        print(f"| {r['scene']} | {r['N']} | {r['op']} | {r['wall']:.1f} | {t['operator']:.2f} | {t['spectrum']:.2f} | "
              f"{t['solve']:.2f} | {','.join(str(x) for x in r['info']['iterations'])} | {r['peak_kib'] / 2**20:.2f}"
              f"{'' if r['peak_set_in_solve'] else '*'} | "
              f"{r['rss_before_kib'] / 2**20:.2f} | {diff} |")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[16, 32, 64])
    ap.add_argument("--tol", type=float, default=1e-4, help="agreement, fraction of max c00 (default 1e-4)")
    ap.add_argument("--twin-budget", type=float, default=900.0,
                    help="seconds the twin may run per size before its time is extrapolated")
    ap.add_argument("--max-steps", type=int, default=100000)
    ap.add_argument("--no-reference", action="store_true", help="skip the 1e-9 reference iteration")
    ap.add_argument("--blas-threads", default="1", help="OPENBLAS_NUM_THREADS unless set (default 1)")
    ap.add_argument("--operator", nargs="+", choices=("auto", "sparse", "stencil"), default=["auto"],
                    help="steady_state's operator (default auto); --steady-only runs each given one")
    ap.add_argument("--steady-only", action="store_true",
                    help="only the steady solve, each (scene, N, operator) in a fresh process: time split, "
                         "iterations, peak RSS; no sparse iteration, twin or reference (too slow at N = 128)")
    ap.add_argument("--scenes", nargs="+", choices=SCENES, default=["vacuum"], help="--steady-only scenes")
    ap.add_argument("--no-compare", action="store_true",
                    help="--steady-only: do not compare the operators' grids (each is saved to a temporary file)")
    ap.add_argument("--case", nargs=3, metavar=("N", "OPERATOR", "SCENE"), help=argparse.SUPPRESS)
    ap.add_argument("--save", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.case:
        return case(int(args.case[0]), args.case[1], args.case[2], args.save)
    if args.steady_only:
        print(f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS')}  loss/step={LOSS}  k1={K1}  "
              f"operators {' '.join(args.operator)}", flush=True)
        return steady_only(args.sizes, args.operator, args.scenes, not args.no_compare)
    if len(args.operator) != 1:
        ap.error("--operator takes one value without --steady-only")

    print(f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS')}  loss/step={LOSS}  k1={K1}  "
          f"tol={args.tol:g} of max c00", flush=True)
    rows = []
    for N in args.sizes:
        r = bench(N, args.tol, args.twin_budget, not args.no_reference, args.max_steps, args.operator[0])
        i = r["info"]
        print(f"N={N}: {r['lobes']} lobes; steady ({i['operator']}) {r['t_steady']:.2f} s "
              f"(operator {i['time']['operator']:.2f}, "
              f"spectrum {i['time']['spectrum']:.2f}, solve {i['time']['solve']:.2f}); BiCGSTAB iterations "
              f"{i['iterations']}, P-products {i['products']}, rho {[round(x, 5) for x in i['rho']]}, "
              f"residual {max(i['residual']):.1e}", flush=True)
        print(f"      K={r['K']} steps to {args.tol:g} (remaining flux fraction then {r['remaining_at_K']:.2e}); "
              f"sparse iteration {r['t_sparse']:.2f} s; twin {r['t_twin']:.2f} s{' (est.)' if r['twin_est'] else ''}"
              + (f"; twin(K) vs steady {r['err_twin_vs_steady']:.2e}" if "err_twin_vs_steady" in r else "")
              + (f"; steady vs reference (K={r['K_ref']}) {r['err_steady_vs_ref']:.2e}"
                 if "err_steady_vs_ref" in r else ""), flush=True)
        rows.append(r)

    print()
    print("| N | unknowns/colour | rho (R) | steady [s] | BiCGSTAB it. (R,G,B) | K to tol | twin K steps [s] "
          "| sparse K steps [s] | speed-up vs twin | vs sparse | steady err vs ref | twin(K) err |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        i = r["info"]
        est = " (est.)" if r["twin_est"] else ""
        print(f"| {r['N']} | {r['unknowns']} | {i['rho'][0]:.5f} | {r['t_steady']:.2f} | "
              f"{','.join(str(x) for x in i['iterations'])} | {r['K']} | {r['t_twin']:.1f}{est} | "
              f"{r['t_sparse']:.2f} | {r['t_twin'] / r['t_steady']:.0f}x{est} | {r['t_sparse'] / r['t_steady']:.1f}x | "
              f"{r.get('err_steady_vs_ref', float('nan')):.1e} | {r.get('err_twin_vs_steady', float('nan')):.1e} |")


if __name__ == "__main__":
    if "--case" in sys.argv:                 # a child of --steady-only: no page
        raise SystemExit(main())
    from page import run

    raise SystemExit(run(main, lambda argv: "bench_steady_memory" if "--steady-only" in argv else "bench_steady",
                         lambda argv: ("steps = steady: time and peak memory of the solve, sparse against matrix-free"
                                       if "--steady-only" in argv else
                                       "steps = steady against iterating to convergence")))
