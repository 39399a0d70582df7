"""The committed small references: ``baselines/refs/<scene>/``.

A sweep at the committed size (64x64) compares against these instead of rendering
a reference, and the accuracy tests always do. They are Mitsuba references like any
other (``reference.json``, ``subsurface.exr`` with standard errors, the two halves);
they live here, below the runs and the regression machinery, because both read them.
:mod:`harness.regression.baselines` writes them (``regenerate-references``).
"""

import json

from harness import paths
from harness.errors import InputError

#: Folder of the committed small references, one sub-folder per scene.
REF_DIR = paths.BASELINE_DIR / "refs"


def committed_reference(scene, ref_dir=None):
    """The committed small reference for ``scene`` (at its current size), or an error naming the fix.

    ``ref_dir`` defaults to :data:`REF_DIR`, read at call time (tests point it elsewhere).
    """
    ref = (REF_DIR if ref_dir is None else ref_dir) / scene.name
    meta = ref / "reference.json"
    fix = f"run `sslpv-harness baselines regenerate-references --scene {scene.name}`"
    if not meta.is_file():
        raise InputError(ref, "reference", "is missing", fix)
    info = json.loads(meta.read_text())
    if info.get("content_hash") != scene.content_hash:
        raise InputError(meta, "content_hash", f"reference was rendered for scene hash "
                         f"{str(info.get('content_hash'))[:12]}, the scene now hashes to {scene.content_hash[:12]}",
                         fix)
    return ref


def find_committed_reference(scene, ref_dir=None):
    """Like :func:`committed_reference` but None when there is none for this exact scene."""
    try:
        return committed_reference(scene, ref_dir)
    except InputError:
        return None
