"""Committed accuracy baselines and the small references they were measured against.

Layout (all committed)::

    baselines/<scene>.json            metric values with noise floors, per (size, configuration)
    baselines/images/<scene>/<config>-<W>x<H>.exr
                                      the SSLPV subsurface image of each entry (float32, with
                                      the renderer's coverage as the ``mask`` layer): the old
                                      image of every verdict (:mod:`harness.regression.verdict`)
    baselines/refs/<scene>/           a small Mitsuba reference (64x64, or the scene's aspect at a longer
                                      side of 64: harness.reference.committed.small_size): subsurface.exr, full.exr,
                                      half_a.exr, half_b.exr, mask.exr, reference.json
    baselines/accuracy_matrix.toml    which configurations the pytest accuracy tests check

A baseline entry is ``{"size": [W, H], "scene_hash": ..., "config": label, "params": {...},
"metrics": {image: {metric: {"value", "noise_floor"}}}, "image": "images/...exr",
"gl_renderer": GL_RENDERER string of the render, "git_commit", "updated"}``.

Commands (``sslpv-harness baselines ...``):

* ``update --store S [--scenes A,B]``: replace the entries of the configurations found in the
  store's latest run (for those scenes, or all) and their committed images (copied from the
  run's render folders), print a before/after table, change nothing else.
* ``show [--store S] [--scenes A,B]``: print the entries as a table; with ``--store``, the
  before/after table that ``update`` would write, writing nothing.
* ``regenerate-references [--scenes A,B]``: render the small reference again with new seeds,
  check it against the committed one with a per-pixel two-sided z-test that uses both noise
  estimates, Bonferroni-corrected for the number of pixels (as Mitsuba's render tests do),
  and refuse it if they disagree.
"""

import json
import shutil
from datetime import datetime, timezone
from pathlib import Path
from typing import Annotated

import numpy as np
from pydantic import Field, model_validator

from harness.io.atomic import atomic_dir, atomic_write
from harness import paths
from harness.errors import InputError
from harness.reference import committed
from harness.regression.verdict import ToleranceSpec
from harness.runs.params import param_lists_model
from harness.scene import list_scenes, load_scene, scene_path
from harness.validation import FieldProblem, InputModel, read_toml, validate

REPO = paths.REPO
BASELINE_DIR = paths.BASELINE_DIR
REF_DIR = committed.REF_DIR
MATRIX_FILE = BASELINE_DIR / "accuracy_matrix.toml"
IMAGE_DIR_NAME = "images"
#: The committed size of a square scene; a non-square one keeps its aspect (:func:`committed.small_size`).
SMALL_SIZE = (64, 64)
#: Family-wise false-rejection probability of the reference check (per image).
SIGNIFICANCE = 0.01


# --------------------------------------------------------------------------- files

def baseline_path(scene_name):
    return BASELINE_DIR / f"{scene_name}.json"


class AccuracyMatrix(InputModel):
    """``baselines/accuracy_matrix.toml``: the scenes and configurations of ``pytest -m accuracy``."""

    scenes: Annotated[list[Annotated[str, Field(min_length=1)]], Field(min_length=1)] = Field(
        description="suite scenes", examples=[["sphere_homogeneous", "jade_veins"]])
    params: param_lists_model("cli") = Field(description="every combination is a case")
    also: list[param_lists_model("cli")] = Field([], description="further products, as [[also]] tables")
    tolerance: dict[str, ToleranceSpec] = Field(
        {}, description="[tolerance.default] and [tolerance.<scene>] (a scene's keys override the default's)")

    @model_validator(mode="after")
    def _tolerance_names_a_scene(self):
        for key in self.tolerance:
            if key != "default" and key not in self.scenes:
                raise FieldProblem(("tolerance", key), "names no scene of the matrix",
                                   f"use [tolerance.default] or one of: {', '.join(self.scenes)}")
        return self


