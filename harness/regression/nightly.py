"""``sslpv-harness nightly``: the standard matrix, judged against last night and the baselines.

1. Runs the sweep declared in ``harness/regression/nightly_matrix.toml`` (references from the cache)
   and appends it to the store as a ``nightly`` run with the date and git commit.
2. Judges every configuration against the previous night's render of it (subsurface and
   full image; the full image only where it differs from the subsurface one) and, at the
   committed size, against the committed image of the accuracy baselines, in the two
   steps of :mod:`harness.regression.verdict`: images equal within the floating-point
   tolerance are *unchanged*; a changed pair is judged per headline metric as a paired
   difference against tonight's reference (Delta, its standard error, z, the threshold
   ``tol + t SE``, Bonferroni over every comparison of the night). Pairs that cannot be
   made (last night's renders deleted, the scene changed, another GL renderer) are named
   in one line each.
3. Writes ``reports/nightly/<date>/``: the sweep report (``report/``), trend plots of each
   headline metric over past nights per scene and configuration, the verdict with every
   regression and improvement; and ``reports/nightly/index.html``, the nights newest first.
4. Exits non-zero (1) on a regression; improvements are reported and exit 0.

The previous night's render folders (``reports/nightly/runs/<date>/renders``) must be kept
until the next night, beside ``reports/nightly.sqlite``.

A ``[[also]]`` table with ``method = "dipole"`` (or ``"dirpole"``) adds a rival's configurations
(``harness.methods``; its parameters, e.g. ``gather = ["dense", "vertex"]``); they are judged against the
previous night like SSLPV's (the committed baselines are SSLPV's). ``nightly --method M,...`` runs only the
matrix's products of those methods.
"""

import json
import time
from collections import Counter
from datetime import date as _date
from pathlib import Path
from typing import Annotated, Literal, Optional, Union

from pydantic import Field

import numpy as np

from harness.io.atomic import atomic_dir, atomic_write
from harness.io.outputs import check_nightly_folder
from harness.errors import InputError
from harness.methods import config_label as method_label, get_method
from harness.runs.params import any_product_model, check_methods, check_products, config_label, \
    param_lists_model, product_dict
from harness.scene import list_scenes, load_scene
from harness.regression.trends import trend_plots
from harness.regression.verdict import DEFAULT_TOLERANCE, HEADLINE, ToleranceSpec, image_change, judge_images, overall
from harness.validation import InputModel, SweepSize, read_toml, validate

TEMPLATES = Path(__file__).resolve().parent / "nightly_templates"


_PRODUCT = param_lists_model("cli")


class NightlyMatrix(InputModel):
    """``harness/regression/nightly_matrix.toml``: what the nightly job renders, and its tolerance."""

    scenes: Union[Literal["all"], Annotated[list[Annotated[str, Field(min_length=1)]], Field(min_length=1)]] = Field(
        "all", description='"all", or a list of suite scene names', examples=[["thin_ring", "jade_veins"]])
    size: Optional[SweepSize] = Field(
        None, description='image size [W, H], or "small" (each scene at its committed small size, its own aspect); '
        "default: each scene's own", examples=[[128, 128], "small"])
    params: _PRODUCT = Field(default_factory=_PRODUCT, description="every combination is rendered")
    also: list[any_product_model("cli")] = Field([], description="further products, as [[also]] tables; "
                                                     'method = "dipole" (or "dirpole") makes a rival\'s')
    tolerance: ToleranceSpec = Field(default_factory=ToleranceSpec)


def load_matrix(path):
    """Read and validate the standard matrix file: types by :class:`NightlyMatrix`, renderer values
    by SSLPVParams, scene names by the suite, each bad one named by its key."""
    from harness.runs.sweep import resolve_scenes

    path = Path(path)
    data = read_toml(path, "a matrix file", "give the nightly matrix file (harness/regression/nightly_matrix.toml)")
    if isinstance(data, dict):
        check_methods(data.get("params", {}), path, "params")
        check_methods(data.get("also", []), path, "also")
    m = validate(NightlyMatrix, data, path)
    scenes = list_scenes() if m.scenes == "all" else resolve_scenes(m.scenes, where=path, field="scenes")
    products = []
    for i, table in enumerate([m.params, *m.also]):
        where = "params" if i == 0 else f"also[{i - 1}]"
        for lists in _split_methods([product_dict(table)], path, where):
            # a relative calibrated:PATH stays as written (portable labels and baselines); it is found from the
            # current folder or the repository (sslpv_gl.calibrated.resolve_path), and checked now
            check_products(lists, path, where)
            products.append(lists)
    params = products if len(products) > 1 else products[0]
    return {"scenes": scenes, "params": params, "size": m.size, "tolerance": m.tolerance.over(DEFAULT_TOLERANCE),
            "path": str(path)}


