"""Sweep throughput: per-configuration against grouped (one propagation per step group), in one run.

Runs the same sweep twice on this machine, each into a fresh folder and store:

1. ``group=False``: every configuration is its own worker task (RSM, injection,
   material and a propagation of its own ``K``), the sweep before step groups;
2. ``group=True`` (the default): one task per step group, ONE propagation to the
   largest ``K``, each ``K`` shaded as it passes (``SSLPVRenderer.render_steps``).

It prints both wall times (``run_sweep``'s ``wall_s``: from the start of the sweep,
cluster start-up included, to the last row recorded) and their ratio, and checks
that both stores hold the same configurations with identical metric values.

The issue's default sweep is ``--grid 16,32,64,128 --steps 4,8,16,32,64`` over the
default suite; here at ``--size small`` (64x64; wide_slab 60x36) so that the committed references
(``baselines/refs``) are used and nothing is rendered by Mitsuba.

``--table`` instead measures the grouped sweep's wall time against workers x
``LP_NUM_THREADS`` (llvmpipe's threads per worker process) on the sweep given,
e.g. ``--scenes thin_ring,jade_veins,two_lights --grid 32,64``.

It also prints, per N, the propagation stage time summed over each sweep's tasks and the
steps they ran (``--summarize DIR`` prints that table for an earlier run's ``--out DIR``).

Run: ``.venv/bin/python benchmarks/bench_sweep.py [--grid 16,32,64,128] [--steps 4,8,16,32,64]``
"""

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path


def one(scenes, params, size, out, group, workers, lp_threads):
    from harness.runs.sweep import SweepConfig, run_sweep

    cfg = SweepConfig(scenes=scenes, params=params, out=str(out), size=size)
    t0 = time.perf_counter()
    summary = run_sweep(cfg, workers=workers, progress=False, group=group, lp_threads=lp_threads, cache=False)
    summary["bench_wall_s"] = time.perf_counter() - t0
    if summary["failed"]:
        raise SystemExit(f"{summary['failed']} configurations failed in {out}")
    return summary


def metrics_by_key(store_path):
    from harness.store import Store

    with Store(store_path) as st:
        return {c["config_key"]: c["metrics"] for c in st.configs()}


def propagation_by_grid(store_path):
    """Per N: the propagation stage time summed over the sweep's tasks [s] and the steps they ran.

    A grouped row's ``propagation`` timing is that of the steps up to its own K (cumulative),
    so a group counts once, with its largest K (``shared["group_steps"]``); a single render
    counts with its own K.
    """
    from harness.store import Store

    out = {}
    with Store(store_path) as st:
        for c in st.configs():
            k, shared = c["params"]["steps"], c["shared"]
            if shared and k != max(shared["group_steps"]):
                continue
            row = out.setdefault(c["params"]["N"], {"s": 0.0, "steps": 0})
            row["s"] += c["timings"].get("propagation", 0.0) / 1e3
            row["steps"] += k
    return out


def print_propagation(old_store, new_store):
    """The Markdown table of :func:`propagation_by_grid` for both sweeps, and its rows."""
    a, b = propagation_by_grid(old_store), propagation_by_grid(new_store)
    print("\npropagation stage, summed over tasks (worker seconds; two workers run at once):\n"
          "| N | per-configuration [s] | steps | s/step | grouped [s] | steps | s/step | grouped/per-configuration |\n"
          "|---|---|---|---|---|---|---|---|")
    rows = []
    for n in sorted(set(a) | set(b)):
        x, y = a.get(n, {"s": 0.0, "steps": 0}), b.get(n, {"s": 0.0, "steps": 0})
        per = [r["s"] / r["steps"] if r["steps"] else float("nan") for r in (x, y)]
        ratio = y["s"] / x["s"] if x["s"] else float("nan")
        print(f"| {n} | {x['s']:.1f} | {x['steps']} | {per[0]:.4f} | {y['s']:.1f} | {y['steps']} | {per[1]:.4f} "
              f"| {ratio:.3f} |")
        rows.append({"N": n, "per_config_s": x["s"], "per_config_steps": x["steps"], "grouped_s": y["s"],
                     "grouped_steps": y["steps"]})
    tot = [sum(r[k] for r in rows) for k in ("per_config_s", "grouped_s")]
    print(f"| all | {tot[0]:.1f} | | | {tot[1]:.1f} | | | {tot[1] / tot[0]:.3f} |")
    return rows


