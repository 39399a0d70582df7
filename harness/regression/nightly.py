"""``sslpv-harness nightly``: the standard matrix, judged against last night and the baselines.

1. Runs the sweep declared in ``harness/regression/nightly_matrix.toml`` (references from the cache)
   and appends it to the store as a ``nightly`` run with the date and git commit.
2. Judges every headline metric (:data:`harness.regression.verdict.HEADLINE`, subsurface and full)
   against the previous night and against the committed baselines: a regression is a
   change beyond the combined noise floors plus the matrix's tolerance.
3. Writes ``reports/nightly/<date>/``: the sweep report (``report/``), trend plots of each
   headline metric over past nights per scene and configuration, the verdict with every
   regression and improvement; and ``reports/nightly/index.html``, the nights newest first.
4. Exits non-zero (1) on a regression.
"""

import json
from datetime import date as _date
from pathlib import Path
from typing import Annotated, Literal, Optional, Union

from pydantic import Field

from harness.io.atomic import atomic_dir, atomic_write
from harness.io.outputs import check_nightly_folder
from harness.errors import InputError
from harness.runs.params import check_products, config_label, param_lists_model, product_dict
from harness.scene import list_scenes, load_scene
from harness.regression.verdict import DEFAULT_TOLERANCE, HEADLINE, ToleranceSpec, compare_rows, overall
from harness.validation import ImageSize, InputModel, read_toml, validate

TEMPLATES = Path(__file__).resolve().parent / "nightly_templates"


_PRODUCT = param_lists_model("cli")


class NightlyMatrix(InputModel):
    """``harness/regression/nightly_matrix.toml``: what the nightly job renders, and its tolerance."""

    scenes: Union[Literal["all"], Annotated[list[Annotated[str, Field(min_length=1)]], Field(min_length=1)]] = Field(
        "all", description='"all", or a list of suite scene names', examples=[["thin_ring", "jade_veins"]])
    size: Optional[Annotated[list[ImageSize], Field(min_length=2, max_length=2)]] = Field(
        None, description="image size [W, H]; default: each scene's own", examples=[[128, 128]])
    params: _PRODUCT = Field(default_factory=_PRODUCT, description="every combination is rendered")
    also: list[_PRODUCT] = Field([], description="further products, as [[also]] tables")
    tolerance: ToleranceSpec = Field(default_factory=ToleranceSpec)


def load_matrix(path):
    """Read and validate the standard matrix file: types by :class:`NightlyMatrix`, renderer values
    by SSLPVParams, scene names by the suite, each bad one named by its key."""
    from harness.runs.sweep import resolve_scenes

    path = Path(path)
    m = validate(NightlyMatrix, read_toml(path, "a matrix file", "give the nightly matrix file "
                                                "(harness/regression/nightly_matrix.toml)"), path)
    scenes = list_scenes() if m.scenes == "all" else resolve_scenes(m.scenes, where=path, field="scenes")
    products = [product_dict(t) for t in [m.params, *m.also]]
    for i, lists in enumerate(products):
        # a relative calibrated:PATH stays as written (portable labels and baselines); it is found from the
        # current folder or the repository (sslpv_gl.calibrated.resolve_path), and checked now
        check_products(lists, path, "params" if i == 0 else f"also[{i - 1}]")
    params = products if m.also else products[0]
    return {"scenes": scenes, "params": params, "size": m.size, "tolerance": m.tolerance.over(DEFAULT_TOLERANCE),
            "path": str(path)}


def rows_for_run(store, run_id):
    """Headline metric rows of one run, keyed by scene and configuration label."""
    rows = []
    for c in store.configs(run_id=run_id):
        if c["status"] != "ok":
            continue
        label = config_label(c["params"])
        for image, ms in c["metrics"].items():
            for metric, m in ms.items():
                rows.append({"scene": c["scene"], "config": label, "image": image, "metric": metric,
                             "value": m["value"], "noise_floor": m["noise_floor"]})
    return rows


