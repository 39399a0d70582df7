"""``sslpv-harness study``: run a study file through the sweep and write the study folder.

``DIR`` (``--out``) must be new, empty, or a study's (it holds :data:`STUDY_MARKER`); anything else is
refused with one line before any work. Inside it:

* ``sweep/``: the sweep's folder (``sweep.json``, ``store.sqlite``, ``renders/``), resumable: an
  interrupted study continues where it stopped when the same command is run again, and every
  configuration that the result cache (``cache/results``) holds is served from it, so a second run
  with nothing changed renders nothing; when nothing the outputs depend on changed at all
  (:mod:`harness.study.memo`), the folder is served as it is, in seconds;
* ``results.csv`` and ``results.parquet`` (:mod:`harness.study.table`), ``study.json`` (provenance:
  commit, GL renderer, package versions, the references' hashes and noise, the study file itself),
  ``index.html`` (the map) and ``figures/`` (SVG and PNG). Each is written atomically
  (:mod:`harness.io.atomic`): a killed study leaves the previous complete file or none.

Limits: the tables are built from the sweep's latest finished run only; a study whose sweep is
incomplete (a failed configuration) writes no table and exits 1 with the command that resumes it.
"""

import hashlib
import json
import subprocess
import time
from pathlib import Path

from harness.io.atomic import atomic_dir, atomic_write
from harness.io.outputs import SWEEP_MARKER, check_owned_folder
from harness.study import figures as figs
from harness.study.extensions import default_outside, effects, is_extension
from harness.study.headline import _Images, headline
from harness.study.limits import limits
from harness.study.present import (best_at_budget_table, budget_rows, extension_lines, extension_rows,
                                   headline_rows, judging_methods, limit_lines, target_table)
from harness.study.spec import load_study
from harness.study.target import scene_info, target
from harness.study.table import rows_of, write_csv, write_parquet

#: In every study folder; only such folders (or new, empty ones) are written into.
STUDY_MARKER = ".sslpv-study"
TEMPLATES = Path(__file__).resolve().parent / "templates"


def check_study_folder(path, mark=False):
    """Refuse ``path`` unless it is new, empty, or a study's; ``mark=True`` creates and marks it."""
    path = Path(path)
    # a study killed during its first sweep has its sweep folder and no marker yet: it is ours too
    check_owned_folder(path, STUDY_MARKER, lambda p: (p / "sweep" / SWEEP_MARKER).is_file(), "a study's folder",
                       "give --out a new or empty folder, or the folder of an earlier study to update it")
    if mark:
        path.mkdir(parents=True, exist_ok=True)
        (path / STUDY_MARKER).touch()


def _dirty(repo):
    try:
        out = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=repo, capture_output=True,
                             text=True, timeout=20, check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    return bool(out.stdout.strip()) if out.returncode == 0 else None


def _reference_info(refs):
    """Each scene's reference folder with the sha256 of its images and its recorded noise."""
    out = {}
    for scene, d in sorted(refs.items()):
        d = Path(d)
        meta = json.loads((d / "reference.json").read_text()) if (d / "reference.json").is_file() else {}
        out[scene] = {"dir": str(d), "sha256": {f.name: hashlib.sha256(f.read_bytes()).hexdigest()
                                                for f in sorted(d.glob("*.exr"))},
                      "K": meta.get("K"), "spp_total": meta.get("spp_total"),
                      "median_rel_se_subsurface": meta.get("median_rel_se_subsurface"),
                      "target_rel_se": meta.get("target_rel_se"), "content_hash": meta.get("content_hash")}
    return out


def _render_page(path, **ctx):
    import jinja2

    env = jinja2.Environment(loader=jinja2.FileSystemLoader(TEMPLATES), autoescape=True,
                             undefined=jinja2.StrictUndefined)
    with atomic_write(path) as tmp:
        tmp.write_text(env.get_template("study.html.j2").render(**ctx))


def write_figures(out, rows, head, study):
    """Every figure into ``out/figures`` (replaced as a whole); returns ``{"plots", "images"}`` names."""
    metric = head["metric"]
    names = {"plots": [], "images": []}
    with atomic_dir(Path(out) / "figures") as tmp:
        names["plots"].append("pareto")
        figs.pareto(rows, head["scenes"], head["families"], metric, tmp)
        sslpv_fams = [f for f in head["families"] if any(r["family"] == f and r["method"] == "sslpv" for r in rows)]
        figs.refine_k(rows, head["scenes"], sslpv_fams, metric, study["budget"], tmp)
        names["plots"].append("refine_k")
        if figs.refine_n(rows, head["scenes"], sslpv_fams, metric, study["budget"], tmp):
            names["plots"].append("refine_n")
        for scene in head["scenes"]:
            if figs.images(scene, head["overall"].get(scene, {}), head["families"], tmp):
                names["images"].append(f"images_{scene}")
    return names