def load_matrix(path=MATRIX_FILE):
    """The accuracy-test matrix, validated: ``{"scenes", "params" (command-line names -> lists),
    "tolerance" ({"default" or scene: {"rel", "abs"}})}``."""
    from harness.runs.params import check_products, product_dict
    from harness.runs.sweep import resolve_scenes

    path = Path(path)
    m = validate(AccuracyMatrix, read_toml(path, "a matrix file", "restore baselines/accuracy_matrix.toml"), path)
    resolve_scenes(m.scenes, where=path, field="scenes")
    for i, table in enumerate([m.params, *m.also]):
        check_products(product_dict(table), path, "params" if i == 0 else f"also[{i - 1}]")
    return {"scenes": list(m.scenes), "params": m.params.model_dump(exclude_none=True),
            "also": [t.model_dump(exclude_none=True) for t in m.also],
            "tolerance": {k: t.model_dump(exclude_none=True) for k, t in m.tolerance.items()}}


def read_baseline(scene_name, check_scene=True):
    """Entries of one scene's baseline file, validated against the scene as it is now."""
    path = baseline_path(scene_name)
    if not path.is_file():
        return []
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise InputError(path, "json", f"is not valid JSON ({exc})", "restore it from git") from exc
    if data.get("scene") != scene_name:
        raise InputError(path, "scene", f"names {data.get('scene')!r}, not {scene_name!r}", "rename or fix the file")
    if check_scene:
        if not scene_path(scene_name).is_file():
            raise InputError(path, "scene", f"scene {scene_name!r} no longer exists in reference_scenes/",
                             "delete this baseline file or restore the scene")
        scene = load_scene(scene_name)
        for e in data.get("entries", []):
            expected = scene.with_resolution(*e["size"]).content_hash
            if e["scene_hash"] != expected:
                raise InputError(path, f"entries[{e['config']} at {e['size'][0]}x{e['size'][1]}].scene_hash",
                                 f"baseline was made for scene hash {e['scene_hash'][:12]} but the scene now "
                                 f"hashes to {expected[:12]}",
                                 f"if the scene change is intended, run `sslpv-harness baselines "
                                 f"regenerate-references --scenes {scene_name}` and then `baselines update`")
    return data.get("entries", [])


def all_baselines():
    """Every baseline file checked: a file whose scene is gone is an error, not silently skipped."""
    out = {}
    for path in sorted(BASELINE_DIR.glob("*.json")):
        name = path.stem
        out[name] = read_baseline(name)
    return out


def find_entry(entries, size, params):
    """The entry for this size and configuration; parameters added to the renderer after the
    baseline was written take their defaults, so old baselines stay valid."""
    from sslpv_gl.params import SSLPVParams

    known = {f for f in SSLPVParams().as_dict()}
    for e in entries:
        stored = SSLPVParams(**{k: v for k, v in e["params"].items() if k in known}).as_dict()
        if list(e["size"]) == list(size) and stored == dict(params):
            return e
    return None


def committed_reference(scene):
    """The committed small reference for ``scene`` in :data:`REF_DIR` (see :mod:`harness.reference.committed`)."""
    return committed.committed_reference(scene, REF_DIR)


def image_name(scene_name, label, size):
    """Path of an entry's committed image, relative to :data:`BASELINE_DIR`."""
    from harness.runs.params import file_label

    return f"{IMAGE_DIR_NAME}/{scene_name}/{file_label(label)}-{int(size[0])}x{int(size[1])}.exr"


def update_command(scene_name=None):
    """The one-line command that accepts new values and images (for messages)."""
    return ("run a `sweep --size small` of baselines/accuracy_matrix.toml and `sslpv-harness baselines update "
            f"--store STORE{' --scenes ' + scene_name if scene_name else ''}`")


