"""``sslpv-harness study --docs``: ``docs/results.md`` and its figures, written from a finished study.

The page holds the headline table, the calibration target (:mod:`harness.study.target`: the best
committed calibration, held out, against the energy and relMSE targets), the "what limits SSLPV" lines,
the extensions' table, the Pareto and refinement plots
(copied from the study's ``figures/`` to ``docs/figures/results_*.svg|png``), and is headed by the
command, the commit and the GL renderer that made it. Nothing in it is typed by hand: run the
command again to bring it up to date.

Limits: it is written from the study just run (normally the default one); a dirty working tree is
said in the header (the commit alone does not then reproduce it).
"""

import shutil
from pathlib import Path

from harness import paths
from harness.io.atomic import atomic_write
from harness.methods.extension_outside import CHOICE, write_choice
from harness.study.present import (best_at_budget_table, extension_lines, extension_rows, headline_rows,
                                   judging_methods, limit_lines, target_table)

DOC = paths.REPO / "docs" / "results.md"
FIGURES = ("pareto", "refine_k", "refine_n")


def _md_cell(c):
    if c is None:
        return "–"
    mark = {"best": "**best**", "worse": "worse"}.get(c["status"], c["mark"])
    return f"{c['vals']} {mark}<br>`{c['setting']}`<br>{c['cost']}"


def write_docs(built, out, doc=DOC, choice=None):
    """Write ``doc`` and copy the plots next to it (``docs/figures/results_<name>.svg|png``), and commit the
    extensions' outside treatment the study chose to ``choice`` (:data:`harness.methods.extension_outside.CHOICE`
    beside the default ``doc``, ``outside.json`` beside another); returns the paths."""
    info, head = built["info"], built["head"]
    choice = (CHOICE if Path(doc) == DOC else Path(doc).parent / "outside.json") if choice is None else choice
    metrics = info["metrics"]
    figdir = Path(doc).parent / "figures"
    figdir.mkdir(parents=True, exist_ok=True)
    written = []
    plots = [f for f in FIGURES if f in info["figures"]["plots"]]
    for name in plots:
        for ext in ("svg", "png"):
            target = figdir / f"results_{name}.{ext}"
            with atomic_write(target) as tmp:
                shutil.copyfile(Path(out) / "figures" / f"{name}.{ext}", tmp)
            written.append(str(target))
    dirty = " (working tree with uncommitted changes)" if info.get("dirty") else ""
    study_path = Path(info["study_path"])
    if study_path.is_absolute() and study_path.is_relative_to(paths.REPO):
        study_path = study_path.relative_to(paths.REPO)        # the same page from any clone
    lines = [
        "# Results: how far SSLPV is from Mitsuba 3 ground truth",
        "",
        f"Written by `{info['command']}` from the study's sweep at commit `{info['commit']}`"
        + (f" (this page by the code at `{info['commit_now']}`)" if info.get("commit_now") not in (None, info["commit"])
           else "") + f"{dirty}, GL renderer `{info['gl_renderer']}`, "
        f"from the study file `{study_path}` (sha256 `{info['study_sha256'][:12]}`): "
        f"{info['configurations']} configurations ({info['rendered']} rendered in that run, {info['reused']} "
        "served from the result cache). Do not edit by hand: run the command again.",
        "",
        "## Headline: the best setting of each family, per scene",
        "",
        f"Each cell: subsurface {' / '.join(metrics)} of the family's best setting within the real-time budgets "
        f"(SSLPV at N = {info['budget']['grid']}, K in {', '.join(map(str, info['budget']['steps']))}; a rival's every "
        f"setting), ranked by {metrics[0]}, then its setting and cost (frame ms on this device; device-independent "
        "work units per frame). Noise floor: each metric between the reference's two independent halves. Marks: "
        "**best** of the row; ≈ within the reference's noise of the best; worse beyond it; ≈+ better beyond noise "
        "in another metric; ± worse in one, better in another: paired differences of "
        f"{', '.join(info['significance'])} against the row's best ({judging_methods(info['significance'])}, tolerance 0, "
        f"α = {info['alpha']}, "
        f"Bonferroni over {head['comparisons']['overall']} comparisons × {len(info['significance'])} metrics).",
        "",
        "| scene | noise floor | " + " | ".join(head["families"]) + " |",
        "|---|---|" + "---|" * len(head["families"]),
    ]
    for r in headline_rows(head, metrics):
        lines.append(f"| {r['scene']} | {r['floor']} | " + " | ".join(_md_cell(c) for c in r["cells"]) + " |")
    if built.get("target") is not None:
        intro, rows, verdict = target_table(built["target"])
        lines += ["", "## The calibration target", ""]
        if intro:
            lines += [intro, "", "| budget | target | needed | measured | met |", "|---|---|---|---|---|"]
            lines += ["| " + " | ".join(r) + " |" for r in rows]
            lines.append("")
        lines.append(verdict)
        intro, rows = best_at_budget_table(built["target"])
        if intro:
            lines += ["", "### The best at one budget alone", "", intro, "",
                      "| budget | target | needed | measured | met |", "|---|---|---|---|---|"]
            lines += ["| " + " | ".join(r) + " |" for r in rows]
    lines += ["", "## What limits SSLPV here", ""]
    for scene in head["scenes"]:
        if scene in built["limits"]:
            lines.append(f"**{scene}**")
            lines.append("")
            lines += [f"* {x}" for x in limit_lines(built["limits"][scene])]
            lines.append("")
    ext = built.get("extensions")
    if ext and ext["families"]:
        lines += ["## The extensions beside the published method", "",
                  "Options the paper does not have (`docs/diffusion_mapping.md`, Secs. 8-11), each family against "
                  "its base (the same mapping without them): per scene, the ratio of the best setting's "
                  f"subsurface {ext['metric']} within the budgets (extension / base) and the paired judgement "
                  f"(better / worse beyond the reference's noise, ≈ within it; Bonferroni over "
                  f"{ext['comparisons']} comparisons). Columns: median ratio over the scenes; scenes better / "
                  "worse / judged.", "",
                  "| family | base | median | better / worse / scenes | " + " | ".join(ext["scenes"]) + " |",
                  "|---|---|---|---|" + "---|" * len(ext["scenes"])]
        for r in extension_rows(ext, metrics):
            lines.append(f"| {r['family']} | {r['base']} | {r['median']} | {r['counts']} | "
                         + " | ".join(r["cells"]) + " |")
        lines += [""] + [f"{x}" for x in extension_lines(ext)] + [""]
        from datetime import datetime, timezone

        committed = write_choice(ext.get("default_outside"), info | {"created": datetime.now(timezone.utc).isoformat()},
                                 choice)
        if committed is not None:
            written.append(committed)
            shown = Path(committed).relative_to(paths.REPO) if Path(committed).is_relative_to(paths.REPO) else committed
            lines += [f"That choice is committed to `{shown}`: a render that turns on an extension and gives no "
                      "`--outside` uses it, or the next treatment of that file it accepts that beat the paper's "
                      "(`harness/methods/extension_outside.py`).", ""]
    lines += ["## Figures", ""]
    for name in plots:
        lines += [f"![{name}](figures/results_{name}.png) ([SVG](figures/results_{name}.svg))", ""]
    lines += ["The per-budget table, the images with their error maps and every row (`results.csv`) are in the "
              "study's folder (`index.html`).", ""]
    with atomic_write(doc) as tmp:
        tmp.write_text("\n".join(lines))
    written.append(str(doc))
    return written
