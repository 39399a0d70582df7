"""The reference cost model: fit it on a family of homogeneous spheres, and check it on real scenes.

``--fit`` renders ``sphere_homogeneous`` (its mesh, camera and light) at 32x32 with
homogeneous media over a grid of sigma_t and albedo (8 seeds x ``--spp`` samples each,
serial, Dr.Jit's default thread count), measures the seconds per sample per covered
pixel and the relative variance of one sample, fits the model of
``harness/reference/cost.py`` and writes ``harness/reference/cost_model.json``.

``--check SCENE[:WxH] ...`` compares, for each scene, the model's prediction
(``sslpv-harness reference --estimate``) with the wall time of the real command
(``sslpv-harness reference SCENE --size WxH --force``, default LocalCluster, into a
temporary cache) at the scene's ``small_reference_rel_se`` target; ``SCENE:committed``
takes the measured time from the committed reference in ``baselines/refs`` instead of
rendering it again.

Usage::

    .venv/bin/python benchmarks/bench_reference_cost.py --fit            # about 5 minutes on 2 cores
    .venv/bin/python benchmarks/bench_reference_cost.py --check sphere_homogeneous:64x64 jade_veins:64x64 \\
        skin_torus:64x64 marble_sphere:committed
"""

import argparse
import json
import os
import platform
import tempfile
import time
from datetime import datetime, timezone

import numpy as np

from harness.reference import cost
from harness.scene import load_scene

SIGMA_T = (1.5, 6.0, 24.0, 96.0, 192.0)
ALBEDO = (0.6, 0.9, 0.99, 0.999)


def measure_point(base, sigma_t, albedo, spp, K=8):
    from harness.reference.render import render_reference

    shape = base.medium.sigma_t.shape
    scene = base.with_medium(sigma_t=np.full(shape, sigma_t, np.float32), albedo=np.full(shape, albedo, np.float32))
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        meta = render_reference(scene, f"{tmp}/ref", spp=spp, K=K)
        wall = time.perf_counter() - t0
    n = meta["spp_total"]
    r = meta["median_rel_se_subsurface"]
    chord = cost.mean_chord(scene.mesh)
    return {"sigma_t": sigma_t, "albedo": albedo, "tau": sigma_t * chord, "spp_total": n,
            "covered_pixels": meta["covered_pixels"], "render_s": meta["render_seconds"], "wall_s": wall,
            "t_px": meta["render_seconds"] / (n * meta["covered_pixels"]), "rel_se": r, "v": r * r * n,
            "rr_depth": meta["integrator"]["rr_depth"]}


def do_fit(spp, out):
    import mitsuba

    from harness.runs.sweep import make_client

    base = load_scene("sphere_homogeneous").with_resolution(32, 32)
    points = []
    print(f"{'sigma_t':>8} {'albedo':>7} {'tau':>7} {'rr_depth':>8} {'s/spp/px':>10} {'rel SE':>7} {'v':>9}")
    for st in SIGMA_T:
        for a in ALBEDO:
            p = measure_point(base, st, a, spp)
            points.append(p)
            print(f"{st:>8g} {a:>7g} {p['tau']:>7.1f} {p['rr_depth']:>8} {p['t_px']:>10.3e} {p['rel_se']:>7.4f} "
                  f"{p['v']:>9.3g}", flush=True)
    tau, alb = [p["tau"] for p in points], [p["albedo"] for p in points]
    tc, trms = cost.fit(tau, alb, [p["t_px"] for p in points])
    vc, vrms = cost.fit(tau, alb, [p["v"] for p in points])
    t0 = time.perf_counter()
    client, cluster = make_client(None, None)
    client.close()
    cluster.close()
    start = time.perf_counter() - t0
    overhead = float(np.median([p["wall_s"] - p["render_s"] for p in points]))
    model = {"fitted": datetime.now(timezone.utc).isoformat(timespec="seconds"),
             "command": f"benchmarks/bench_reference_cost.py --fit --spp {spp}",
             "machine": {"cores": os.cpu_count(), "cpu": platform.processor() or platform.machine(),
                         "mitsuba": mitsuba.__version__, "variant": "llvm_ad_rgb", "threads": "Dr.Jit default"},
             "family": "sphere_homogeneous mesh, camera and light, 32x32, homogeneous grey media, index-matched",
             "time": {"quantity": "seconds per sample per covered pixel", "coef": tc.tolist(), "rms_log": trms},
             "noise": {"quantity": "relative variance of one sample (median over lit pixel-channels)",
                       "coef": vc.tolist(), "rms_log": vrms},
             "overhead_s": {"serial": overhead, "cluster_start": start},
             "points": points}
    with open(out, "w") as f:
        json.dump(model, f, indent=1)
    print(f"time model: coef {np.round(tc, 4).tolist()}, RMS residual {trms:.3f} (log units, x{np.exp(trms):.2f})")
    print(f"noise model: coef {np.round(vc, 4).tolist()}, RMS residual {vrms:.3f} (log units, x{np.exp(vrms):.2f})")
    print(f"overhead: {overhead:.2f} s per reference (serial), {start:.2f} s to start a LocalCluster; wrote {out}")


