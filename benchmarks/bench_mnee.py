"""The exact smooth-dielectric reference (``mneevolpath``): agreement, limits, failures and cost.

Parts (``--part``, default all but ``slab``, ``time``, ``rough`` and ``eta2``, which take longest):

``halfspace``   test 1 at a larger budget: single scattering in the validation half-space
                (:mod:`harness.reference.halfspace`), eta 1.33 and 1.5, 32 x 32, K = 16 x 128
                spp, against the NumPy route: z-statistics, image mean, planted errors.
``slab``        the chains' test 2 at a larger budget: the half-space under a slab of the same medium
                (air between; :data:`harness.reference.halfspace.SLAB_SETUP`), single scattering
                through three interfaces, eta 1.33 and 1.5, 32 x 32, K = 16 x 128 spp, against the
                NumPy route: z-statistics, image mean, two planted errors.
``eta1``        test 2: eta = 1.0001 against index-matched ``volpath`` (jade_veins, 32 x 32), over the lit
                pixels as the eta -> 1 tests count them (:func:`harness.reference.noise.stack_agreement`).
``area-limit``  test 3's sequence: stock ``volpath`` with a sphere light of radius r
                (radiance I / (pi r^2)) behind the grey half-space over the point-light image,
                r = 0.4, 0.25, 0.15, 0.1.
``rough``       report only: GGX ``roughdielectric`` with alpha = 0.2, 0.1, 0.05 against the
                exact image of the same scene (skin_torus_dielectric, 32 x 32): energy ratio,
                relative MSE, and the rough image's own noise.
``failures``    the manifold walks on every smooth scene of the suite and the half-space
                (64 x 64, ``stats`` with 4 probe seeds): share of walks started that converge
                and connect, share rescued by a probe, and the light the probes found that the
                main walk missed (a lower bound of the energy lost), per channel.
``time``        the time to reach each smooth scene's noise target (``reference_rel_se``) at
                128 x 128 against the index-matched version of the same scene, in one run:
                rendered to the target with ``render_reference`` (pilot and top-ups), or with
                ``--time-spp S`` predicted from one render of K = 8 x S spp each (time and
                measured noise, SE ~ 1/sqrt(N)).
``eta2``        SSLPV with ``eta2`` off and on against the exact committed 64 x 64 references
                of the smooth scenes: energy ratio and relMSE of the subsurface image.

Usage: ``.venv/bin/python benchmarks/bench_mnee.py [--part halfspace eta1 ...] [--variant cuda_ad_rgb]``.
``--write`` writes the printout to ``docs/benchmarks/bench_mnee[_PART...].md`` (one page per
``--part`` selection; ``benchmarks/page.py``).
"""

import argparse
import dataclasses
import tempfile
import time

import numpy as np

from harness.reference import halfspace
from harness.reference import mitsuba_scene as ms
from harness.reference.noise import lit_mask, stack_agreement
from harness.scene import Boundary, load_scene

SMOOTH_SCENES = ms.smooth_suite_scenes()


def fmt(a, digits=4):
    return "[" + ", ".join(f"{v:.{digits}f}" for v in np.ravel(a)) + "]"


# --------------------------------------------------------------------------- parts

def against_numpy(mi, scene, max_depth, ref, planted, note=""):
    """Render ``scene`` (K = 16 x 128 spp, ``max_depth``) and print its agreement with the NumPy image ``ref``
    (z-statistics over the pixels with noise, the image mean ratio) and how far each planted error's image lies."""
    st, secs = ms.render_seeds(mi, ms.build_scene_dict(scene, max_depth=max_depth), range(16), 128)
    mean, se = st.mean(0), st.std(0, ddof=1) / np.sqrt(len(st))
    lit = np.all(se > 0, axis=-1)
    z = ((mean - ref) / np.where(se > 0, se, 1))[lit]
    per_seed = st.mean((1, 2))
    ratio = per_seed.mean(0) / ref.mean((0, 1))
    ratio_se = per_seed.std(0, ddof=1) / np.sqrt(len(st)) / ref.mean((0, 1))
    print(f"  eta {scene.boundary.eta}: {secs:.0f} s; {note}within 4 SE {np.mean(np.all(np.abs(z) <= 4, -1)):.4f} of "
          f"{int(lit.sum())} pixels, max |z| {np.abs(z).max():.2f}, mean z^2 {np.mean(z ** 2):.3f}; image mean / NumPy "
          f"{fmt(ratio)} +- {fmt(ratio_se)}; median pixel rel SE {np.median(se[lit] / mean[lit]):.4f}")
    for name, wrong in planted.items():
        zw = ((mean - wrong) / np.where(se > 0, se, 1))[lit]
        print(f"    planted '{name}': mean z^2 {np.mean(zw ** 2):.1f}, image mean / NumPy "
              f"{fmt(per_seed.mean(0) / wrong.mean((0, 1)))}")


