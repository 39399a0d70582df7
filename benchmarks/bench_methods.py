"""Precomputation and per-frame times of every method, as ratios to SSLPV's per-frame time, in ONE run.

One process, one GL context per renderer, each scene of the suite at ``--size``: SSLPV at the paper's
configuration (N = 32, K = 32, ``--sslpv-mapping``), then the dipole rivals (dense gather at its default spacing,
vertex gather at density 0.5 and range 2, the cubemap gather at 512 disc samples over 4 frames, the
hierarchical gather at its default bound, the standard dipole's atlas gather at 128 texels and 64 links, all under the
sizing rule ``fit = coarsen`` (``dipole_gl.sizing``) and with the method's default terms (diffusion plus single
scattering), as in the nightly matrix). Precomputation = the method's precomputation steps (host ms, measured when they were made: the
first render of a configuration); per frame = the sum of the frame stages (GL ms; host ms where the driver's
timer queries miss compute work, ``dipole_gl/timing.py``), the median of ``--repeat`` renders after that.
A second table gives each method's work units per frame (device-independent: ``harness.methods``) as ratios
to SSLPV's.

    .venv/bin/python benchmarks/bench_methods.py [--scenes a,b] [--size small | 64x64] [--repeat 3]

``--size small`` (the default): each scene at its committed small size (64x64, wide_slab 60x36).

A third table gives, per rival configuration, what the sizing rule chose and what the first render
did: the setting used, the samples or vertices and pairs, the gather's dispatches, the frame and the
precomputation in seconds, the spot check against the twin (``dipole_gl.check``: its largest
difference and host seconds) and the wall time of that first render. A configuration that fails
prints its one-line error in the tables instead. ``--write`` writes the tables to
``docs/benchmarks/bench_methods.md`` (``benchmarks/page.py``).
"""

import argparse
import statistics
import sys
import time

from harness.methods import get_method
from harness.reference.committed import sized_scene
from harness.scene import list_scenes, load_scene

#: the nightly matrix's rival settings (the vertex gather's defaults exceed its table on apple_sphere)
CONFIGS = [("dipole", {"gather": "dense", "fit": "coarsen"}),
           ("dipole", {"gather": "vertex", "density": 0.5, "range": 2.0, "fit": "coarsen"}),
           ("dirpole", {"gather": "dense", "fit": "coarsen"}),
           ("dirpole", {"gather": "vertex", "density": 0.5, "range": 2.0, "fit": "coarsen"}),
           ("dipole", {"gather": "cubemap", "samples": 512, "frames": 4, "fit": "coarsen"}),
           ("dirpole", {"gather": "cubemap", "samples": 512, "frames": 4, "fit": "coarsen"}),
           ("dipole", {"gather": "hierarchical", "fit": "coarsen"}),
           ("dirpole", {"gather": "hierarchical", "fit": "coarsen"}),
           ("dipole", {"gather": "atlas", "atlas_size": 128, "links": 64, "fit": "coarsen"})]


def frame_ms(method, scene, params, repeat):
    t = time.perf_counter()
    first = method.render(scene, params)
    wall = time.perf_counter() - t
    pre = sum(v for v in first.precompute_ms.values() if v == v)
    frames = [method.render(scene, params).frame_ms for _ in range(repeat)]
    return pre, statistics.median(frames), first, wall


