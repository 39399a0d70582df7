"""Connections through several interfaces: the deficit, the crossing counts, the chains' agreement.

On a non-convex scene, at eta = 1.0001 (where the straight segment is the exact connection)
against index-matched ``volpath`` (each in the reference's passes: one grey pass per channel of a
chromatic medium), renders ``mneevolpath`` with ``max_crossings = 1`` (one
refraction only, the integrator before chains) and with chains (``--max-crossings``), with
``stats``: prints the image mean ratio to the index-matched image and its standard error,
the share of lit pixels within 4 SE (as the eta -> 1 tests count them: a pixel's channels that
:func:`harness.reference.noise.lit_mask` calls lit), the share of connections by the number of crossings of the
seed segment, and the light of the connections not made (the straight seed's index-matched
light, ``mnee_lost_*``) as a share of the index-matched image.

Scenes (``--scene``, one or more; by default ``torus_hole`` and every suite scene behind a smooth
dielectric; one with ``--area-limit``, by default ``torus_hole``): ``torus_hole`` (skin_torus_dielectric's
torus and light, whose light passes through the near side of the ring to reach the far side, with a thin medium: sigma_t
1.5 / 2 / 3, albedo 0.9 / 0.85 / 0.8), or any suite scene name.

``--area-limit R``: instead, the area-light limit on the scene at eta 1.4 (``--eta``): stock
``volpath`` with a sphere light of radius R (radiance I / (pi R^2)) at the point light's place,
over the pixels where its absorber pass (albedo 0) shows no reflection of the bulb in the
boundary (a point light has none), against ``mneevolpath`` with the point light (chains on and off), at
``--max-depth``; prints the image mean ratios and their standard errors.

``--decompose``: instead, per scene (``--scenes``; ``torus_hole`` at eta 1.4), the power that first
scatters in the medium traced from the point light through every specular path
(:mod:`harness.reference.specular_paths`: one refraction, chains through 3, 5 ... crossings,
paths with a reflection) against what ``mneevolpath``'s connections deliver
(:mod:`harness.reference.connection_power`), the share of connections by crossing count of the
seed segment (``stats``, at ``--size``), and, when ``torus_hole`` is among them, the area-light limit
at each ``--depths`` beside the shortfall the first-scatter figures predict for that depth. With
``--write`` it writes ``docs/benchmarks/mnee_chains.md`` (:mod:`page`) for the default scenes and
``mnee_chains_<scene names>.md`` for another set (e.g. ``--scenes bunny_dielectric``). The other runs'
``--write`` writes their printout to ``mnee_chains_eta_one[_<scenes>].md`` (by the scenes named; none for
the default set) or ``mnee_chains_area_limit.md``.

Usage: ``.venv/bin/python benchmarks/mnee_chains.py [--scene torus_hole] [--size 32] [--spp 64] [--seeds 4]``
``[--area-limit 0.25 --eta 1.4 --max-depth 6 --area-spp 16384]``
``[--decompose --depths 4 5 6 --write]``.
"""

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

from harness.reference import mitsuba_scene as ms
from harness.reference import nonconvex
from harness.scene import Boundary, load_scene

SMOOTH_SCENES = ("torus_hole", "skin_torus_dielectric", "jade_backlit_dielectric")


def scene_named(name):
    return nonconvex.torus_hole() if name == "torus_hole" else load_scene(name)


def median_rel_se(stack, covered):
    """Median over covered, lit (pixel, channel) pairs of se / mean (K seeds)."""
    mean, se = stack.mean(0), stack.std(0, ddof=1) / np.sqrt(len(stack))
    lit = covered[..., None] & (mean > 0)
    return float(np.median(se[lit] / mean[lit]))