def _split_methods(products, path, where):
    """Another method's product split as that method does it (the dipole rivals: one per gather, with the
    parameters that belong to each); SSLPV's products as they are."""
    out = []
    for lists in products:
        name = lists.get("method", "sslpv")
        if name == "sslpv":
            out.append(lists)
            continue
        try:
            parts = get_method(name).split_products({k: v for k, v in lists.items() if k != "method"})
        except InputError as exc:
            raise InputError(path, f"{where}.{exc.field}", exc.problem, exc.fix) from None
        out += [{"method": name, **p} for p in parts]
    return out


def select_methods(params, methods):
    """Only the products of ``methods`` (``nightly --method``); SSLPV's products name no method."""
    items = params if isinstance(params, list) else [params]
    keep = [p for p in items if p.get("method", "sslpv") in methods]
    if not keep:
        raise InputError("--method", "method", f"the matrix has no products of {', '.join(methods)}",
                         "add an [[also]] table with method = ... to the matrix, or change --method")
    return keep


def _label(c):
    """A stored configuration's label, whatever its method (``harness.methods``)."""
    return method_label(c.get("method", "sslpv"), c["params"])


def _render_images(render_dir):
    """``{"subsurface", "full", "mask"}`` of an SSLPV render folder, or None when it is gone."""
    from harness.io.images import read_exr

    d = Path(render_dir or "")
    if not render_dir or not (d / "subsurface.exr").is_file() or not (d / "full.exr").is_file():
        return None
    sub = read_exr(d / "subsurface.exr")
    return {"subsurface": sub["rgb"], "full": read_exr(d / "full.exr")["rgb"], "mask": sub["mask"] > 0.5}


def _baseline_images(scenes, size):
    """``{(scene, config label): (entry, loader)}`` of the committed images at the nightly's size."""
    from harness.reference.committed import sized_scene
    from harness.regression.baselines import committed_image, read_baseline

    out = {}
    for name in scenes:
        sized = sized_scene(load_scene(name), size)          # "small": each scene's committed size
        want = [sized.camera.width, sized.camera.height]
        # scene hashes are compared per pair (one line each), so one stale entry does not stop the night
        for e in read_baseline(name, check_scene=False):
            if list(e["size"]) == want and e.get("image"):
                out[(name, config_label(e["params"]))] = (e, lambda n=name, e=e: committed_image(n, e))
    return out


