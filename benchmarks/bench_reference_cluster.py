"""Parallel efficiency of references on Dask: the same reference, same seeds, serial and on a LocalCluster.

In one run, for one scene (default ``jade_veins`` at 64x64, its ``small_reference_rel_se``
target; pilot, steps and top-ups as ``sslpv-harness reference`` does them):

* serial, 1 Dr.Jit thread (one core): ``T1``;
* serial, Dr.Jit's default thread count (every core: the serial renderer as it is used);
* a LocalCluster of W workers (``--workers``, default 2), ``cores // W`` Dr.Jit threads each: ``TW``.

Parallel efficiency ``E = T1 / (cores used x TW)`` (1 is perfect), and, since other jobs on a
shared machine change wall times from one run to the next, the CPU efficiency: the CPU time the
serial render's jobs used over the CPU time the cluster's jobs used (1: distributing costs no extra
work; it does not see the scheduling or the client's merging). With one Dr.Jit thread per
worker the cluster's images are bit-identical to the 1-thread serial ones (checked here, every
EXR); wall times include starting the cluster (reported apart).

Usage: ``.venv/bin/python benchmarks/bench_reference_cluster.py [--scene jade_veins] [--size 64] [--workers 2]
[--target T] [--repeat R]``. Other jobs on the machine change the times: the load average is printed
before each run, and ``--repeat`` interleaves the sequence again.
"""

import argparse
import os
import tempfile
import time

import numpy as np


def _identical(a, b, files):
    from harness.io.images import read_exr

    for f in files:
        if f.endswith(".exr"):
            x, y = read_exr(f"{a}/{f}"), read_exr(f"{b}/{f}")
            if set(x) != set(y) or not all(np.array_equal(x[k], y[k]) for k in x):
                return False
    return True


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="jade_veins")
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--workers", default="2", help="comma-separated LocalCluster sizes")
    ap.add_argument("--target", type=float, help="median relative SE (default: the scene's small_reference_rel_se)")
    ap.add_argument("--repeat", type=int, default=1, help="repeat the sequence (serial-1, clusters, serial-default)")
    args = ap.parse_args()

    from dask.distributed import Client, LocalCluster

    from harness.reference.render import render_reference
    from harness.runs.references import local_threads
    from harness.scene import load_scene

    scene = load_scene(args.scene).with_resolution(args.size, args.size)
    target = args.target or scene.tolerances.get("small_reference_rel_se") or 0.05
    cores = os.cpu_count()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        def timed(label, cores_used, **kw):
            load = os.getloadavg()[0]
            t0 = time.perf_counter()
            meta = render_reference(scene, f"{tmp}/{label}", target_rel_se=target, **kw)
            rows.append({"label": label, "cores": cores_used, "wall": time.perf_counter() - t0, "meta": meta})
            print(f"{label:<30} load {load:4.1f}  wall {rows[-1]['wall']:7.1f} s  jobs' render time "
                  f"{meta['render_seconds']:7.1f} s, CPU {meta['render_cpu_seconds']:7.1f} s  {meta['spp_total']} spp  "
                  f"median rel SE {meta['median_rel_se_subsurface']:.4f}", flush=True)
            return meta

        print(f"{args.scene} {args.size}x{args.size}, target {target:.2%}, {cores} cores; the machine's load average "
              "is printed before each run (other jobs share it: compare runs made at similar load)")
        sizes = [int(x) for x in args.workers.split(",")]
        for rep in range(args.repeat):
            base = timed(f"serial-1thread-{rep}", 1, threads=1)
            for w in sizes:
                th = local_threads(w)
                t0 = time.perf_counter()
                with LocalCluster(n_workers=w, threads_per_worker=1, processes=True, dashboard_address=None,
                                  silence_logs=50) as cluster, Client(cluster) as client:
                    client.wait_for_workers(w)
                    start = time.perf_counter() - t0
                    label = f"cluster-{w}x{th}thread-{rep}"
                    meta = timed(label, w * th, threads=th, client=client)
                same = _identical(f"{tmp}/serial-1thread-{rep}", f"{tmp}/{label}", base["files"]) if th == 1 else None
                r, r1 = rows[-1], next(x for x in rows if x["label"] == f"serial-1thread-{rep}")
                eff = r1["wall"] / (r["cores"] * r["wall"])
                cpu = r1["meta"]["render_cpu_seconds"] / r["meta"]["render_cpu_seconds"]
                print(f"  LocalCluster start {start:.1f} s (not in the wall above); {w} workers x {th} thread: "
                      f"speed-up over serial-1thread {r1['wall'] / r['wall']:.2f}; parallel efficiency "
                      f"T1 / ({r['cores']} x T{w}) = {eff:.2f}; CPU efficiency (serial CPU / cluster CPU) {cpu:.2f}; "
                      f"images identical to serial-1thread: {same}; workers used {meta['workers']}", flush=True)
            timed(f"serial-default-threads-{rep}", cores)
            d, c = rows[-1], rows[-2]
            print(f"  serial with Dr.Jit's {cores} threads: speed-up over serial-1thread {r1['wall'] / d['wall']:.2f}; "
                  f"the last cluster's speed-up over it {d['wall'] / c['wall']:.2f}", flush=True)

if __name__ == "__main__":
    from page import run

    raise SystemExit(run(main, "bench_reference_cluster", 'Parallel efficiency of references on Dask'))
