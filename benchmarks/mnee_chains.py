"""Connections through several interfaces (issue 26): the deficit, the crossing counts, the chains' agreement.

On a non-convex scene, at eta = 1.0001 (where the straight segment is the exact connection)
against index-matched ``volpath``, renders ``mneevolpath`` with ``max_crossings = 1`` (one
refraction only, the integrator before chains) and with chains (``--max-crossings``), with
``stats``: prints the image mean ratio to the index-matched image and its standard error,
the share of pixels within 4 SE, the share of connections by the number of crossings of the
seed segment, and the light of the connections not made (the straight seed's index-matched
light, ``mnee_lost_*``) as a share of the index-matched image.

Scenes (``--scene``): ``torus_hole`` (skin_torus_dielectric's torus and light, whose light
passes through the near side of the ring to reach the far side, with a thin medium: sigma_t
1.5 / 2 / 3, albedo 0.9 / 0.85 / 0.8), or any suite scene name.

Usage: ``.venv/bin/python benchmarks/mnee_chains.py [--scene torus_hole] [--size 32] [--spp 64] [--seeds 4]``.
"""

import argparse
import dataclasses
import time

import numpy as np

from harness.reference import mitsuba_scene as ms
from harness.reference import nonconvex
from harness.scene import Boundary, load_scene


def scene_named(name):
    return nonconvex.torus_hole() if name == "torus_hole" else load_scene(name)


def render(mi, d, seeds, spp):
    scene = mi.load_dict(d)
    t = time.perf_counter()
    out = np.stack([np.asarray(mi.render(scene, seed=int(s), spp=spp), dtype=np.float64) for s in seeds])
    return out, time.perf_counter() - t


def fmt(a, digits=4):
    return "[" + ", ".join(f"{v:.{digits}f}" for v in np.ravel(a)) + "]"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", default="torus_hole")
    ap.add_argument("--size", type=int, default=32)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--max-crossings", type=int, nargs="+", default=[1, 5])
    ap.add_argument("--eta", type=float, default=1.0001)
    args = ap.parse_args()
    mi = ms.use_variant("llvm_ad_rgb")
    from harness.reference import mnee

    base = scene_named(args.scene).with_resolution(args.size, args.size)
    matched = dataclasses.replace(base, boundary=Boundary("index-matched"))
    smooth = dataclasses.replace(base, boundary=Boundary("dielectric", args.eta, 0.0))
    print(f"{args.scene} at {args.size} x {args.size}, K = {args.seeds} x {args.spp} spp each, eta = {args.eta}")
    b, tb = render(mi, ms.build_scene_dict(matched), range(100, 100 + args.seeds), args.spp)
    pb = b.mean((1, 2))
    print(f"  index-matched volpath: {tb:.0f} s, image mean {fmt(pb.mean(0))}")
    names = ["R", "G", "B"] + list(mnee.STATS_AOVS)
    for mc in args.max_crossings:
        d = ms.build_scene_dict(smooth)
        d["integrator"].update(stats=True, max_crossings=mc)
        a, ta = render(mi, d, range(args.seeds), args.spp)
        img, aov = a[..., :3], a[..., 3:].sum((1, 2)).mean(0)
        st = dict(zip(names[3:], aov))
        se = np.sqrt(img.var(0, ddof=1) / len(img) + b.var(0, ddof=1) / len(b))
        lit = np.all(se > 0, axis=-1)
        z = ((img.mean(0) - b.mean(0)) / np.where(se > 0, se, 1))[lit]
        pa = img.mean((1, 2))
        se_m = np.sqrt(pa.var(0, ddof=1) / len(pa) + pb.var(0, ddof=1) / len(pb))
        started = st["mnee_started"]
        cross = [st[k] / started for k in ("mnee_cross1", "mnee_cross3", "mnee_cross5", "mnee_cross7_more")]
        over = st["mnee_over_max"] / started
        lost = np.array([st["mnee_lost_r"], st["mnee_lost_g"], st["mnee_lost_b"]]) / (pb.mean(0) * args.size ** 2)
        print(f"  max_crossings = {mc}: {ta:.0f} s ({ta / tb:.2f} x index-matched); image mean ratio "
              f"{fmt(pa.mean(0) / pb.mean(0))}, (difference) / SE {fmt((pa.mean(0) - pb.mean(0)) / se_m, 2)}; "
              f"pixels within 4 SE {np.mean(np.all(np.abs(z) <= 4, -1)):.4f}, mean z {fmt(z.mean(0), 2)}")
        print(f"    connections by crossings of the seed segment (1, 3, 5, >= 7): {fmt(cross)}; chains connected "
              f"{st['mnee_chain_connected'] / started:.4f}, lost {st['mnee_lost'] / started:.4f} (over the maximum "
              f"{over:.4f}); lost light "
              f"(straight, index-matched) / image {fmt(lost)}")


if __name__ == "__main__":
    main()