def fmt(a, digits=4):
    return "[" + ", ".join(f"{v:.{digits}f}" for v in np.ravel(a)) + "]"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", nargs="+", default=None,
                    help="one scene or more (default: torus_hole and every suite smooth-dielectric scene; with "
                         "--area-limit one, default torus_hole)")
    ap.add_argument("--size", type=int, default=32)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--max-crossings", type=int, nargs="+", default=[1, 5])
    ap.add_argument("--eta", default="1.0001", help="the boundary's index, or 'own' (the scene's)")
    ap.add_argument("--area-limit", type=float, default=None, metavar="R")
    ap.add_argument("--max-depth", type=int, default=-1)
    ap.add_argument("--area-spp", type=int, default=16384)
    ap.add_argument("--decompose", action="store_true", help="the first-scatter decomposition and its page")
    ap.add_argument("--scenes", nargs="+", default=list(SMOOTH_SCENES))
    ap.add_argument("--depths", type=int, nargs="+", default=[4, 5, 6])
    ap.add_argument("--photons", type=int, default=1 << 16)
    ap.add_argument("--points", type=int, default=1 << 19)
    ap.add_argument("--write", action="store_true", help="write docs/benchmarks/mnee_chains[_<scenes>].md (with --decompose)")
    args = ap.parse_args()
    mi = ms.use_variant("llvm_ad_rgb")
    if args.decompose:
        return decompose(mi, args)
    if args.area_limit is not None:
        args.scene = args.scene or ["torus_hole"]
        if len(args.scene) != 1:
            print(f"error: --scene: scene: --area-limit takes one scene, not {len(args.scene)}; name one", file=sys.stderr)
            return 2
        return area_limit(mi, args)
    for name in args.scene or ["torus_hole", *ms.smooth_suite_scenes()]:
        eta_one(mi, args, name)


def eta_one(mi, args, name):
    """eta = 1.0001 against index-matched volpath on the scene ``name``, with and without chains (docstring)."""
    from harness.reference import mnee
    from harness.reference.noise import lit_mask, stack_agreement

    base = scene_named(name).with_resolution(args.size, args.size)
    matched = dataclasses.replace(base, boundary=Boundary("index-matched"))
    eta = base.boundary.eta if args.eta == "own" else float(args.eta)
    smooth = dataclasses.replace(base, boundary=Boundary("dielectric", eta, 0.0))
    print(f"{name} at {args.size} x {args.size}, K = {args.seeds} x {args.spp} spp each, eta = {eta}, "
          f"{len(ms.channel_passes(base.medium))} pass(es) as the reference renders them")
    b, tb = ms.render_in_passes(mi, matched, range(100, 100 + args.seeds), args.spp)
    pb = b.mean((1, 2))
    coverage = ms.coverage_mask(matched)
    covered = coverage >= 1.0
    rb = median_rel_se(b, covered)
    lit_c = lit_mask(b.mean(0), coverage)
    print(f"  index-matched volpath: {tb:.0f} s, image mean {fmt(pb.mean(0))}, median rel. SE {rb:.4f}")
    names = ["R", "G", "B"] + list(mnee.STATS_AOVS)
    for mc in args.max_crossings:
        a, ta = ms.render_in_passes(mi, smooth, range(args.seeds), args.spp, {"stats": True, "max_crossings": mc})
        img, aov = a[..., :3], a[..., 3:].sum((1, 2)).mean(0)
        st = dict(zip(names[3:], aov))
        # z per lit channel, as the eta -> 1 tests judge (noise.lit_mask of the index-matched image)
        ag = stack_agreement(img, b, lit_c)
        z, within = ag["z"], ag["within"]
        started = st["mnee_started"]
        cross = [st[k] / started for k in ("mnee_cross1", "mnee_cross3", "mnee_cross5", "mnee_cross7_more")]
        over = st["mnee_over_max"] / started
        lost = np.array([st["mnee_lost_r"], st["mnee_lost_g"], st["mnee_lost_b"]]) / (pb.mean(0) * args.size ** 2)
        ra = median_rel_se(img, covered)
        # Time to a noise target T = t (r / target)^2 for both, in one run: their ratio.
        print(f"  max_crossings = {mc}: {ta:.0f} s ({ta / tb:.2f} x index-matched), median rel. SE {ra:.4f}: time to "
              f"the same noise {ta * ra ** 2 / (tb * rb ** 2):.2f} x index-matched; image mean ratio "
              f"{fmt(ag['ratio'])}, (difference) / SE {fmt(ag['diff'] / ag['diff_se'], 2)}; "
              f"lit pixels within 4 SE {within:.4f} of {ag['pixels']}, mean z {fmt(np.nanmean(z.reshape(-1, 3), 0), 2)}")
        print(f"    connections by crossings of the seed segment (1, 3, 5, >= 7): {fmt(cross)}; chains connected "
              f"{st['mnee_chain_connected'] / started:.4f}, lost {st['mnee_lost'] / started:.4f} (over the maximum "
              f"{over:.4f}); lost light "
              f"(straight, index-matched) / image {fmt(lost)}")


