"""FLIP's time under OpenMP's two wait policies, with and without a competing process; one run, ratios.

    python benchmarks/bench_openmp_wait.py [--size 64] [--exposures 10] [--repeats 5]

``harness/__init__.py`` sets ``OMP_WAIT_POLICY=PASSIVE`` for every harness process. This measures
why: ``flip_evaluator.evaluate`` (HDR, the given number of exposures, a fixed image pair) is timed in
a fresh process under ``ACTIVE`` (GNU OpenMP's spinning threads) and ``PASSIVE`` (sleeping
threads), alone and beside one busy process per core (as in a sweep: the other worker, llvmpipe).
It prints the median seconds per evaluation, each policy's ratio to ``PASSIVE``, and checks that
both policies return the same FLIP map, bit for bit.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import subprocess
import sys
import time

_CHILD = r"""
import hashlib, json, sys, time
import numpy as np, flip_evaluator
size, n, repeats = (int(a) for a in sys.argv[1:4])
rng = np.random.default_rng(0)
ref = (rng.random((size, size, 3)) * 5).astype(np.float32)
test = (ref * 1.1 + 0.01).astype(np.float32)
p = {"startExposure": -2.0, "stopExposure": 2.0, "numExposures": n}
times = []
for _ in range(repeats):
    t = time.perf_counter()
    m, _, _ = flip_evaluator.evaluate(ref, test, "HDR", applyMagma=False, computeMeanError=False, parameters=p)
    times.append(time.perf_counter() - t)
print(json.dumps({"s": sorted(times)[len(times) // 2], "map": hashlib.sha256(np.asarray(m).tobytes()).hexdigest()}))
"""


def _spin(stop):
    while not stop.is_set():
        sum(i * i for i in range(10000))


def _run(policy, args):
    env = dict(os.environ, OMP_WAIT_POLICY=policy)
    out = subprocess.run([sys.executable, "-c", _CHILD, str(args.size), str(args.exposures), str(args.repeats)],
                         env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--exposures", type=int, default=10)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args(argv)
    rows = {}
    for load in ("alone", "beside busy processes"):
        stop, procs = multiprocessing.Event(), []
        if load != "alone":
            procs = [multiprocessing.Process(target=_spin, args=(stop,)) for _ in range(os.cpu_count() or 1)]
            for p in procs:
                p.start()
            time.sleep(0.5)
        try:
            for policy in ("ACTIVE", "PASSIVE"):
                rows[(load, policy)] = _run(policy, args)
        finally:
            stop.set()
            for p in procs:
                p.join()
    print(f"flip_evaluator HDR, {args.size}x{args.size}, {args.exposures} exposures, median of {args.repeats}, "
          f"{os.cpu_count()} cores")
    print("| load | OMP_WAIT_POLICY | s per evaluation | ratio to PASSIVE |")
    print("|---|---|---|---|")
    for (load, policy), r in rows.items():
        print(f"| {load} | {policy} | {r['s']:.4f} | {r['s'] / rows[(load, 'PASSIVE')]['s']:.2f} |")
    same = len({r["map"] for r in rows.values()}) == 1
    print(f"FLIP maps identical under every policy and load: {same}")
    return 0 if same else 1


if __name__ == "__main__":
    from page import run

    raise SystemExit(run(main, "bench_openmp_wait", "FLIP's time under OpenMP's two wait policies"))
