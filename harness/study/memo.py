"""Is a study folder already up to date? The key of everything a study's outputs depend on.

A warm study (nothing changed since the last finished run into the same folder) should take seconds.
The sweep alone would serve every configuration from the result cache but still measure each one
again against its reference (FLIP, SSIM, CIEDE2000 of two images per configuration: minutes for the
default study on two cores). :func:`inputs_key` is the sha256 of

* the resolved study (scenes, products, size, budget, metrics, significance, calibrations with their
  file hashes, twins, title);
* every configuration's result-cache key (:func:`harness.runs.cache.result_key`: the method's code
  and shaders, the scene, the parameters, the reference's files, this machine's GL renderer, the
  package versions), so anything that would re-render a configuration changes it;
* the committed data files it reads beside the renders (:func:`data_hash`: the calibrations' reports and
  floors, the selection of the best, the scenes' lighting-twin verdicts);
* the code that measures and presents: the Python modules that :mod:`harness.study.run` and the sweep
  worker import (the metrics among them), as syntax trees without docstrings, and the page template.

When the key equals the one the folder's ``study.json`` recorded, every output is there and every
render folder it names exists, the study serves the folder as it is (nothing rendered, measured or
written). Limits: a change outside these inputs (an environment variable, another data file read at run
time) is not seen; ``--no-cache`` bypasses it.
"""

import hashlib
import json
from pathlib import Path

from harness.io.source import import_closure, module_path, python_source_hash

#: The modules whose code decides what a study writes from its renders.
MEASURING = ("harness.study.run", "harness.study.docs", "harness.runs.sweep", "harness.runs.worker")
OUTPUTS = ("results.csv", "results.parquet", "study.json", "index.html", "figures")


def code_hash(templates):
    """sha256 over the measuring modules (:data:`MEASURING` and their imports) and the templates."""
    h = hashlib.sha256()
    for mod in sorted(import_closure(MEASURING)):
        h.update(mod.encode() + b"\0" + python_source_hash(module_path(mod)).encode())
    for p in sorted(Path(templates).glob("*")):
        h.update(p.name.encode() + b"\0" + hashlib.sha256(p.read_bytes()).digest())
    return h.hexdigest()


def inputs_key(study, templates, progress=False):
    """The key of ``study`` (:func:`harness.study.spec.load_study`'s dict) as it would run now, or None
    when a scene has no committed or cached reference yet (the sweep then renders it)."""
    from harness.reference.committed import sized_scene
    from harness.runs.cache import local_gl_renderer, reference_hash, result_key
    from harness.runs.rivals import method_of
    from harness.runs.sweep import expand_all, fetch_references
    from harness.scene import load_scene

    scenes = [sized_scene(load_scene(n), study["size"]) for n in study["scenes"]]
    refs, missing = fetch_references(scenes, None, progress)
    if missing:
        return None
    gl = local_gl_renderer()
    ref_hash = {name: reference_hash(d) for name, d in refs.items()}
    keys = sorted(result_key(method_of(p), s.content_hash, p.as_dict(), ref_hash[s.name], gl)
                  for s in scenes for p in expand_all(study["params"]))
    resolved = {k: study[k] for k in ("scenes", "params", "size", "budget", "metrics", "significance",
                                      "calibrations", "twins", "title")}
    doc = {"study": resolved, "configurations": keys, "code": code_hash(templates), "data": data_hash(study)}
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()


def data_hash(study):
    """sha256 over the committed data files the study reads beside its renders: each calibration's report
    (``calibration.json``) and every floor file its floor may come from (its own and its sources',
    :func:`harness.calibration.floor.floor_files`; :mod:`harness.study.limits`), the selection of the best
    calibration (:data:`harness.study.target.SELECTION`) and each scene's lighting-twin verdicts
    (:data:`harness.study.twin.VERDICTS`); a file that is absent counts as absent."""
    from harness.calibration.floor import floor_files
    from harness.study.target import SELECTION
    from harness.study.twin import VERDICTS

    files = [SELECTION] + [VERDICTS / f"{n}.json" for n in study["scenes"]]
    for cal in study["calibrations"]:
        report = Path(cal["path"]).with_name("calibration.json")
        files += [report, *floor_files(report)]
    h = hashlib.sha256()
    for p in files:
        h.update(str(p).encode() + b"\0" + (hashlib.sha256(p.read_bytes()).digest() if p.is_file() else b"absent"))
    return h.hexdigest()


def up_to_date(out, key):
    """The folder's ``study.json`` when ``out`` holds complete outputs made with ``key``, else None."""
    out = Path(out)
    if key is None or not all((out / name).exists() for name in OUTPUTS):
        return None
    try:
        info = json.loads((out / "study.json").read_text())
    except (OSError, ValueError):
        return None
    if info.get("inputs_key") != key:
        return None
    import csv

    with open(out / "results.csv", newline="") as f:
        dirs = [r["render_dir"] for r in csv.DictReader(f)]
    if len(dirs) != info.get("configurations") or not all(Path(d, "subsurface.exr").is_file() for d in dirs):
        return None
    return info