def baseline_rows(scenes, size):
    """Committed baseline rows at the nightly's image size (scenes without any are skipped)."""
    from harness.regression.baselines import read_baseline

    rows = []
    for name in scenes:
        scene = load_scene(name)
        want = list(size) if size else [scene.camera.width, scene.camera.height]
        for e in read_baseline(name):
            if list(e["size"]) != want:
                continue
            for image, ms in e["metrics"].items():
                for metric, m in ms.items():
                    rows.append({"scene": name, "config": e["config"], "image": image, "metric": metric,
                                 "value": m["value"], "noise_floor": m["noise_floor"]})
    return rows


def trend_plots(store, night_run_ids, out_dir):
    """Per scene and headline metric: the subsurface value over nights, one line per configuration.

    One panel per mapping; colour is the grid resolution N, line style the step count;
    the y axis is the metric's badness (distance from its ideal) on a log scale.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from harness.regression.verdict import badness

    series = {}
    for rid, night in night_run_ids:
        for c in store.configs(run_id=rid):
            if c["status"] != "ok":
                continue
            p = c["params"]
            for metric in HEADLINE:
                m = c["metrics"].get("subsurface", {}).get(metric)
                if m is not None:
                    key = (c["scene"], metric)
                    line = (p.get("mapping"), p.get("N"), p.get("steps"))
                    series.setdefault(key, {}).setdefault(line, []).append((night, badness(metric, m["value"])))
    styles = ["-", "--", ":", "-."]
    out = []
    for (scene, metric), lines in sorted(series.items()):
        mappings = sorted({k[0] for k in lines})
        grids = sorted({k[1] for k in lines})
        steps = sorted({k[2] for k in lines})
        fig, axes = plt.subplots(1, len(mappings), figsize=(4.2 * len(mappings) + 1.6, 3.4), squeeze=False,
                                 sharey=True)
        for ax, mapping in zip(axes[0], mappings):
            for (mp, n, k), pts in sorted(lines.items()):
                if mp != mapping:
                    continue
                colour = plt.cm.viridis(grids.index(n) / max(len(grids) - 1, 1))
                ax.plot([p[0] for p in pts], [max(p[1], 1e-6) for p in pts], marker="o", ms=3, lw=1,
                        color=colour, ls=styles[steps.index(k) % len(styles)], label=f"N{n} K{k}")
            ax.set_yscale("log")
            ax.set_title(f"mapping={mapping}", fontsize=9)
            ax.tick_params(axis="x", labelrotation=30, labelsize=7)
        ideal = "|x - 1|" if metric == "energy_ratio" else "value"
        axes[0][0].set_ylabel(f"{metric} ({ideal})")
        axes[0][-1].legend(fontsize=6, ncol=1, loc="upper left", bbox_to_anchor=(1.02, 1.0))
        fig.suptitle(f"{scene}: {metric} of the subsurface image per night (lower is better)", fontsize=10)
        fig.tight_layout()
        name = f"trend_{scene}_{metric}.png"
        fig.savefig(out_dir / name, dpi=90)
        plt.close(fig)
        out.append({"scene": scene, "metric": metric, "file": name})
    return out


def _render(template, **ctx):
    import jinja2

    env = jinja2.Environment(loader=jinja2.FileSystemLoader(TEMPLATES), autoescape=True,
                             undefined=jinja2.StrictUndefined)
    return env.get_template(template).render(**ctx)


def write_index(out_root):
    """``index.html``: every night, newest first, with its verdict."""
    nights = []
    for meta in sorted(Path(out_root).glob("*/night.json"), reverse=True):
        info = json.loads(meta.read_text())
        nights.append(info)
    with atomic_write(Path(out_root) / "index.html") as tmp:
        tmp.write_text(_render("index.html.j2", nights=nights))
    return Path(out_root) / "index.html"


def run_nightly(matrix_path, store_path, out_root, night=None, scheduler=None, workers=None, progress=True):
    from harness.progress import Progress
    from harness.runs.sweep import SweepConfig, run_sweep
    from harness.store import Store

    matrix = load_matrix(matrix_path)
    night = night or _date.today().isoformat()
    try:
        _date.fromisoformat(night)
    except ValueError:
        raise InputError("--date", "date", f"{night!r} is not YYYY-MM-DD", "write e.g. 2026-11-22") from None
    out_root = Path(out_root)
    # ---- (issue 13) every output is checked before anything is written: a user's folder as
    # --out, a folder that cannot be written, another program's or a corrupt store
    check_nightly_folder(out_root)
    Store.check(store_path)
    cfg = SweepConfig(scenes=matrix["scenes"], params=matrix["params"], out=str(out_root / "runs" / night),
                      store=str(store_path), size=matrix["size"], kind="nightly")
    with Progress("nightly", 3, unit="steps", enabled=progress) as steps:
        steps.log(f"{night}: the matrix {matrix['path']}, {len(matrix['scenes'])} scenes, store {store_path}")
        summary = run_sweep(cfg, scheduler=scheduler, workers=workers, progress=progress)
        check_nightly_folder(out_root, mark=True)
        steps.advance(failed=int(summary["status"] != "finished"),
                      detail=f"sweep {summary['status']}: {summary['ok']} ok, {summary['failed']} failed")
        result = _judge_and_report(matrix, store_path, out_root, night, summary, steps)
    return result


def _judge_and_report(matrix, store_path, out_root, night, summary, steps):
    """Verdicts against the previous night and the baselines, the night's report, the index."""
    from harness.report.build import build_report
    from harness.store import Store

    run_id = summary["run_id"]
    tol = matrix["tolerance"]
    with Store(store_path) as st:
        now_rows = rows_for_run(st, run_id)
        nights = [(r["id"], (r.get("config") or {}).get("out", "").rsplit("/", 1)[-1] or r["date"])
                  for r in st.runs(kind="nightly") if r["status"] == "finished"]
        earlier = [(rid, d) for rid, d in nights if d < night]
        prev = earlier[-1] if earlier else None
        prev_rows = rows_for_run(st, prev[0]) if prev else []
        changes = compare_rows(prev_rows, now_rows, tol, "previous-night")
        base = baseline_rows(matrix["scenes"], matrix["size"])
        changes += compare_rows(base, now_rows, tol, "baseline")
        verdict = overall(changes)
        steps.advance(detail=f"verdict: {verdict}")
        night_dir = out_root / night
        with atomic_dir(night_dir) as tmp:
            build_report(store_path, tmp / "report", run_id=run_id, title=f"SSLPV nightly {night}")
            latest = {}
            for rid, d in nights:
                latest[d] = rid  # a re-run of the same night replaces it in the trend
            trends = trend_plots(st, sorted(((rid, d) for d, rid in latest.items()), key=lambda x: x[1]), tmp)
            flagged = sorted((c for c in changes if c.verdict != "unchanged"),
                             key=lambda c: (c.verdict != "regression", -abs(c.delta)))
            info = {"date": night, "verdict": verdict, "run_id": run_id, "git_commit": st.run(run_id)["git_commit"],
                    "previous_night": prev[1] if prev else None, "configurations": summary["configurations"],
                    "failed": summary["failed"], "baseline_comparisons": sum(c.against == "baseline" for c in changes),
                    "previous_comparisons": sum(c.against == "previous-night" for c in changes),
                    "regressions": [c.as_dict() for c in flagged if c.verdict == "regression"],
                    "improvements": [c.as_dict() for c in flagged if c.verdict == "improvement"],
                    "tolerance": tol, "wall_s": summary.get("wall_s")}
            (tmp / "night.json").write_text(json.dumps(info, indent=1))
            (tmp / "index.html").write_text(_render("night.html.j2", info=info, trends=trends, changes=flagged))
    index = write_index(out_root)
    steps.advance(detail=f"report {night_dir}")
    out = {"verdict": verdict, "date": night, "night_dir": str(night_dir), "index": str(index),
           "store": str(store_path), "run_id": run_id, "regressions": len(info["regressions"]),
           "improvements": len(info["improvements"]), "configurations": summary["configurations"],
           "failed": summary["failed"], "not_run": summary.get("not_run", 0), "status": summary["status"],
           "sweep_wall_s": summary.get("wall_s")}
    if summary["status"] != "finished":
        out["resume"], out["error"] = summary.get("resume"), summary.get("error")
    return out


def run_nightly_cli(args):
    """Progress on stderr (``harness.progress``); the result on stdout."""
    return run_nightly(args.matrix, args.store, args.out, night=args.date, scheduler=args.scheduler)