def committed_image(scene_name, entry):
    """The committed SSLPV image of a baseline entry: ``(rgb (H, W, 3), coverage mask (H, W) bool)``.

    One-line :class:`InputError` for an entry without an image, a missing file, an image
    of another size than the entry's, or one without the ``mask`` layer.
    """
    from harness.io.images import read_exr

    size = entry["size"]
    where = f"entries[{entry['config']} at {size[0]}x{size[1]}]"
    if not entry.get("image"):
        raise InputError(baseline_path(scene_name), f"{where}.image", "has no committed SSLPV image",
                         update_command(scene_name))
    path = BASELINE_DIR / entry["image"]
    if not path.is_file():
        raise InputError(path, "file", f"the committed SSLPV image of {scene_name} {entry['config']} is missing",
                         update_command(scene_name))
    layers = read_exr(path)
    h, w = layers["rgb"].shape[:2]
    if [w, h] != list(size):
        raise InputError(path, "size", f"is {w}x{h}, the baseline entry is {size[0]}x{size[1]}",
                         update_command(scene_name))
    if "mask" not in layers:
        raise InputError(path, "mask", "has no coverage layer 'mask'", update_command(scene_name))
    return layers["rgb"], layers["mask"] > 0.5


# --------------------------------------------------------------------------- update

def _rows_from_store(store_path, scene=None):
    """The successful SSLPV configurations of the store's latest run (of the scenes in ``scene``, a list, when given)."""
    from harness.store import Store

    store_path = Path(store_path) if store_path else None
    if store_path is None or not store_path.is_file():
        raise InputError("--store", "store", f"no results store at {store_path}" if store_path else
                         "no results store given",
                         "pass --store with the store.sqlite of a sweep, a nightly run or a failed accuracy test")
    with Store(store_path) as st:
        runs = [r for r in st.runs() if r.get("n_configs")]
        if not runs:
            raise InputError(store_path, "runs", "the store holds no configurations", "run a sweep first")
        configs = [c for c in st.configs(run_id=runs[-1]["id"]) if scene is None or c["scene"] in scene]
    # the baselines are SSLPV's (another method's configurations, harness.methods, have none)
    return [c for c in configs if c["status"] == "ok" and c.get("method", "sslpv") == "sslpv"], runs[-1]


def _size_of(config):
    meta = Path(config["reference_dir"] or "") / "reference.json"
    if meta.is_file():
        info = json.loads(meta.read_text())
        return [int(info["width"]), int(info["height"])]
    raise InputError(meta, "reference", "the configuration's reference is gone, so its image size is unknown",
                     "re-run the sweep")


