"""A content-addressed cache of reference folders.

References live in ``<cache_dir>/<scene.name>/<content_hash[:16]>/``. A folder
is served only when its ``reference.json`` parses, names the same full
``content_hash`` and every listed file is present; anything else (a changed
scene, a foreign or damaged folder) is rendered again. Folders are written
atomically (``harness.io.atomic.atomic_dir``), so a half-written one never exists
under the final name.

A cached reference made for a looser noise target than the one asked for is
not served (it would not meet the request), nor one rendered with other Mitsuba
settings (integrator, colour passes: ``mitsuba_scene.scene_notes``) than the harness
uses now; ``force=True`` always renders. The ``reference`` command's glue (cluster,
estimate) is :mod:`harness.runs.references`.

Default cache folder: ``$SSLPV_CACHE`` or ``<repo>/cache/references``.
"""

import json
import os
from pathlib import Path

from harness import paths

from . import mitsuba_scene as ms
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


def current_settings(scene):
    """The Mitsuba settings a reference of ``scene`` is rendered with now (compared with a cached one's)."""
    notes = json.loads(json.dumps(ms.scene_notes(scene)))
    return {k: notes[k] for k in ("integrator", "channel_passes")}


def _serves(meta, scene, render_kwargs):
    if meta is None or meta.get("content_hash") != scene.content_hash:
        return False
    if {k: meta.get(k) for k in ("integrator", "channel_passes")} != current_settings(scene):
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
