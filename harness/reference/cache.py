"""A content-addressed cache of reference folders, and the ``reference`` command's glue.

References live in ``<cache_dir>/<scene.name>/<content_hash[:16]>/``. A folder
is served only when its ``reference.json`` parses, names the same full
``content_hash`` and every listed file is present; anything else (a changed
scene, a foreign or damaged folder) is rendered again. Folders are written
atomically (``harness.io.atomic.atomic_dir``), so a half-written one never exists
under the final name.

A cached reference made for a looser noise target than the one asked for is
not served (it would not meet the request); ``force=True`` always renders.

Default cache folder: ``$SSLPV_CACHE`` or ``<repo>/cache/references``.
"""

import json
import os
import shutil
from pathlib import Path

from harness import paths
from harness.io.atomic import atomic_dir
from harness.io.outputs import check_replaceable, check_writable
from harness.errors import InputError

from . import render as _render

REPO_ROOT = paths.REPO


def default_cache_dir():
    """``$SSLPV_CACHE`` if set, else ``<repo>/cache/references``."""
    env = os.environ.get("SSLPV_CACHE")
    return Path(env) if env else REPO_ROOT / "cache" / "references"


def cache_path(scene, cache_dir=None):
    return Path(cache_dir or default_cache_dir()) / scene.name / scene.content_hash[:16]


def read_reference_meta(folder):
    """The folder's ``reference.json`` as a dict, or ``None`` when it is missing, unreadable or incomplete."""
    folder = Path(folder)
    try:
        meta = json.loads((folder / "reference.json").read_text())
    except (OSError, ValueError):
        return None
    files = meta.get("files") if isinstance(meta, dict) else None
    if not isinstance(files, list) or not all((folder / f).is_file() for f in files):
        return None
    return meta


def _serves(meta, scene, render_kwargs):
    if meta is None or meta.get("content_hash") != scene.content_hash:
        return False
    target = render_kwargs.get("target_rel_se")
    if target is not None and render_kwargs.get("spp") is None:
        # Serve only what was measured to meet the target, not what merely aimed at it.
        measured = meta.get("median_rel_se_subsurface")
        if measured is None or measured > target:
            return False
    return True


def reference_for(scene, cache_dir=None, force=False, **render_kwargs):
    """Path of a complete reference folder for ``scene``, rendering it only when no valid one is cached.

    ``render_kwargs`` go to :func:`harness.reference.render.render_reference`.
    """
    folder = cache_path(scene, cache_dir)
    if not force and _serves(read_reference_meta(folder), scene, render_kwargs):
        return folder
    _render.render_reference(scene, folder, **render_kwargs)
    return folder


def run_reference_cmd(scene_name, out_dir=None, target=None, spp=None, variant=None, force=False):
    """``sslpv-harness reference SCENE [--out DIR] [--target T] [--spp N] [--variant V] [--force]``.

    Renders (or takes from the cache) the reference of a suite scene, copies it
    to ``out_dir`` when given, and returns what it wrote and measured.
    """
    from harness.scene import load_scene

    scene = load_scene(scene_name)
    if target is not None and not (0 < float(target) < 1):
        raise InputError("--target", "target", f"must be a relative standard error in (0, 1), got {target}",
                         "use e.g. 0.05")
    if out_dir is not None:                    # refused before minutes of rendering, not after them
        check_replaceable(out_dir)
        check_writable(out_dir, "--out")
    kwargs = {"spp": spp, "variant": variant}
    # The scene states the noise its reference needs (dielectric scenes converge slowly).
    target = target if target is not None else scene.tolerances.get("reference_rel_se")
    if target is not None:
        kwargs["target_rel_se"] = float(target)
    before = _render.RENDER_COUNT
    folder = reference_for(scene, force=force, **kwargs)
    meta = read_reference_meta(folder)
    result = {"scene": scene.name, "content_hash": scene.content_hash, "reference_dir": str(folder),
              "rendered": _render.RENDER_COUNT != before, "out_dir": None, "files": meta["files"],
              "median_rel_se_subsurface": meta.get("median_rel_se_subsurface"),
              "median_rel_se_full": meta.get("median_rel_se_full"), "spp_total": meta.get("spp_total"),
              "K": meta.get("K"), "render_seconds": meta.get("render_seconds")}
    if out_dir is not None:
        out = Path(out_dir)
        if out.resolve() != folder.resolve():
            with atomic_dir(out) as tmp:
                for name in meta["files"]:
                    shutil.copy2(folder / name, tmp / name)
        result["out_dir"] = str(out)
    return result
