"""SSLPV against its rivals on the suite: subsurface relMSE and FLIP, with noise floors, per scene.

Runs one sweep (Dask, the committed 64x64 references, so nothing is rendered with Mitsuba) with SSLPV over
N 16/32/64 x K 8/16/32/64 x mapping collision/diffusion and the dipole rivals (``dipole``, ``dirpole``; dense
gather at the default spacing, and the vertex gather at its defaults), then prints, per scene:

* SSLPV at its best configuration under the budget: the lowest subsurface relMSE among SSLPV configurations
  whose frame time is within the frame time of the paper's configuration (N 32, K 32, collision) in this run;
* the dipole and the directional dipole (dense: the model's error alone; vertex: Hao & Varshney's gather);
* whether the published ranking (the directional dipole better than the standard dipole) holds: "yes" when
  dirpole's relMSE is lower by more than both noise floors, "no" when higher by more, "tie" otherwise.

Every scene of the suite is index-matched except layered_dielectric (eta 1.4), so every method sees eta = 1
there. The store and the report (``OUT/store.sqlite``, ``OUT/report``) stay for inspection.

    .venv/bin/python benchmarks/rivals_table.py --out DIR [--scenes a,b] [--workers 2]
"""

import argparse
from pathlib import Path

from harness.report.build import build_report
from harness.runs.sweep import SweepConfig, run_sweep
from harness.scene import list_scenes
from harness.store import Store

PRODUCTS = [{"N": [16, 32, 64], "steps": [8, 16, 32, 64], "mapping": ["collision", "diffusion"]},
            {"method": "dipole", "gather": ["dense"]}, {"method": "dipole", "gather": ["vertex"]},
            {"method": "dirpole", "gather": ["dense"]}, {"method": "dirpole", "gather": ["vertex"]}]


def metric(c, name):
    m = c["metrics"]["subsurface"][name]
    return m["value"], m["noise_floor"]


def fmt(c):
    (r, rf), (f, ff) = metric(c, "relmse"), metric(c, "flip")
    return f"{r:.4f} ({rf:.4f}) / {f:.3f} ({ff:.3f})"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, type=Path)
    ap.add_argument("--scenes", default=None)
    ap.add_argument("--workers", type=int, default=None)
    args = ap.parse_args()
    scenes = args.scenes.split(",") if args.scenes else list_scenes()
    cfg = SweepConfig(scenes=scenes, params=PRODUCTS, out=str(args.out), size=[64, 64])
    summary = run_sweep(cfg, workers=args.workers, progress=False)
    print(f"sweep: {summary['configurations']} configurations, {summary['ok']} ok, {summary['failed']} failed, "
          f"{summary['wall_s']} s")
    build_report(summary["store"], args.out / "report", run_id=summary["run_id"])
    with Store(summary["store"]) as st:
        configs = [c for c in st.configs(run_id=summary["run_id"]) if c["status"] == "ok"]
    print("\n| scene | SSLPV best under budget: config, budget | SSLPV relMSE (floor) / FLIP (floor) | dipole dense | "
          "dirpole dense | dipole vertex | dirpole vertex | dirpole better than dipole (dense)? |")
    print("|---|---|---|---|---|---|---|---|")
    for s in scenes:
        cs = [c for c in configs if c["scene"] == s]
        ss = [c for c in cs if c["method"] == "sslpv"]
        paper = [c for c in ss if c["params"]["N"] == 32 and c["params"]["steps"] == 32
                 and c["params"]["mapping"] == "collision"]
        budget = paper[0]["cost_ms"] if paper else None
        afford = [c for c in ss if budget is not None and c["cost_ms"] <= budget]
        best = min(afford, key=lambda c: metric(c, "relmse")[0]) if afford else None
        rival = {(c["method"], c["params"]["gather"]): c for c in cs if c["method"] != "sslpv"}
        cells = []
        for key in (("dipole", "dense"), ("dirpole", "dense"), ("dipole", "vertex"), ("dirpole", "vertex")):
            cells.append(fmt(rival[key]) if key in rival else "failed")
        verdict = "-"
        if ("dipole", "dense") in rival and ("dirpole", "dense") in rival:
            (a, af), (b, bf) = metric(rival[("dipole", "dense")], "relmse"), metric(rival[("dirpole", "dense")], "relmse")
            verdict = "yes" if b < a - (af + bf) else "no" if b > a + (af + bf) else "tie"
        label = (f"N{best['params']['N']} K{best['params']['steps']} {best['params']['mapping']}, "
                 f"{budget:.0f} ms") if best else "-"
        print(f"| {s} | {label} | {fmt(best) if best else '-'} | " + " | ".join(cells) + f" | {verdict} |")


if __name__ == "__main__":
    main()
