"""Energy carried by long paths: what a depth cap, Russian roulette and spectral tracking miss.

For one scene (default ``marble_sphere``, 32x32, 4 seeds x 16 spp, the same seeds everywhere)
prints the mean radiance over covered pixels, per channel, with its standard error over seeds:

* ``spectral``: one RGB pass (Mitsuba samples distances with one hero channel and weights the
  others by coefficient ratios), at Mitsuba's default ``rr_depth = 5``, and with hard depth caps;
* ``per-channel``: one grey pass per channel (what the harness renders when sigma_t differs
  between channels), at ``rr_depth = 5``, the harness's rule (``mitsuba_scene.rr_depth_for``)
  and hard caps ``max_depth = rr_depth = d`` (no roulette before the cap).

The missing energy of a setting is ``1 - E / E(largest cap)``: with the same seeds the paths are
the same up to the cap, so the differences between caps are the energy of the longer paths.

Usage: ``.venv/bin/python benchmarks/bench_path_depth.py [--scene marble_sphere] [--caps 100,300,1000,3000,10000]``
(about 10 minutes on 2 cores at the defaults).
"""

import argparse
import time

import numpy as np


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="marble_sphere")
    ap.add_argument("--size", type=int, default=32)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--caps", default="100,300,1000,3000,10000")
    ap.add_argument("--spectral-caps", default="100,300,1000", help="hard caps for the one-RGB-pass rows")
    args = ap.parse_args()

    from harness.reference import mitsuba_scene as ms
    from harness.scene import load_scene

    mi = ms.use_variant()
    scene = load_scene(args.scene).with_resolution(args.size, args.size)
    covered = ms.coverage_mask(scene) >= 0.999

    def energy(s, channel, rr, md):
        d = ms.build_scene_dict(s, rr_depth=rr, max_depth=md, channel=channel)
        sc = mi.load_dict(d)
        t0 = time.perf_counter()
        per_seed = np.stack([np.asarray(mi.render(sc, seed=k, spp=args.spp), np.float64)[covered].mean(0)
                             for k in range(args.seeds)])
        return per_seed, (time.perf_counter() - t0) / (args.seeds * args.spp)

    def row(label, channels, rr, md):
        seeds, cost = [], 0.0
        if channels is None:
            seeds, cost = energy(scene, None, rr, md)
        else:
            parts = []
            for c in range(3):
                e, t = energy(scene, c, rr if rr is not None else ms.integrator_dict(scene, channel=c)["rr_depth"], md)
                parts.append(e[:, c])
                cost += t
            seeds = np.stack(parts, axis=1)
        m, se = seeds.mean(0), seeds.std(0, ddof=1) / np.sqrt(len(seeds))
        return {"label": label, "mean": m, "se": se, "cost": cost}

    caps = [int(c) for c in args.caps.split(",")]
    rows = [row("spectral, rr_depth 5 (Mitsuba default)", None, 5, -1)]
    rows += [row(f"spectral, hard cap {d}", None, d, d) for d in (int(c) for c in args.spectral_caps.split(","))]
    rows.append(row("per-channel, rr_depth 5", "split", 5, -1))
    rows.append(row("per-channel, harness rule " + "/".join(str(ms.integrator_dict(scene, channel=c)["rr_depth"])
                                                            for c in range(3)), "split", None, -1))
    rows += [row(f"per-channel, hard cap {d}", "split", d, d) for d in caps]
    ref = rows[-1]["mean"]
    print(f"{args.scene} {args.size}x{args.size}, {args.seeds} seeds x {args.spp} spp; missing energy relative to "
          f"'{rows[-1]['label']}'")
    for r in rows:
        miss = 1 - r["mean"] / ref
        print(f"{r['label']:<44} mean {np.array2string(r['mean'], precision=5)} +- "
              f"{np.array2string(r['se'], precision=5)}  missing {np.array2string(100 * miss, precision=2)} %  "
              f"({r['cost']:.3f} s/spp)", flush=True)


if __name__ == "__main__":
    from page import run

    raise SystemExit(run(main, "bench_path_depth", 'Energy carried by long paths: depth caps, Russian roulette, spectral tracking'))