def update(store_path, scene=None, yes=True, commit=None):
    """Replace baseline entries with the values of the store's latest run; returns the before/after rows."""
    from harness.runs.params import config_label
    from harness.store import git_commit

    wanted = [scene] if isinstance(scene, str) else scene
    if wanted is not None:
        from harness.runs.sweep import resolve_scenes

        resolve_scenes(list(wanted), where="--scenes")
    configs, run = _rows_from_store(store_path, wanted)
    gl = run.get("gl_renderer") or "unknown"
    if not configs:
        of = f" of {', '.join(wanted)}" if wanted else ""
        raise InputError(store_path, "configurations", f"no successful configuration{of} in the latest run",
                         "run the sweep for that scene first")
    changed, table, images = {}, [], {}
    now = datetime.now(timezone.utc).isoformat(timespec="seconds")
    for c in configs:
        name = c["scene"]
        if name not in changed:
            changed[name] = read_baseline(name, check_scene=False)
        size = _size_of(c)
        current = load_scene(name).with_resolution(*size).content_hash
        if c["scene_hash"] != current:
            raise InputError(store_path, f"{name}.scene_hash", "the store's values were measured on an older "
                             "version of the scene", "re-run the sweep on the current scene")
        label = config_label(c["params"])
        src = Path(c["render_dir"] or "") / "subsurface.exr"
        if not c["render_dir"] or not src.is_file():
            raise InputError(store_path, f"{name} {label}.render_dir", f"the SSLPV image {src} is gone",
                             "re-run the sweep (or the accuracy test) that made this store")
        rel = image_name(name, label, size)
        images[rel] = src
        new = {"size": size, "scene_hash": c["scene_hash"], "config": label, "params": c["params"],
               "metrics": {img: {m: {"value": v["value"], "noise_floor": v["noise_floor"]} for m, v in ms.items()}
                           for img, ms in c["metrics"].items()},
               "image": rel, "gl_renderer": gl, "git_commit": commit or git_commit(), "updated": now}
        entries = changed[name]
        old = find_entry(entries, size, c["params"])
        for metric in ("relmse", "si_relmse", "energy_ratio", "flip"):
            before = old["metrics"]["subsurface"][metric]["value"] if old else None
            table.append({"scene": name, "size": f"{size[0]}x{size[1]}", "config": label, "metric": metric,
                          "before": before, "after": new["metrics"]["subsurface"][metric]["value"],
                          "noise_floor": new["metrics"]["subsurface"][metric]["noise_floor"]})
        if old is not None:
            entries[entries.index(old)] = new
        else:
            entries.append(new)
    if yes:
        from harness.io.images import read_exr, write_exr

        for rel, src in images.items():
            layers = read_exr(src)
            if "mask" not in layers:
                raise InputError(src, "mask", "has no coverage layer 'mask'", "re-run the sweep that made it")
            (BASELINE_DIR / rel).parent.mkdir(parents=True, exist_ok=True)
            write_exr(BASELINE_DIR / rel, layers["rgb"], extra={"mask": layers["mask"]})
        for name, entries in changed.items():
            entries.sort(key=lambda e: (e["size"], e["config"]))
            with atomic_write(baseline_path(name)) as tmp:
                tmp.write_text(json.dumps({"scene": name, "entries": entries}, indent=1, sort_keys=True) + "\n")
    return {"written": sorted(str(baseline_path(n)) for n in changed) if yes else [],
            "images": sorted(str(BASELINE_DIR / r) for r in images) if yes else [], "changes": table}


def format_changes(changes):
    from io import StringIO

    from rich.console import Console
    from rich.table import Table

    t = Table(title="baseline update (subsurface image)")
    for col in ("scene", "size", "config", "metric", "before", "after", "noise floor"):
        t.add_column(col, justify="right" if col in ("before", "after", "noise floor") else "left")
    for r in changes:
        t.add_row(r["scene"], r["size"], r["config"], r["metric"],
                  "new" if r["before"] is None else f"{r['before']:.5g}", f"{r['after']:.5g}",
                  f"{r['noise_floor']:.3g}")
    buf = StringIO()
    Console(file=buf, width=140).print(t)
    return buf.getvalue()


# --------------------------------------------------------------------------- references

def reference_agreement(old, new, significance=SIGNIFICANCE, k_old=None, k_new=None):
    """Per-pixel two-sided Welch t-test of two independent reference estimates.

    ``t = (a - b) / sqrt(se_a^2 + se_b^2)`` for every pixel and channel with a
    non-zero standard error. Each standard error is itself estimated from ``K``
    seeds, so ``t`` follows Student's t with the Welch–Satterthwaite degrees of
    freedom, not a normal law (with K = 8 a normal z-test rejects far too often).
    The images disagree when the smallest p-value is below ``significance / n``
    (Bonferroni over the ``n`` tests), as in Mitsuba's render tests. Pixels where
    both estimates have zero error must be equal. ``k_old``/``k_new`` of None mean
    the errors are known exactly (a z-test).
    """
    from scipy import stats

    a, b = old["rgb"].astype(np.float64), new["rgb"].astype(np.float64)
    va, vb = old["se"].astype(np.float64) ** 2, new["se"].astype(np.float64) ** 2
    se = np.sqrt(va + vb)
    tested = se > 0
    n = int(tested.sum())
    t = np.abs(a - b)[tested] / se[tested]
    if k_old is None and k_new is None:
        p = 2 * stats.norm.sf(t)
    else:
        dof_a = (k_old - 1) if k_old else np.inf
        dof_b = (k_new - 1) if k_new else np.inf
        with np.errstate(divide="ignore", invalid="ignore"):
            dof = (va + vb)[tested] ** 2 / (va[tested] ** 2 / dof_a + vb[tested] ** 2 / dof_b)
        p = 2 * stats.t.sf(t, np.maximum(dof, 1.0))
    worst = int(np.argmin(p)) if n else 0
    p_min = float(p[worst]) if n else 1.0
    exact_mismatch = int(np.count_nonzero((~tested) & (a != b)))
    ok = (p_min >= significance / max(n, 1)) and exact_mismatch == 0
    return {"agree": bool(ok), "tests": n, "t_at_p_min": float(t[worst]) if n else 0.0,
            "t_max": float(t.max()) if n else 0.0, "p_min": p_min, "alpha": significance,
            "threshold_p": significance / max(n, 1), "untested_mismatches": exact_mismatch}


