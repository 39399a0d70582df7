"""Precomputation and per-frame times of every method, as ratios to SSLPV's per-frame time, in ONE run.

One process, one GL context per renderer, each scene of the suite at ``--size``: SSLPV at the paper's
configuration (N = 32, K = 32, ``--sslpv-mapping``), then the dipole rivals (dense gather at its default spacing,
vertex gather at density 0.5 and range 2, as in the nightly matrix). Precomputation = the method's precomputation steps (host ms, measured when they were made: the
first render of a configuration); per frame = the sum of the frame stages (GL ms; host ms where the driver's
timer queries miss compute work, ``dipole_gl/timing.py``), the median of ``--repeat`` renders after that.

    .venv/bin/python benchmarks/bench_methods.py [--scenes a,b] [--size small | 64x64] [--repeat 3]

``--size small`` (the default): each scene at its committed small size (64x64, wide_slab 60x36).
"""

import argparse
import statistics
import time

from harness.methods import get_method
from harness.reference.committed import sized_scene
from harness.scene import list_scenes, load_scene

#: the nightly matrix's rival settings (the vertex gather's defaults exceed its table on apple_sphere)
CONFIGS = [("dipole", {"gather": "dense"}), ("dipole", {"gather": "vertex", "density": 0.5, "range": 2.0}),
           ("dirpole", {"gather": "dense"}), ("dirpole", {"gather": "vertex", "density": 0.5, "range": 2.0})]


def frame_ms(method, scene, params, repeat):
    first = method.render(scene, params)
    pre = sum(v for v in first.precompute_ms.values() if v == v)
    frames = [method.render(scene, params).frame_ms for _ in range(repeat)]
    return pre, statistics.median(frames), first


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default=None)
    ap.add_argument("--size", default="small")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--sslpv-mapping", default="collision")
    args = ap.parse_args()
    size = "small" if args.size == "small" else [int(v) for v in args.size.split("x")]
    names = args.scenes.split(",") if args.scenes else list_scenes()
    sslpv = get_method("sslpv")
    sp = sslpv.make_params(N=32, steps=32, mapping=args.sslpv_mapping)
    t0 = time.perf_counter()
    rows = []
    for name in names:
        scene = sized_scene(load_scene(name), size)
        _, s_frame, _ = frame_ms(sslpv, scene, sp, args.repeat)
        row = {"scene": name, "sslpv": s_frame}
        for kernel, kw in CONFIGS:
            m = get_method(kernel)
            p = m.make_params(**kw)
            pre, frame, _ = frame_ms(m, scene, p, args.repeat)
            row[f"{kernel}-{kw['gather']}"] = (pre / s_frame, frame / s_frame, pre, frame)
        rows.append(row)
        print(f"{name}: SSLPV N32 K32 {args.sslpv_mapping} {s_frame:.1f} ms/frame; "
              + "; ".join(f"{k} pre {v[2]:.0f} ms, frame {v[3]:.1f} ms" for k, v in row.items()
                          if isinstance(v, tuple)), flush=True)
    keys = [f"{k}-{kw['gather']}" for k, kw in CONFIGS]
    print(f"\nratios to SSLPV's per-frame time (N32 K32 {args.sslpv_mapping}), size {args.size}, median of {args.repeat} frames, "
          f"one run of {time.perf_counter() - t0:.0f} s")
    print("| scene | SSLPV ms/frame | " + " | ".join(f"{k} precomp. / frame" for k in keys) + " |")
    print("|---|---|" + "---|" * len(keys))
    for r in rows:
        print(f"| {r['scene']} | {r['sslpv']:.1f} | " + " | ".join(f"{r[k][0]:.2f} / {r[k][1]:.2f}" for k in keys) + " |")
    for m in ("sslpv", "dipole", "dirpole"):
        get_method(m).release()


if __name__ == "__main__":
    main()