def sizing_row(name, kernel, gather, first, wall):
    """The sizing table's row: what the rule chose and what the first render did."""
    i = first.info
    if gather == "cubemap":
        used = f"{i['samples']} samples x {i['frames']} frames"
        size = f"{i['face_texels']:,} face texels"
    elif gather == "dense":
        used, size = f"spacing {i['spacing_used']:g}", f"{i['samples']:,} samples"
    elif gather == "hierarchical":
        used, size = f"spacing {i['spacing_used']:g}", f"{first.precompute_work['octree']:,} octree nodes"
    elif gather == "atlas":
        used = f"{i['atlas_size']} texels, {i['links_per_texel']:.1f} links"
        size = f"{i['patches']:,} patches, {first.precompute_work['links']:,} links"
    else:
        used, size = f"density {i['density_used']:g}", f"{i['vertices']:,} vertices, {i['pairs']:,} pairs"
    c = i["check"]
    return (f"| {name} | {kernel} | {gather} | {used} | {size} | {i['dispatches']} | "
            f"{sum(first.timings_ms.values()) / 1e3:.2f} | {sum(first.precompute_ms.values()) / 1e3:.2f} | "
            f"{c['max_rel_diff']:.1e} / {c['ms'] / 1e3:.2f} | {wall:.1f} |")


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
    rows, sizing, work = [], [], []
    for name in names:
        scene = sized_scene(load_scene(name), size)
        _, s_frame, s_first, _ = frame_ms(sslpv, scene, sp, args.repeat)
        row = {"scene": name, "sslpv": s_frame}
        work.append({"scene": name, "sslpv": sum(s_first.work.values())})
        for kernel, kw in CONFIGS:
            m = get_method(kernel)
            p = m.make_params(**kw)
            try:
                pre, frame, first, wall = frame_ms(m, scene, p, args.repeat)
            except Exception as exc:  # noqa: BLE001 -- the tables report every failure
                why = f"failed: {type(exc).__name__}: {str(exc).splitlines()[0]}"
                row[f"{kernel}-{kw['gather']}"] = why
                sizing.append(f"| {name} | {kernel} | {kw['gather']} | {why} |||||||")
                continue
            row[f"{kernel}-{kw['gather']}"] = (pre / s_frame, frame / s_frame, pre, frame)
            work[-1][f"{kernel}-{kw['gather']}"] = sum(first.work.values())
            sizing.append(sizing_row(name, kernel, kw["gather"], first, wall))
        rows.append(row)
        print(f"{name}: SSLPV N32 K32 {args.sslpv_mapping} {s_frame:.1f} ms/frame; "
              + "; ".join(f"{k} pre {v[2]:.0f} ms, frame {v[3]:.1f} ms" for k, v in row.items()
                          if isinstance(v, tuple)), file=sys.stderr, flush=True)
    keys = [f"{k}-{kw['gather']}" for k, kw in CONFIGS]
    print(f"\nratios to SSLPV's per-frame time (N32 K32 {args.sslpv_mapping}), size {args.size}, median of {args.repeat} frames, "
          f"one run of {time.perf_counter() - t0:.0f} s\n")
    print("| scene | SSLPV ms/frame | " + " | ".join(f"{k} precomp. / frame" for k in keys) + " |")
    print("|---|---|" + "---|" * len(keys))
    for r in rows:
        print(f"| {r['scene']} | {r['sslpv']:.1f} | " + " | ".join(
            f"{r[k][0]:.2f} / {r[k][1]:.2f}" if isinstance(r[k], tuple) else r[k] for k in keys) + " |")
    print("\nwork units per frame (the sum over the frame's stages of each method's device-independent work count, "
          "harness.methods: cells, texels, kernel evaluations, links), as a ratio to SSLPV's:\n")
    print("| scene | SSLPV work / frame | " + " | ".join(keys) + " |")
    print("|---|---|" + "---|" * len(keys))
    for w in work:
        print(f"| {w['scene']} | {w['sslpv']:.3g} | " + " | ".join(
            f"{w[k] / w['sslpv']:.2f}" if k in w else "-" for k in keys) + " |")
    print("\nthe rivals under the sizing rule (fit = coarsen), first render of each configuration:\n")
    print("| scene | method | gather | setting used | size | dispatches | frame s | precompute s | "
          "check: max diff / s | wall s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for line in sizing:
        print(line)
    for m in ("sslpv", "dipole", "dirpole"):
        get_method(m).release()


if __name__ == "__main__":
    from page import run

    raise SystemExit(run(main, "bench_methods", "Every method's precomputation and frame time, as ratios to SSLPV's",
                         markdown=True))
