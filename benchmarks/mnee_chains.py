"""Connections through several interfaces: the deficit, the crossing counts, the chains' agreement.

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

``--area-limit R``: instead, the area-light limit on the scene at eta 1.4 (``--eta``): stock
``volpath`` with a sphere light of radius R (radiance I / (pi R^2)) at the point light's place,
over the pixels where its absorber pass (albedo 0) shows no reflection of the bulb in the
boundary (a point light has none), against ``mneevolpath`` with the point light (chains on and off), at
``--max-depth``; prints the image mean ratios and their standard errors.

Usage: ``.venv/bin/python benchmarks/mnee_chains.py [--scene torus_hole] [--size 32] [--spp 64] [--seeds 4]``
``[--area-limit 0.25 --eta 1.4 --max-depth 6 --area-spp 16384]``.
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


def median_rel_se(stack, covered):
    """Median over covered, lit (pixel, channel) pairs of se / mean (K seeds)."""
    mean, se = stack.mean(0), stack.std(0, ddof=1) / np.sqrt(len(stack))
    lit = covered[..., None] & (mean > 0)
    return float(np.median(se[lit] / mean[lit]))


def fmt(a, digits=4):
    return "[" + ", ".join(f"{v:.{digits}f}" for v in np.ravel(a)) + "]"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", default="torus_hole")
    ap.add_argument("--size", type=int, default=32)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--max-crossings", type=int, nargs="+", default=[1, 5])
    ap.add_argument("--eta", default="1.0001", help="the boundary's index, or 'own' (the scene's)")
    ap.add_argument("--area-limit", type=float, default=None, metavar="R")
    ap.add_argument("--max-depth", type=int, default=-1)
    ap.add_argument("--area-spp", type=int, default=16384)
    args = ap.parse_args()
    mi = ms.use_variant("llvm_ad_rgb")
    if args.area_limit is not None:
        return area_limit(mi, args)
    from harness.reference import mnee

    base = scene_named(args.scene).with_resolution(args.size, args.size)
    matched = dataclasses.replace(base, boundary=Boundary("index-matched"))
    eta = base.boundary.eta if args.eta == "own" else float(args.eta)
    smooth = dataclasses.replace(base, boundary=Boundary("dielectric", eta, 0.0))
    print(f"{args.scene} at {args.size} x {args.size}, K = {args.seeds} x {args.spp} spp each, eta = {eta}")
    b, tb = render(mi, ms.build_scene_dict(matched), range(100, 100 + args.seeds), args.spp)
    pb = b.mean((1, 2))
    covered = ms.coverage_mask(matched) >= 1.0
    rb = median_rel_se(b, covered)
    print(f"  index-matched volpath: {tb:.0f} s, image mean {fmt(pb.mean(0))}, median rel. SE {rb:.4f}")
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
        ra = median_rel_se(img, covered)
        # Time to a noise target T = t (r / target)^2 for both, in one run: their ratio.
        print(f"  max_crossings = {mc}: {ta:.0f} s ({ta / tb:.2f} x index-matched), median rel. SE {ra:.4f}: time to "
              f"the same noise {ta * ra ** 2 / (tb * rb ** 2):.2f} x index-matched; image mean ratio "
              f"{fmt(pa.mean(0) / pb.mean(0))}, (difference) / SE {fmt((pa.mean(0) - pb.mean(0)) / se_m, 2)}; "
              f"pixels within 4 SE {np.mean(np.all(np.abs(z) <= 4, -1)):.4f}, mean z {fmt(z.mean(0), 2)}")
        print(f"    connections by crossings of the seed segment (1, 3, 5, >= 7): {fmt(cross)}; chains connected "
              f"{st['mnee_chain_connected'] / started:.4f}, lost {st['mnee_lost'] / started:.4f} (over the maximum "
              f"{over:.4f}); lost light "
              f"(straight, index-matched) / image {fmt(lost)}")


def area_limit(mi, args):
    r, md = args.area_limit, args.max_depth
    scene = dataclasses.replace(scene_named(args.scene).with_resolution(args.size, args.size),
                                boundary=Boundary("dielectric", float(args.eta), 0.0))
    light = scene.lights[0]
    print(f"area-light limit, {args.scene} at {args.size} x {args.size}, eta {args.eta}, max_depth {md}, "
          f"sphere light r = {r}: K = {args.seeds} x {args.area_spp} spp (full and absorber), point K = "
          f"{args.seeds} x {args.spp}")
    intensity = np.asarray(light.intensity, float)
    bulb = {"type": "sphere", "center": [float(c) for c in light.position], "radius": r,
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": (intensity / (np.pi * r * r)).tolist()}}}
    seeds = range(100, 100 + args.seeds)
    full, tf = render(mi, ms.build_scene_dict(scene, lights=False, extra_emitters={"bulb": bulb}, sample_emitters=False,
                                              integrator={"type": "volpath", "max_depth": md}), seeds, args.area_spp)
    absorber, ta = render(mi, ms.build_scene_dict(scene, albedo_override=0.0, lights=False,
                                                  extra_emitters={"bulb": bulb}, sample_emitters=False,
                                                  integrator={"type": "volpath", "max_depth": md}),
                          range(200, 200 + args.seeds), args.area_spp)
    # Pixels where the bulb's reflection shows (in any channel, in the absorber image) are left out, so
    # that its noise does not swamp the comparison; the rest are compared as they are.
    keep = np.all(absorber.mean(0) <= 1e-3 * np.maximum(full.mean(0), 1e-12), axis=-1)
    f, a = full[:, keep].mean(1), absorber.mean((1, 2))
    area = f.mean(0)
    var_area = f.var(0, ddof=1) / len(f)
    print(f"  volpath, sphere light: {tf + ta:.0f} s; reflection of the bulb {fmt(a.mean(0) / full.mean((0, 1, 2)))} "
          f"of the full image, {int((~keep).sum())} of {keep.size} pixels left out for it; subsurface {fmt(area, 6)}")
    for mc in args.max_crossings:
        d = ms.build_scene_dict(scene, max_depth=md)
        d["integrator"]["max_crossings"] = mc
        p, tp = render(mi, d, range(args.seeds), args.spp)
        p = p[:, keep].mean(1)
        ratio = area / p.mean(0)
        se = ratio * np.sqrt(var_area / area ** 2 + p.var(0, ddof=1) / len(p) / p.mean(0) ** 2)
        print(f"  mneevolpath, point light, max_crossings = {mc}: {tp:.0f} s; sphere / point {fmt(ratio)} "
              f"+- {fmt(se)}")


if __name__ == "__main__":
    from page import run

    raise SystemExit(run(main, lambda argv: "mnee_chains_area_limit" if "--area-limit" in argv else "mnee_chains",
                         "Connections through several interfaces"))