def regenerate_reference(scene_name, seed_offset=None, target=None, into=None, client=None, threads=None,
                         progress=False, sms_split=None):
    """Render the small reference again with new seeds; keep it only if it agrees with the old one.

    ``sms_split``: :func:`harness.reference.render.render_reference`'s (None: its default).

    ``into`` writes the new reference to another folder instead of replacing the
    committed one (the accuracy meta-tests keep such re-seeded references). ``client``
    renders its jobs on a Dask cluster (``threads``: Dr.Jit threads per render there).
    """
    from harness.io.images import read_exr
    from harness.reference.render import render_reference

    scene = committed.small_scene(load_scene(scene_name))
    dest = REF_DIR / scene_name
    old_meta = dest / "reference.json"
    old_info = json.loads(old_meta.read_text()) if old_meta.is_file() else None
    old_seeds = (old_info or {}).get("seeds") or [0]
    base_seed = seed_offset if seed_offset is not None else int(max(old_seeds)) + 1000
    target = target or scene.tolerances.get("small_reference_rel_se")
    kwargs = {"target_rel_se": float(target)} if target else {}
    kwargs["sms_split"] = sms_split
    tmp_root = REPO / "cache" / "regenerate"
    tmp_root.mkdir(parents=True, exist_ok=True)
    out = tmp_root / scene_name
    if out.exists():
        shutil.rmtree(out)
    if client is not None:
        kwargs.update(client=client, threads=threads)
    if progress:
        kwargs["progress"] = True
    render_reference(scene, out, seed_base=base_seed, **kwargs)
    result = {"scene": scene_name, "dest": str(dest), "base_seed": base_seed}
    if old_info is not None and old_info.get("content_hash") == scene.content_hash:
        checks = {}
        for part in ("subsurface", "full"):
            new_info = json.loads((out / "reference.json").read_text())
            checks[part] = reference_agreement(read_exr(dest / f"{part}.exr"), read_exr(out / f"{part}.exr"),
                                               k_old=old_info.get("K"), k_new=new_info.get("K"))
        result["check"] = checks
        if not all(c["agree"] for c in checks.values()):
            worst = min(checks.items(), key=lambda kv: kv[1]["p_min"])
            raise InputError(dest, f"{worst[0]}.exr", f"the new reference disagrees with the committed one "
                             f"(|t| = {worst[1]['t_at_p_min']:.2f}, p = {worst[1]['p_min']:.2e} < "
                             f"{worst[1]['threshold_p']:.2e} after Bonferroni over {worst[1]['tests']} pixels)",
                             f"nothing was replaced; new render kept in {out} for inspection")
        result["status"] = ("written to " + str(into) if into else "replaced") + " (agrees with the old reference)"
    else:
        result["status"] = "new (no reference for this scene version to check against)"
    target_dir = Path(into) if into else dest
    result["written"] = str(target_dir)
    with atomic_dir(target_dir) as tmp:
        for f in out.iterdir():
            shutil.copy2(f, tmp / f.name)
    shutil.rmtree(out, ignore_errors=True)
    return result