def area_ratio(mi, scene, r, md, seeds, area_spp, spp):
    """Sphere light (volpath) over point light (the scene's integrator) at ``max_depth = md``: ratio, SE, pixels out."""
    light = scene.lights[0]
    area = ms.area_light_limit(light.position, light.intensity, r, md)
    full, _ = ms.render_seeds(mi, ms.build_scene_dict(scene, **area), range(100, 100 + seeds), area_spp)
    absorber, _ = ms.render_seeds(mi, ms.build_scene_dict(scene, albedo_override=0.0, **area), range(200, 202), area_spp // 4)
    keep = np.all(absorber.mean(0) <= 1e-3 * np.maximum(full.mean(0), 1e-12), axis=-1)
    point, _ = ms.render_seeds(mi, ms.build_scene_dict(scene, max_depth=md), range(seeds), spp)
    f, p = full[:, keep].mean(1), point[:, keep].mean(1)
    ratio = f.mean(0) / p.mean(0)
    se = ratio * np.sqrt(f.var(0, ddof=1) / len(f) / f.mean(0) ** 2 + p.var(0, ddof=1) / len(p) / p.mean(0) ** 2)
    return ratio, se, int((~keep).sum())


def rgb(a, digits=3):
    return " / ".join(f"{v:.{digits}f}" for v in np.ravel(a))


def page_name(scenes):
    """``mnee_chains`` for the default scenes, ``mnee_chains_<last path parts>`` for another set (one page per set)."""
    if list(scenes) == list(SMOOTH_SCENES):
        return "mnee_chains"
    return "mnee_chains_" + "_".join(Path(s).name for s in scenes)


def decompose(mi, args):
    """First-scattered light by path type, traced and delivered; crossing counts; the area-light limit (docstring)."""
    from page import Page

    from harness.reference import connection_power, losses, specular_paths

    page = Page(page_name(args.scenes), "Manifold connections on curved and non-convex meshes: what they deliver, what they miss")
    page.para(
        "The power that first scatters in the medium, traced from the point light through every specular path "
        f"({args.photons} photons split deterministically at each boundary hit, `harness/reference/specular_paths.py`), "
        "by class: one refraction (`direct`), through other parts of the object (`chain3`: leave, enter, leave), and "
        "any path with a reflection at the boundary on the way (`reflection`), which no connection of `mneevolpath` "
        "makes. Against it, the same power as `mneevolpath`'s own connection delivers it "
        f"(`harness/reference/connection_power.py`, {args.points} uniform points in the medium's box, with its "
        "standard error): `missed = 1 - delivered / traced`, what `reference.json` records as "
        "`mnee_losses.first_scatter` (`harness/reference/losses.py`). Shares are per channel R / G / B.")
    rows, scenes = [], {}
    for name in args.scenes:
        scene = nonconvex.torus_hole(1.4) if name == "torus_hole" else load_scene(name)
        scenes[name] = scene
        traced = specular_paths.trace(scene, photons=args.photons)
        by = traced["by_class"]
        total = sum(by.values(), np.zeros(3))
        chains = sum((v for k, v in by.items() if k.startswith("chain")), np.zeros(3))
        got, se, _ = connection_power.delivered(scene, points=args.points)
        single = dataclasses.replace(scene, boundary=dataclasses.replace(scene.boundary, max_crossings=1))
        got1, se1, _ = connection_power.delivered(single, points=args.points)
        direct = by.get("direct", np.zeros(3))
        rows.append([name, f"{scene.boundary.eta:g}", rgb(direct / total), rgb(chains / total),
                     rgb(by.get("reflection", np.zeros(3)) / total),
                     f"{rgb(got1 / direct)} ± {rgb(se1 / direct)}",
                     f"{rgb(1 - got / total)} ± {rgb(se / total)}"])
    page.table(["scene", "eta", "direct", "chains", "reflection", "single walk delivered / traced direct",
                "missed (all)"], rows,
               note="`direct`, `chains`, `reflection`: shares of the traced first-scattered power. The single walk's "
                    "delivery (rendered with `max_crossings = 1`) over the traced one-refraction power shows the light "
                    "lost to single walks that end on another solution than the one that carries it (occluded, or "
                    "one of several near a caustic of the interface) or fail.")
    rows = []
    for name, scene in scenes.items():
        small = scene.with_resolution(args.size, args.size)
        found = losses.measure(small)
        for c, ch in found["channels"].items():
            rows.append([name, c, " / ".join(f"{ch['crossings'][b]:.3f}" for b in losses.BINS),
                         f"{ch['single_walk_failed']:.3f}", f"{ch['chain_connected']:.3f}", f"{ch['lost']:.4f}"])
            if len(found["channels"]) == 1:
                rows[-1][1] = "RGB"
    page.table(["scene", "channel", "crossings 1 / 3 / 5 / >= 7", "single walk not converged", "chain connected",
                "not made (counted)"], rows,
               note=f"Shares of the connections from medium vertices ({args.size} x {args.size}, "
                    f"{losses.LOSS_SEEDS} x {losses.LOSS_SPP} spp, `stats`).")
    if "torus_hole" not in args.scenes:     # the area-light limit is measured on the torus lit through its hole
        page.finish(args.write)
        return
    scene = nonconvex.torus_hole(1.4).with_resolution(args.size, args.size)
    traced = specular_paths.trace(scene, photons=args.photons)["by_label"]
    total = sum(traced.values(), np.zeros(3))
    rows = []
    for md in args.depths:
        # A first scattering at depth 2 reaches the light through at most md - 3 boundary events; mneevolpath
        # connects one refraction from md = 4 and chains through k crossings from md = k + 3.
        reach = sum((v for lab, v in traced.items() if len(lab) <= md - 3), np.zeros(3))
        kmax = max(1, md - 3 - (md - 3 + 1) % 2)
        sc = dataclasses.replace(scene, boundary=dataclasses.replace(scene.boundary, max_crossings=min(kmax, 9)))
        got, se, _ = connection_power.delivered(sc, points=args.points)
        ratio, rse, out = area_ratio(mi, sc, args.area_limit or 0.25, md, args.seeds, args.area_spp, args.spp)
        rows.append([md, f"{rgb(ratio)} ± {rgb(rse)}", f"{rgb(reach / got)} ± {rgb(reach / got * se / got)}",
                     f"{rgb(reach / total)}", out])
    page.table(["max_depth", "sphere light / point light (image)", "traced / delivered (first scatter)",
                "traced share reachable at this depth", "pixels left out"], rows,
               note=f"torus_hole, eta 1.4, {args.size} x {args.size}: stock `volpath` with a sphere light of radius "
                    f"{args.area_limit or 0.25} (radiance I / (pi r^2); {args.seeds} x {args.area_spp} spp) over "
                    f"`mneevolpath` with the point light ({args.seeds} x {args.spp} spp), image means over the pixels "
                    "that show no reflection of the bulb, with their standard errors; beside it the ratio the "
                    "first-scatter figures predict for a first scattering at this depth (paths of at most "
                    "max_depth - 3 boundary events traced; chains delivered from max_depth = 6). Higher orders of "
                    "scattering, the image's weighting of the medium and the bulb's radius make the two differ.")
    page.finish(args.write)


def area_limit(mi, args):
    r, md = args.area_limit, args.max_depth
    scene = dataclasses.replace(scene_named(args.scene[0]).with_resolution(args.size, args.size),
                                boundary=Boundary("dielectric", float(args.eta), 0.0))
    light = scene.lights[0]
    print(f"area-light limit, {args.scene[0]} at {args.size} x {args.size}, eta {args.eta}, max_depth {md}, "
          f"sphere light r = {r}: K = {args.seeds} x {args.area_spp} spp (full and absorber), point K = "
          f"{args.seeds} x {args.spp}")
    area = ms.area_light_limit(light.position, light.intensity, r, md)
    seeds = range(100, 100 + args.seeds)
    full, tf = ms.render_seeds(mi, ms.build_scene_dict(scene, **area), seeds, args.area_spp)
    absorber, ta = ms.render_seeds(mi, ms.build_scene_dict(scene, albedo_override=0.0, **area), range(200, 200 + args.seeds),
                          args.area_spp)
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
        p, tp = ms.render_seeds(mi, d, range(args.seeds), args.spp)
        p = p[:, keep].mean(1)
        ratio = area / p.mean(0)
        se = ratio * np.sqrt(var_area / area ** 2 + p.var(0, ddof=1) / len(p) / p.mean(0) ** 2)
        print(f"  mneevolpath, point light, max_crossings = {mc}: {tp:.0f} s; sphere / point {fmt(ratio)} "
              f"+- {fmt(se)}")


def printout_page(argv):
    """The page of a run whose figures are its printout (:func:`page.run`); None for ``--decompose``, which
    writes its own page (:func:`page_name`), so that the two never write the same file."""
    if "--decompose" in argv:
        return None
    if "--area-limit" in argv:
        return "mnee_chains_area_limit"
    scenes = []
    for a in argv[argv.index("--scene") + 1:] if "--scene" in argv else []:
        if a.startswith("-"):
            break
        scenes.append(a)
    return "_".join(["mnee_chains_eta_one", *scenes])


if __name__ == "__main__":
    from page import run

    if printout_page(sys.argv[1:]) is None:
        raise SystemExit(main())
    raise SystemExit(run(main, printout_page, "Connections through several interfaces"))