def build_outputs(out, study, summary, command, key=None):
    """The tables, figures, provenance and page of a finished sweep (see the module docstring)."""
    from harness.regression.verdict import ALPHA
    from harness.store import Store, git_commit, machine, versions

    out = Path(out)
    with Store(summary["store"]) as st:
        configs = [c for c in st.configs(run_id=summary["run_id"]) if c["status"] == "ok"]
        run = st.run(summary["run_id"])
    rows = rows_of(configs)
    write_csv(rows, out / "results.csv")
    write_parquet(rows, out / "results.parquet")
    images = _Images()
    # the headline, its plots and limits keep the published method and the calibrations; the extensions
    # have their own table, each against its base family
    paper_rows = [r for r in rows if not is_extension(r)]
    head = headline(paper_rows, study["budget"], study["metrics"], study["significance"])
    lims = limits(rows, head["scenes"], head["metric"], study["twins"], study["calibrations"], study["budget"],
                  images)
    ext = effects(rows, study["budget"], study["metrics"], study["significance"], images)
    ext["default_outside"] = default_outside(ext)
    tgt = target(rows, study["calibrations"], study["budget"], scene_info(sorted({r["scene"] for r in rows})))
    names = write_figures(out, paper_rows, head, study)
    reused = sum(r["cached"] for r in rows)
    info = {"title": study["title"], "commit": run.get("git_commit") or git_commit(), "commit_now": git_commit(),
            "dirty": _dirty(Path(__file__).resolve().parents[2]), "gl_renderer": run.get("gl_renderer") or summary.get("gl_renderer"),
            "versions": versions(), "machine": machine(), "command": command, "study_path": study["path"],
            "study_sha256": study["sha256"], "study_text": study["text"], "size": study["size"],
            "budget": study["budget"], "metrics": study["metrics"], "significance": study["significance"],
            "calibrations": study["calibrations"], "twins": study["twins"],
            "references": _reference_info(summary["references"]), "store": summary["store"],
            "run_id": summary["run_id"], "configurations": len(rows), "reused": reused,
            "rendered": len(rows) - reused, "sweep_wall_s": summary.get("wall_s"), "alpha": ALPHA,
            "figures": names, "limits": lims, "extensions": ext, "target": tgt, "inputs_key": key,
            "headline": {s: {f: {"setting": c["row"]["setting"], "status": c["status"], "changes": c["changes"]}
                             for f, c in cells.items()} for s, cells in head["overall"].items()}}
    _render_page(out / "index.html", info=info, head=head, metrics=study["metrics"], budget=study["budget"],
                 significance=study["significance"], methods=judging_methods(study["significance"]), alpha=ALPHA,
                 figures=names,
                 headline_rows=headline_rows(head, study["metrics"]), budget_rows=budget_rows(head, study["metrics"]),
                 limit_lines=[(s, limit_lines(lims[s])) for s in head["scenes"] if s in lims],
                 extension_rows=extension_rows(ext, study["metrics"]), extension_lines=extension_lines(ext),
                 target_table=target_table(tgt), best_at_budget=best_at_budget_table(tgt))
    # last: its inputs_key declares the folder complete (harness.study.memo), so it follows every other output
    with atomic_write(out / "study.json") as tmp:
        tmp.write_text(json.dumps(info, indent=1, default=str))
    return {"rows": rows, "head": head, "limits": lims, "extensions": ext, "target": tgt, "info": info}


def run_study(study_path, out, size=None, scheduler=None, workers=None, progress=True, cache=True, command=None,
              rebuild=False):
    """Run the study (see the module docstring); returns the summary the command line prints.

    A folder that is up to date (:mod:`harness.study.memo`: nothing the outputs depend on changed) is
    served as it is, unless ``rebuild`` (``--docs`` needs the tables in memory: they are rebuilt from the
    store, without the sweep) or ``cache`` is False.
    """
    from harness.runs.sweep import SweepConfig, run_sweep
    from harness.study.memo import inputs_key, up_to_date

    t0 = time.perf_counter()
    study = load_study(study_path, size=size)
    out = Path(out).resolve()
    check_study_folder(out)
    command = command or f"sslpv-harness study {study_path} --out {out}"
    key = inputs_key(study, TEMPLATES, progress) if cache else None
    prev = up_to_date(out, key)
    if prev is not None:
        result = {"out": str(out), "status": "finished", "unchanged": True, "configurations": prev["configurations"],
                  "rendered": 0, "reused": prev["configurations"], "failed": 0, "sweep_wall_s": 0.0}
        if rebuild:
            summary = {"store": prev["store"], "run_id": prev["run_id"], "gl_renderer": prev["gl_renderer"],
                       "references": {s: r["dir"] for s, r in prev["references"].items()}, "wall_s": 0.0}
            result["_built"] = build_outputs(out, study, summary, command, key)
        result.update(_paths(out, prev["configurations"], t0))
        return result
    cfg = SweepConfig(scenes=study["scenes"], params=study["params"], out=str(out / "sweep"), size=study["size"],
                      kind="study")
    summary = run_sweep(cfg, scheduler=scheduler, workers=workers, progress=progress, cache=cache)
    check_study_folder(out, mark=True)
    result = {"out": str(out), "status": summary["status"], "unchanged": False,
              "configurations": summary["configurations"], "rendered": summary["ok"] - summary.get("reused", 0),
              "reused": summary.get("reused", 0), "skipped_done": summary.get("skipped_done", 0),
              "failed": summary["failed"], "sweep_wall_s": summary.get("wall_s")}
    if summary["status"] != "finished":
        result["resume"] = command
        result["error"] = summary.get("error") or summary.get("first_error")
        result["wall_s"] = round(time.perf_counter() - t0, 2)
        return result
    built = build_outputs(out, study, summary, command, key)
    result.update(_paths(out, len(built["rows"]), t0))
    result["_built"] = built
    return result


def _paths(out, rows, t0):
    return {"index": str(out / "index.html"), "csv": str(out / "results.csv"),
            "parquet": str(out / "results.parquet"), "study_json": str(out / "study.json"),
            "figures": str(out / "figures"), "rows": rows, "wall_s": round(time.perf_counter() - t0, 2)}