# --------------------------------------------------------------------------- CLI

def _scene_names(spec, known):
    """``--scenes A,B`` -> names, each one of ``known`` (a misspelt one gets the closest name)."""
    from harness.runs.sweep import resolve_scenes

    names = resolve_scenes(spec)
    for n in names:
        if n not in known:
            raise InputError("--scenes", "scenes", f"{n!r} has no committed baseline",
                             f"choose from: {', '.join(known)}" if known else "run `baselines update` first")
    return names


def show_table(entries):
    """The committed entries (``{scene: [entry]}``) as a text table: one row per scene, size and configuration."""
    from io import StringIO

    from rich.console import Console
    from rich.table import Table

    t = Table(title="committed baselines (subsurface image)")
    for col in ("scene", "size", "config", "relmse", "si_relmse", "energy_ratio", "flip", "updated", "commit"):
        t.add_column(col, justify="left" if col in ("scene", "size", "config", "updated", "commit") else "right")
    for name, rows in entries.items():
        for e in rows:
            m = e.get("metrics", {}).get("subsurface", {})
            vals = [f"{m[k]['value']:.5g}" if k in m and m[k].get("value") is not None else "-"
                    for k in ("relmse", "si_relmse", "energy_ratio", "flip")]
            t.add_row(name, f"{e['size'][0]}x{e['size'][1]}", e["config"], *vals, str(e.get("updated", ""))[:10],
                      str(e.get("git_commit") or "")[:10])
    buf = StringIO()
    Console(file=buf, width=160, color_system=None, force_terminal=False).print(t)
    return "\n".join(line.rstrip() for line in buf.getvalue().rstrip().splitlines())


def run_baselines_cli(args):
    """``sslpv-harness baselines ACTION``: ``(result, text)``; see :mod:`harness.cli.baselines`."""
    scenes = None if args.scenes is None else [n.strip() for n in args.scenes.split(",")]
    if args.action == "update":
        res = update(args.store, scene=scenes, yes=True)
        return res, format_changes(res["changes"])
    if args.action == "show":
        if args.store is not None:               # what `update --store` would change, nothing written
            res = update(args.store, scene=scenes, yes=False)
            return {"store": str(args.store), "changes": res["changes"]}, format_changes(res["changes"])
        known = [p.stem for p in sorted(BASELINE_DIR.glob("*.json"))]
        names = known if scenes is None else _scene_names(args.scenes, known)
        entries = {n: read_baseline(n) for n in names}
        return entries, show_table(entries)
    from harness.runs.sweep import resolve_scenes

    names = resolve_scenes(args.scenes) if args.scenes else list_scenes()
    if args.into and len(names) != 1:
        raise InputError("--into", "into", f"needs exactly one scene, got {len(names)}", "add --scenes NAME")
    from harness.reference.jobs import RenderSetup
    from harness.runs.references import _client

    # --sms-split applies to the scenes that sample specular manifolds; over several scenes the others
    # render one pass, as they would without it. Named for scenes of which none samples, it is refused.
    samples = {n: RenderSetup(load_scene(n)).samples_manifolds for n in names}
    if args.sms_split is not None and args.sms_split > 1 and not any(samples.values()):
        raise InputError("--sms-split", "sms_split", f"none of the scenes ({', '.join(names)}) samples specular "
                         "manifolds ([boundary] sms_trials > 0 behind a smooth dielectric)",
                         "leave --sms-split out, or name a scene that samples")
    # On a LocalCluster by default (--scheduler: an existing one; --serial: in this process).
    client, cluster, threads = _client(args.scheduler, args.workers, args.serial)
    try:
        out = [regenerate_reference(n, into=args.into, client=client, threads=threads,
                                    progress=args.progress and not args.json,
                                    sms_split=args.sms_split if samples[n] else None)
               for n in names]
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    return {"references": out}, None
