"""The committed small references: ``baselines/refs/<scene>/``.

A sweep at the committed size (:func:`small_size`: 64x64 for a square scene; a
non-square one keeps its aspect, e.g. 160x96 -> 60x36) compares against these instead
of rendering a reference, and the accuracy tests always do. They are Mitsuba references like any
other (``reference.json``, ``subsurface.exr`` with standard errors, the two halves);
they live here, below the runs and the regression machinery, because both read them.
:mod:`harness.regression.baselines` writes them (``regenerate-references``).
"""

import json
import math

from harness import paths
from harness.errors import InputError

#: Folder of the committed small references, one sub-folder per scene.
REF_DIR = paths.BASELINE_DIR / "refs"
#: The longer side of a committed small image.
SMALL_EDGE = 64


def small_size(width, height, edge=SMALL_EDGE):
    """The committed small image size ``[W, H]`` of a ``width x height`` camera: the same aspect.

    The longer side becomes at most ``edge``: the largest multiple of the reduced
    aspect ``(W, H) / gcd`` that fits, so the aspect is kept exactly (128x128 -> 64x64,
    160x96 -> 60x36, 1280x720 -> 64x36). Where no multiple reaches ``edge / 2`` (an
    aspect such as 127x128), the longer side is ``edge`` and the shorter one rounded.
    """
    width, height = int(width), int(height)
    g = math.gcd(width, height)
    a, b = width // g, height // g
    k = edge // max(a, b)
    if k >= 1 and k * max(a, b) >= edge / 2:
        return [k * a, k * b]
    if width >= height:
        return [edge, max(1, round(edge * height / width))]
    return [max(1, round(edge * width / height)), edge]


def small_scene(scene):
    """``scene`` at its committed small size (:func:`small_size` of its camera)."""
    return scene.with_resolution(*small_size(scene.camera.width, scene.camera.height))


def sized_scene(scene, size):
    """``scene`` at a sweep's ``size``: ``[W, H]``, ``"small"`` (:func:`small_scene`) or None (its own)."""
    if size is None:
        return scene
    if size == "small":
        return small_scene(scene)
    return scene.with_resolution(*size)


def committed_reference(scene, ref_dir=None):
    """The committed small reference for ``scene`` (at its current size), or an error naming the fix.

    ``ref_dir`` defaults to :data:`REF_DIR`, read at call time (tests point it elsewhere).
    """
    ref = (REF_DIR if ref_dir is None else ref_dir) / scene.name
    meta = ref / "reference.json"
    fix = f"run `sslpv-harness baselines regenerate-references --scenes {scene.name}`"
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