def main(argv=None):
    from harness.runs.params import parse_lists
    from harness.runs.sweep import DEFAULT_LP_THREADS, parse_size, resolve_scenes
    from harness.scene import list_scenes

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", help="comma-separated suite scenes (default: all)")
    ap.add_argument("--grid", default="16,32,64,128")
    ap.add_argument("--steps", default="4,8,16,32,64")
    ap.add_argument("--size", default="small")
    ap.add_argument("--workers", type=int, default=None, help="LocalCluster workers (default: cores)")
    ap.add_argument("--lp-threads", default=None, help=f"LP_NUM_THREADS (default: {DEFAULT_LP_THREADS})")
    ap.add_argument("--table", action="store_true", help="grouped sweep over workers x LP_NUM_THREADS instead")
    ap.add_argument("--combos", default="1x1,1x2,2x1,2x2,2xdefault",
                    help="with --table: WORKERSxTHREADS list ('default': llvmpipe's own)")
    ap.add_argument("--out", type=Path, default=None, help="keep the sweeps here (default: a temporary folder)")
    ap.add_argument("--json", type=Path, default=None, help="also write the figures as JSON here")
    ap.add_argument("--summarize", type=Path, default=None,
                    help="run nothing: the propagation table of an earlier run's --out folder")
    args = ap.parse_args(argv)
    if args.summarize:
        stores = [args.summarize / name / "store.sqlite" for name in ("per_config", "grouped")]
        missing = [str(p) for p in stores if not p.is_file()]
        if missing:
            print(f"error: {missing[0]}: file: does not exist; pass the --out folder of a bench_sweep run",
                  file=sys.stderr)
            raise SystemExit(2)
        print_propagation(*stores)
        return

    scenes = resolve_scenes(args.scenes) if args.scenes else list_scenes()
    params = parse_lists({"grid": args.grid, "steps": args.steps})
    size = parse_size(args.size)
    n_cfg = len(scenes) * len(params["N"]) * len(params["steps"])
    base = args.out or Path(tempfile.mkdtemp(prefix="bench_sweep_"))
    print(f"sweep: {len(scenes)} scenes x grid {args.grid} x steps {args.steps} at {args.size} = {n_cfg} "
          f"configurations; folders under {base}", flush=True)
    figures = {"scenes": scenes, "grid": args.grid, "steps": args.steps, "size": args.size}
    if args.table:
        rows = []
        for combo in args.combos.split(","):
            w, lp = combo.split("x")
            s = one(scenes, params, size, base / f"table_{combo}", True, int(w), lp if lp == "default" else int(lp))
            rows.append({"workers": int(w), "lp_threads": lp, "wall_s": s["wall_s"]})
            print(f"  workers {w} x LP_NUM_THREADS {lp:>7}: {s['wall_s']:7.1f} s", flush=True)
        best = min(rows, key=lambda r: r["wall_s"])
        print("\n| workers | LP_NUM_THREADS | wall [s] |\n|---|---|---|")
        for r in rows:
            print(f"| {r['workers']} | {r['lp_threads']} | {r['wall_s']:.1f}{' (best)' if r is best else ''} |")
        figures["table"] = rows
    else:
        lp = args.lp_threads if args.lp_threads in (None, "default") else int(args.lp_threads)
        old = one(scenes, params, size, base / "per_config", False, args.workers, lp)
        print(f"  per-configuration: {old['wall_s']:.1f} s ({old['groups']} tasks)", flush=True)
        new = one(scenes, params, size, base / "grouped", True, args.workers, lp)
        print(f"  grouped:           {new['wall_s']:.1f} s ({new['groups']} tasks)", flush=True)
        a, b = metrics_by_key(old["store"]), metrics_by_key(new["store"])
        same = a == b
        ratio = new["wall_s"] / old["wall_s"]
        print(f"\nper-configuration {old['wall_s']:.1f} s, grouped {new['wall_s']:.1f} s, "
              f"ratio grouped/per-configuration = {ratio:.3f} (target <= 0.5); "
              f"{len(a)} configurations, metrics identical: {same}")
        figures.update(old_wall_s=old["wall_s"], new_wall_s=new["wall_s"], ratio=ratio, configurations=len(a),
                       metrics_identical=same, workers=args.workers, lp_threads=args.lp_threads,
                       propagation=print_propagation(old["store"], new["store"]))
        if not same:
            raise SystemExit("the grouped sweep's metrics differ from the per-configuration sweep's")
    if args.json:
        args.json.write_text(json.dumps(figures, indent=2))


if __name__ == "__main__":
    from page import run

    raise SystemExit(run(main, "bench_sweep", 'The default sweep per configuration and in step groups'))