def judge_night(store, run_id, prev_run_id, references, scenes, size, tolerance, draws=None):
    """Tonight's configurations against the previous night's renders and the committed images.

    Returns ``{"changes": [Change], "images": [pair rows], "notes": [one line each],
    "family": m}``; a pair row is ``{scene, config, image, against, changed, line}``.
    """
    from harness.runs.sweep import load_reference

    now = [c for c in store.configs(run_id=run_id) if c["status"] == "ok"]
    gl_now = store.run(run_id).get("gl_renderer")
    notes, pairs = [], []
    prev_by_key, prev_by_label = {}, {}
    if prev_run_id is not None:
        gl_prev = store.run(prev_run_id).get("gl_renderer")
        if gl_prev and gl_now and gl_prev != gl_now:
            notes.append(f"the previous night rendered with {gl_prev!r}, tonight with {gl_now!r}")
        for c in store.configs(run_id=prev_run_id):
            if c["status"] == "ok":
                prev_by_key[c["config_key"]] = c
                prev_by_label[(c["scene"], _label(c))] = c
    base = _baseline_images(scenes, size)
    # Plan every pair first: the Bonferroni family is every comparison the night can judge.
    for c in now:
        label = _label(c)
        p = prev_by_key.get(c["config_key"])
        if p is None and (c["scene"], label) in prev_by_label:
            old_hash = prev_by_label[(c["scene"], label)]["scene_hash"]
            notes.append(f"{c['scene']} {label}: the scene changed since the previous night (hash "
                         f"{old_hash[:12]} -> {c['scene_hash'][:12]}); not compared")
        if p is not None:
            pairs.append(("previous-night", c, p))
        if (c["scene"], label) in base:
            entry, _ = base[(c["scene"], label)]
            if entry["scene_hash"] != c["scene_hash"]:
                notes.append(f"{c['scene']} {label}: the baseline was made for scene hash {entry['scene_hash'][:12]}, "
                             f"tonight's scene hashes to {c['scene_hash'][:12]}; not compared")
                continue
            if entry.get("gl_renderer") and gl_now and entry["gl_renderer"] != gl_now:
                notes.append(f"{c['scene']} {label}: the committed image was rendered by {entry['gl_renderer']!r}, "
                             f"tonight by {gl_now!r}")
            pairs.append(("baseline", c, base[(c["scene"], label)]))
    loaded, refs, rows, changes, todo = {}, {}, [], [], []
    for against, c, old in pairs:
        label = _label(c)
        new = loaded.get(c["render_dir"]) or _render_images(c["render_dir"])
        loaded[c["render_dir"]] = new
        if new is None:
            notes.append(f"{c['scene']} {label}: tonight's render folder {c['render_dir']} is gone; not compared")
            continue
        if against == "previous-night":
            old_imgs = _render_images(old["render_dir"])
            if old_imgs is None:
                notes.append(f"{c['scene']} {label}: the previous night's render folder {old['render_dir']} is "
                             "gone; not compared (keep reports/nightly/runs/<date> until the next night)")
                continue
            parts = ["subsurface"]
            if not (np.array_equal(new["full"], new["subsurface"]) and
                    np.array_equal(old_imgs["full"], old_imgs["subsurface"])):
                parts.append("full")        # with a reflection; else the same image twice
        else:
            try:
                rgb, mask = old[1]()
            except InputError as exc:              # a missing or broken committed image: one line
                notes.append(f"{c['scene']} {label}: {exc}; not compared")
                continue
            old_imgs, parts = {"subsurface": rgb, "mask": mask}, ["subsurface"]
        for part in parts:
            todo.append((against, c, label, part, new, old_imgs))
    family = max(len(todo) * len(HEADLINE), 1)
    for against, c, label, part, new, old_imgs in todo:
        ic = image_change(new[part], old_imgs[part], new["mask"], old_imgs["mask"])
        rows.append({"scene": c["scene"], "config": label, "image": part, "against": against,
                     "changed": ic.changed, "line": ic.line()})
        if not ic.changed:
            continue
        if c["scene"] not in refs:
            rdir = references[c["scene"]]
            refs[c["scene"]] = load_reference(rdir, new["subsurface"].shape[:2])
        ref = refs[c["scene"]]
        se = ref["se"] if part == "subsurface" else ref["se_full"]
        if se is None:
            raise InputError(Path(ref["dir"]) / f"{part}.exr", "se", "has no per-pixel standard error "
                             "(channels R_se, G_se, B_se), so a change cannot be judged against its noise",
                             "delete the cached reference so that it is rendered again")
        changes += judge_images(c["scene"], label, part, new[part], old_imgs[part], ref[part], se, ref["mask"],
                                tolerance, family, against, k=ref.get("K"), draws=draws)
    return {"changes": changes, "images": rows, "notes": notes, "family": family}


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