def do_check(specs):
    from harness.runs.references import run_reference_cmd

    rows = []
    for spec in specs:
        load = os.getloadavg()[0]
        name, _, size = spec.partition(":")
        scene = load_scene(name)
        target = scene.tolerances.get("small_reference_rel_se") or scene.tolerances.get("reference_rel_se") or 0.05
        if size == "committed":
            from harness.reference.committed import REF_DIR

            meta = json.loads((REF_DIR / name / "reference.json").read_text())
            scene = scene.with_resolution(meta["width"], meta["height"])
            target = meta["target_rel_se"]
            workers = (meta.get("slots") or 1) if meta.get("executor", "serial") != "serial" else None
            est = cost.estimate_reference(scene, target, workers=workers)
            measured, how = meta["wall_seconds"], f"committed ({meta.get('executor')})"
            spp_measured = meta["spp_total"]
        else:
            w, h = (int(x) for x in size.lower().split("x")) if size else (scene.camera.width, scene.camera.height)
            scene = scene.with_resolution(w, h)
            est = cost.estimate_reference(scene, target, workers=os.cpu_count())
            with tempfile.TemporaryDirectory() as tmp:
                os.environ["SSLPV_CACHE"] = tmp
                t0 = time.perf_counter()
                res = run_reference_cmd(name, size=f"{w}x{h}", target=target, force=True, progress=False)
                measured = time.perf_counter() - t0
            how, spp_measured = "rendered now (LocalCluster)", res["spp_total"]
        rows.append((name, f"{scene.camera.width}x{scene.camera.height}", target, est["predicted_spp_total"],
                     spp_measured, est["predicted_seconds"], measured, how))
        print(f"{name:<20} {rows[-1][1]:>7} target {target:.2%}: predicted {est['predicted_spp_total']:>7} spp "
              f"{est['predicted_seconds']:>8.1f} s | measured {spp_measured:>7} spp {measured:>8.1f} s "
              f"({how}, load average {load:.1f} before) | time error {est['predicted_seconds'] / measured - 1:+.0%}",
              flush=True)
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fit", action="store_true", help="measure the sphere family and write the model")
    ap.add_argument("--spp", type=int, default=8, help="samples per pixel per seed for --fit (8 seeds)")
    ap.add_argument("--out", default=str(cost.MODEL_FILE), help="model file to write with --fit")
    ap.add_argument("--check", nargs="*", metavar="SCENE[:WxH|:committed]", help="compare prediction and measurement")
    args = ap.parse_args()
    if args.fit:
        do_fit(args.spp, args.out)
    if args.check:
        do_check(args.check)


if __name__ == "__main__":
    main()