def part_halfspace(mi, args):
    print("test 1: single scattering in the half-space against NumPy (32 x 32, K = 16 x 128 spp)")
    for eta in (1.33, 1.5):
        scene = halfspace.validation_scene(eta, size=32)
        ref = halfspace.setup_image(scene, sub=6, nodes=64)
        against_numpy(mi, scene, 4, ref, {
            "no light-side Fresnel": halfspace.setup_image(scene, sub=4, fresnel_light=False),
            "straight inverse square": halfspace.setup_image(scene, sub=4, geometry="straight"),
            "no eta^2 in G": ref / eta ** 2})


def part_slab(mi, args):
    """Test 2 of the chains at a larger budget: the half-space under a slab of the same medium with air between
    (:data:`harness.reference.halfspace.SLAB_SETUP`), single scattering through three interfaces against NumPy."""
    setup = halfspace.SLAB_SETUP
    print("chains, test 2: single scattering under the slab (three interfaces) against NumPy (32 x 32, "
          "K = 16 x 128 spp, max_depth 6)")
    for eta in (1.33, 1.5):
        scene = halfspace.validation_scene(eta, size=32, setup=setup)
        against_numpy(mi, scene, 6, halfspace.setup_image(scene, setup=setup, sub=6, nodes=64), {
            "middle Fresnel factor skipped": halfspace.setup_image(scene, setup=setup, sub=4, fresnel_count=2),
            "straight inverse square": halfspace.setup_image(scene, setup=setup, sub=4, geometry="straight")},
            note=f"chains outside the slab's footprint {halfspace.slab_outside_share(scene):.1e} of the integral; ")


def part_eta1(mi, args):
    print("test 2: eta = 1.0001 (mneevolpath) against index-matched volpath (jade_veins, 32 x 32, K = 8 x 256)")
    base = load_scene("jade_veins").with_resolution(32, 32)
    smooth = dataclasses.replace(base, boundary=Boundary("dielectric", 1.0001, 0.0))
    a, ta = ms.render_seeds(mi, ms.build_scene_dict(smooth), range(8), 256)
    b, tb = ms.render_seeds(mi, ms.build_scene_dict(base), range(100, 108), 256)
    ag = stack_agreement(a, b, lit_mask(b.mean(0), ms.coverage_mask(base)))   # lit as the eta -> 1 tests count
    z = ag["z"][np.isfinite(ag["z"])]
    print(f"  {ta:.0f} s / {tb:.0f} s; lit pixels within 4 SE {ag['within']:.4f} of {ag['pixels']}, max |z| "
          f"{np.abs(z).max():.2f}, mean z^2 {np.mean(z ** 2):.3f}; image mean ratio {fmt(ag['ratio'])}, "
          f"difference / SE {fmt(ag['diff'] / ag['diff_se'], 2)}")


def part_area_limit(mi, args):
    setup = dict(halfspace.SETUP, sigma_t=(1.6, 1.6, 1.6), albedo=(0.8, 0.8, 0.8))
    scene = halfspace.validation_scene(1.33, size=8, setup=setup)
    point, tp = ms.render_seeds(mi, ms.build_scene_dict(scene, max_depth=4), range(8), 1024)
    pm = point.mean((1, 2))[:, 0]
    print(f"test 3: sphere light of radius r / point light (grey half-space, single scattering, 8 x 8); "
          f"point light K = 8 x 1024 spp in {tp:.0f} s, rel SE {pm.std(ddof=1) / np.sqrt(8) / pm.mean():.4f}")
    for r in (0.4, 0.25, 0.15, 0.1):
        d = ms.build_scene_dict(scene, **ms.area_light_limit(setup["light"], setup["intensity"], r, 4))
        area, ta = ms.render_seeds(mi, d, range(100, 108), args.area_spp)
        am = area.mean((1, 2))[:, 0]
        ratio = am.mean() / pm.mean()
        se = ratio * np.hypot(am.std(ddof=1) / np.sqrt(8) / am.mean(), pm.std(ddof=1) / np.sqrt(8) / pm.mean())
        print(f"  r = {r:<5} ratio {ratio:.4f} +- {se:.4f}   (volpath K = 8 x {args.area_spp} spp, {ta:.0f} s)")


