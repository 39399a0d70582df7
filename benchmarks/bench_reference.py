"""Cost of the Mitsuba ground truth: time per 100 spp and the noise it reaches, at 256x256.

For each scene, renders K = 8 seeds x SPP samples per pixel with the reference
renderer (``harness.reference.render_reference``, fixed spp, no pilot) and prints

* seconds per 100 spp (whole image, all passes),
* the median relative standard error over lit pixels that was measured,
* the time to reach a 2 % median relative SE, EXTRAPOLATED from the measured
  constant SE * sqrt(time) (SE ~ 1/sqrt(spp)); it is not measured.

Usage: ``.venv/bin/python benchmarks/bench_reference.py [--spp 16] [--size 256] [scene ...]``
(about a minute per scene on 2 CPU cores at the defaults).
"""

import argparse
import tempfile
import time

from harness.reference.render import render_reference
from harness.scene import load_scene


def bench(name, size, spp, K=8, target=0.02):
    scene = load_scene(name).with_resolution(size, size)
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        meta = render_reference(scene, f"{tmp}/ref", spp=spp, K=K)
        wall = time.perf_counter() - t0
    secs, r = meta["render_seconds"], meta["median_rel_se_subsurface"]
    total = spp * K
    return {"scene": name, "size": size, "spp_total": total, "render_s": secs, "wall_s": wall,
            "s_per_100spp": secs / total * 100, "rel_se": r, "t_2pct_s": secs * (r / target) ** 2,
            "spp_2pct": total * (r / target) ** 2}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=["sphere_homogeneous", "jade_veins"])
    ap.add_argument("--spp", type=int, default=16, help="samples per pixel per seed (8 seeds)")
    ap.add_argument("--size", type=int, default=256, help="image width and height")
    ap.add_argument("--measure", type=float, metavar="TARGET",
                    help="also render each scene to this median relative SE (e.g. 0.02) and print the measured time")
    args = ap.parse_args()
    print(f"{'scene':<20} {'size':>5} {'spp':>5} {'render s':>9} {'s/100spp':>9} {'med rel SE':>10} "
          f"{'spp@2%':>8} {'t@2% (extrap.)':>15}")
    for name in args.scenes:
        b = bench(name, args.size, args.spp)
        print(f"{b['scene']:<20} {b['size']:>5} {b['spp_total']:>5} {b['render_s']:>9.1f} {b['s_per_100spp']:>9.1f} "
              f"{b['rel_se']:>10.4f} {b['spp_2pct']:>8.0f} {b['t_2pct_s'] / 60:>12.1f} min")
    print("t@2% is extrapolated from the measured SE*sqrt(time) constant (SE ~ 1/sqrt(spp)), not measured.")
    if args.measure:
        print(f"\nmeasured: render_reference with target_rel_se={args.measure} (pilot, then top-ups)")
        print(f"{'scene':<20} {'size':>5} {'spp':>7} {'render s':>9} {'wall s':>8} {'med rel SE':>10} {'met':>5}")
        for name in args.scenes:
            scene = load_scene(name).with_resolution(args.size, args.size)
            with tempfile.TemporaryDirectory() as tmp:
                t0 = time.perf_counter()
                meta = render_reference(scene, f"{tmp}/ref", target_rel_se=args.measure, max_spp_per_seed=65536)
                wall = time.perf_counter() - t0
            print(f"{name:<20} {args.size:>5} {meta['spp_total']:>7} {meta['render_seconds']:>9.1f} {wall:>8.1f} "
                  f"{meta['median_rel_se_subsurface']:>10.4f} {str(meta.get('target_met')):>5}")


if __name__ == "__main__":
    main()