def run_nightly(matrix_path, store_path, out_root, night=None, scheduler=None, workers=None, progress=True,
                methods=None, size=None, cache=True):
    """Run the night (see the module docstring); ``size`` ("small", "own" or ``[W, H]``) overrides the matrix's,
    ``cache`` is :func:`harness.runs.sweep.run_sweep`'s."""
    from harness.progress import Progress
    from harness.runs.sweep import SweepConfig, run_sweep
    from harness.store import Store

    matrix = load_matrix(matrix_path)
    if methods is not None:                       # nightly --method: the matrix's products of these methods
        from harness.methods import parse_methods

        matrix["params"] = select_methods(matrix["params"], parse_methods(methods))
    night = night or _date.today().isoformat()
    try:
        _date.fromisoformat(night)
    except ValueError:
        raise InputError("--date", "date", f"{night!r} is not YYYY-MM-DD", "write e.g. 2026-11-22") from None
    out_root = Path(out_root)
    # ---- every output is checked before anything is written: a user's folder as
    # --out, a folder that cannot be written, another program's or a corrupt store
    check_nightly_folder(out_root)
    Store.check(store_path)
    if size is not None:                          # nightly --size: small, own (None: each scene's own) or [W, H]
        matrix["size"] = None if size == "own" else size
    cfg = SweepConfig(scenes=matrix["scenes"], params=matrix["params"], out=str(out_root / "runs" / night),
                      store=str(store_path), size=matrix["size"], kind="nightly")
    with Progress("nightly", 3, unit="steps", enabled=progress) as steps:
        steps.log(f"{night}: the matrix {matrix['path']}, {len(matrix['scenes'])} scenes, store {store_path}")
        summary = run_sweep(cfg, scheduler=scheduler, workers=workers, progress=progress, cache=cache)
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
    from harness.regression.verdict import ALPHA, IMAGE_ATOL, IMAGE_RTOL
    t_start = time.perf_counter()
    with Store(store_path) as st:
        nights = [(r["id"], (r.get("config") or {}).get("out", "").rsplit("/", 1)[-1] or r["date"])
                  for r in st.runs(kind="nightly") if r["status"] == "finished"]
        earlier = [(rid, d) for rid, d in nights if d < night]
        prev = earlier[-1] if earlier else None
        judged = judge_night(st, run_id, prev[0] if prev else None, summary["references"], matrix["scenes"],
                             matrix["size"], tol)
        changes = judged["changes"]
        t_judged = time.perf_counter()
        steps.log(f"verdicts: {len(judged['images'])} image comparisons in {t_judged - t_start:.1f} s")
        tonight = [c for c in st.configs(run_id=run_id) if c["status"] == "ok"]
        reused = {(c["scene"], _label(c)) for c in tonight if c.get("cached_from")}
        fresh = [c for c in tonight if not c.get("cached_from")]
        rendered = sorted(f"{c['scene']} {_label(c)}" for c in fresh)
        rendered_methods = dict(Counter(c.get("method", "sslpv") for c in fresh))
        changed_pairs = [r for r in judged["images"] if r["changed"]]
        verdict = overall(changes, image_changed=bool(changed_pairs))
        steps.advance(detail=f"verdict: {verdict}")
        night_dir = out_root / night
        with atomic_dir(night_dir) as tmp:
            t0 = time.perf_counter()
            build_report(store_path, tmp / "report", run_id=run_id, title=f"SSLPV nightly {night}")
            t1 = time.perf_counter()
            latest = {}
            for rid, d in nights:
                latest[d] = rid  # a re-run of the same night replaces it in the trend
            trends = trend_plots(st, sorted(((rid, d) for d, rid in latest.items()), key=lambda x: x[1]), tmp)
            steps.log(f"the sweep report in {t1 - t0:.1f} s; {len(trends)} trend figures in "
                      f"{time.perf_counter() - t1:.1f} s")
            order = {"regression": 0, "improvement": 1, "changed-within-noise": 2}
            shown = sorted(changes, key=lambda c: (order[c.verdict], -abs(c.z) if np.isfinite(c.z) else -1e308))
            info = {"date": night, "verdict": verdict, "run_id": run_id, "git_commit": st.run(run_id)["git_commit"],
                    "gl_renderer": st.run(run_id).get("gl_renderer"),
                    "previous_night": prev[1] if prev else None, "configurations": summary["configurations"],
                    "failed": summary["failed"],
                    "baseline_comparisons": sum(r["against"] == "baseline" for r in judged["images"]),
                    "previous_comparisons": sum(r["against"] == "previous-night" for r in judged["images"]),
                    "changed_images": changed_pairs, "family": judged["family"], "notes": judged["notes"],
                    "regressions": [c.as_dict() for c in shown if c.verdict == "regression"],
                    "improvements": [c.as_dict() for c in shown if c.verdict == "improvement"],
                    "within_noise": [c.as_dict() for c in shown if c.verdict == "changed-within-noise"],
                    "tolerance": tol, "alpha": ALPHA, "image_tolerance": {"rtol": IMAGE_RTOL, "atol": IMAGE_ATOL},
                    "wall_s": summary.get("wall_s"), "reused": len(reused), "rendered": rendered,
                    "rendered_methods": rendered_methods,
                    "reused_changes": sorted({f"{c.scene} {c.config}" for c in shown if (c.scene, c.config) in reused})}
            (tmp / "night.json").write_text(json.dumps(info, indent=1))
            (tmp / "index.html").write_text(_render("night.html.j2", info=info, trends=trends, changes=shown))
    index = write_index(out_root)
    steps.advance(detail=f"report {night_dir}")
    out = {"verdict": verdict, "date": night, "night_dir": str(night_dir), "index": str(index),
           "store": str(store_path), "run_id": run_id, "regressions": len(info["regressions"]),
           "improvements": len(info["improvements"]), "changed_images": len(info["changed_images"]),
           "notes": info["notes"], "configurations": summary["configurations"],
           "failed": summary["failed"], "not_run": summary.get("not_run", 0), "status": summary["status"],
           "sweep_wall_s": summary.get("wall_s"), "reused": len(reused), "rendered": len(rendered)}
    if summary["status"] != "finished":
        out["resume"], out["error"] = summary.get("resume"), summary.get("error")
    return out


def run_nightly_cli(args):
    """Progress on stderr (``harness.progress``); the result on stdout."""
    from harness.runs.sweep import parse_size

    size = getattr(args, "size", None)
    size = "own" if size is not None and size.strip().lower() == "own" else parse_size(size)
    return run_nightly(args.matrix, args.store, args.out, night=args.date, scheduler=args.scheduler,
                       workers=args.workers, progress=args.progress, methods=getattr(args, "method", None),
                       size=size, cache=not getattr(args, "no_cache", False))