def part_rough(mi, args):
    from harness.metrics.pixel import energy_ratio, relmse

    name = "skin_torus_dielectric"
    base = load_scene(name).with_resolution(32, 32)
    cov = ms.coverage_mask(base) >= 0.999
    ex, te = ms.render_seeds(mi, ms.build_scene_dict(base), range(8), args.rough_spp // 4)
    exact = ex.mean(0)
    print(f"report: rough dielectric alpha -> 0 against the exact image ({name}, 32 x 32; exact K = 8 x "
          f"{args.rough_spp // 4} spp in {te:.0f} s, median rel SE "
          f"{np.median((ex.std(0, ddof=1) / np.sqrt(8))[cov] / exact[cov]):.4f})")
    for alpha in (0.2, 0.1, 0.05):
        rough = dataclasses.replace(base, boundary=Boundary("dielectric", base.boundary.eta, alpha))
        full, tf = ms.render_seeds(mi, ms.build_scene_dict(rough), range(8), args.rough_spp)
        absorber, ta = ms.render_seeds(mi, ms.build_scene_dict(rough, albedo_override=0.0), range(200, 208), args.rough_spp)
        sub = full - absorber                      # the subsurface part, separated as the harness does
        m = sub.mean(0)
        rel_se = np.median((sub.std(0, ddof=1) / np.sqrt(8))[cov] / np.maximum(m[cov], 1e-12))
        energy = energy_ratio(m, exact, cov)
        err = relmse(m, exact, cov)
        print(f"  alpha {alpha:<5} subsurface energy / exact {fmt(energy.per_channel)}, relMSE {err.value:.4f} "
              f"(harness metric, eps {err.params['eps']}), rough median rel SE {rel_se:.3f} "
              f"(K = 8 x {args.rough_spp} spp, {tf + ta:.0f} s)")


def failure_scenes():
    out = [(n, load_scene(n).with_resolution(64, 64)) for n in SMOOTH_SCENES]
    return out + [("halfspace eta 1.33", halfspace.validation_scene(1.33, size=64))]


def part_failures(mi, args):
    print("manifold walks (64 x 64, 64 spp, stats with 4 probe seeds; shares of walks started)")
    print(f"  {'scene':<26} {'converged':>9} {'connected':>9} {'rescued':>8}   missed light / image (RGB)")
    for name, scene in failure_scenes():
        d = ms.build_scene_dict(scene, max_depth=4 if name.startswith("halfspace") else -1)
        d["integrator"].update(stats=True, probe_seeds=4)
        img, _ = ms.render_seeds(mi, d, [0], 64)
        img = img[0]
        tot = img.sum((0, 1))
        from harness.reference.mnee import PROBE_AOVS, SMS_AOVS, STATS_AOVS   # after use_variant: its integrator needs one

        names = STATS_AOVS + (SMS_AOVS if d["integrator"].get("sms_trials") else ()) + PROBE_AOVS   # its aov_names
        at = {n: 3 + i for i, n in enumerate(names)}                       # after R, G, B: the AOVs by name
        assert img.shape[-1] == 3 + len(at), f"{img.shape[-1]} channels for {3 + len(at)} (R, G, B and the AOVs)"
        started, conv, conn = (tot[at[n]] for n in ("mnee_started", "mnee_converged", "mnee_connected"))
        rescued = tot[at["mnee_probe_rescued"]]
        missed = tot[[at[f"mnee_probe_missed_{c}"] for c in "rgb"]] / tot[:3]
        print(f"  {name:<26} {conv / started:>9.4f} {conn / started:>9.4f} {rescued / started:>8.5f}   {fmt(missed, 5)}")


def part_time(mi, args):
    """Time to the noise target, smooth over index-matched, in one run.

    Without ``--time-spp`` each version is rendered to the target by ``render_reference``
    (pilot and top-ups: measured, not extrapolated; hours at 128 x 128 on a 2-core machine).
    With ``--time-spp S`` each is rendered once at K = 8 x S spp after a warm-up that compiles
    its kernels, and the time to the target is predicted from the measured time and noise by
    SE ~ 1/sqrt(N): ``T = t (r / target)^2`` (the same K, so the low bias of a median of SEs
    cancels in the ratio; ``render_reference``'s own pilot predicts the same way). These renders
    skip the exactness verdict (``judge_exactness=False``), which is no part of a render's cost;
    the CPU column is the render jobs' own CPU time (all their threads).
    """
    from harness.reference.render import render_reference

    mode = "render_reference: pilot and top-ups" if args.time_spp is None else \
        f"K = 8 x {args.time_spp} spp each after a warm-up, T = t (r / target)^2"
    print(f"time to each scene's noise target at 128 x 128 ({mode}), one run, {args.variant}")
    for name in SMOOTH_SCENES:
        smooth = load_scene(name).with_resolution(128, 128)
        target = float(smooth.tolerances["reference_rel_se"])
        matched = dataclasses.replace(smooth, boundary=Boundary("index-matched"))
        rows = {}
        for label, sc in (("index-matched", matched), ("smooth", smooth)):
            with tempfile.TemporaryDirectory() as tmp:
                if args.time_spp is None:
                    meta = render_reference(sc, f"{tmp}/ref", target_rel_se=target, variant=args.variant,
                                            max_spp_per_seed=65536)
                    seconds = meta["render_seconds"]
                else:
                    # no exactness verdict after either render: it is not part of the render's cost
                    warm = render_reference(sc, f"{tmp}/warm", spp=1, K=2, variant=args.variant,
                                            judge_exactness=False)
                    meta = render_reference(sc, f"{tmp}/ref", spp=args.time_spp, K=8, variant=args.variant,
                                            judge_exactness=False)
                    # the render jobs' own CPU time (all their threads: robust to other jobs' load)
                    cpu = meta["render_cpu_seconds"]
                    r = meta["median_rel_se_subsurface"]
                    scale = (r / target) ** 2
                    seconds = meta["render_seconds"] * scale
                    rows[label + " cpu"] = cpu * scale
                    print(f"  {name:<26} {label:<14} warm-up (K = 2 x 1 spp) {warm['render_seconds']:.1f} s; "
                          f"{meta['render_seconds']:.1f} s wall, {cpu:.1f} s CPU for {meta['spp_total']} spp, "
                          f"rel SE {r:.4f} -> {meta['spp_total'] * scale:.0f} spp to {target}")
            rows[label] = seconds
            if args.time_spp is None:
                print(f"  {name:<26} {label:<14} {seconds:>8.1f} s  spp {meta['spp_total']:>6}  "
                      f"rel SE {meta['median_rel_se_subsurface']:.4f} (target {target}, met {meta['target_met']})")
            else:
                print(f"  {name:<26} {label:<14} time to target {seconds:>8.1f} s wall, "
                      f"{rows[label + ' cpu']:.1f} s CPU (predicted)")
        print(f"  {name:<26} ratio smooth / index-matched {rows['smooth'] / rows['index-matched']:.2f}"
              + ("" if args.time_spp is None else
                 f" (wall), {rows['smooth cpu'] / rows['index-matched cpu']:.2f} (CPU time)"))


def part_eta2(mi, args):
    from harness.regression.accuracy import load_case_reference
    from harness.runs.worker import measure
    from sslpv_gl.params import SSLPVParams
    from sslpv_gl.renderer import SSLPVRenderer

    renderer = SSLPVRenderer()
    print("SSLPV eta2 against the exact committed 64 x 64 references (subsurface image)")
    print(f"  {'scene':<26} {'config':<24} {'eta2':>5} {'energy ratio':>13} {'relMSE':>9}")
    try:
        for name in SMOOTH_SCENES:
            scene = load_scene(name).with_resolution(64, 64)
            ref, floors = load_case_reference(scene)
            for mapping in ("collision", "diffusion"):
                for eta2 in (False, True):
                    params = SSLPVParams(N=32, steps=32, mapping=mapping, eta2=eta2)
                    res = renderer.render(scene, params)
                    rows = {r["metric"]: r for r in measure({"subsurface": res.subsurface, "full": res.full}, ref,
                                                            floors) if r["image"] == "subsurface"}
                    print(f"  {name:<26} {'N32-K32-' + mapping:<24} {str(eta2):>5} "
                          f"{rows['energy_ratio']['value']:>13.4f} {rows['relmse']['value']:>9.4f}")
    finally:
        renderer.ctx.release()


PARTS = {"halfspace": part_halfspace, "slab": part_slab, "eta1": part_eta1, "area-limit": part_area_limit, "rough": part_rough,
         "failures": part_failures, "time": part_time, "eta2": part_eta2}
DEFAULT_PARTS = ["halfspace", "eta1", "area-limit", "failures"]


def _page_name(base, argv):
    """``base`` for the default parts, else ``base_<part>_<part>...`` (the parts after ``--part``)."""
    if "--part" not in argv:
        return base
    parts = []
    for a in argv[argv.index("--part") + 1:]:
        if a.startswith("-"):
            break
        parts.append(a.replace("-", "_"))
    return "_".join([base, *parts])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", nargs="+", choices=list(PARTS), default=DEFAULT_PARTS)
    ap.add_argument("--variant", default="llvm_ad_rgb", help="Mitsuba variant (cuda_ad_rgb on an NVIDIA GPU)")
    ap.add_argument("--area-spp", type=int, default=16384, help="spp per seed of the sphere-light renders")
    ap.add_argument("--time-spp", type=int, default=None,
                    help="time part: spp per seed of one render each, time to target predicted from its noise "
                         "(default: render each to the target)")
    ap.add_argument("--rough-spp", type=int, default=1024, help="spp per seed of the rough renders")
    args = ap.parse_args()
    mi = ms.use_variant(args.variant)
    for part in args.part:
        t = time.perf_counter()
        PARTS[part](mi, args)
        print(f"  ({part}: {time.perf_counter() - t:.0f} s)\n")


if __name__ == "__main__":
    from page import run

    raise SystemExit(run(main, lambda argv: _page_name("bench_mnee", argv),
                         "The exact smooth-dielectric reference (MNEE): validation and cost"))
