"""The scene stage: a ``scene.toml`` read once into a validated, immutable :class:`Scene`.

=====================  ======================================================
module                 job
=====================  ======================================================
:mod:`.load`           the file format, validation, :class:`Scene` and its hash
:mod:`.geometry`       meshes: built-in shapes and files, closedness, inside tests
:mod:`.fields`         procedural and file-backed medium grids (sigma_t, albedo, g)
=====================  ======================================================

Both renderers (Mitsuba in :mod:`harness.reference`, SSLPV in :mod:`sslpv_gl`) are
built from the one :class:`Scene`; this package imports neither of them.
"""

from harness.scene.load import (
    BOUNDARY_KINDS,
    SUITE_DIR,
    Boundary,
    Camera,
    Medium,
    PointLight,
    Scene,
    list_scenes,
    load_scene,
    scene_hash,
    scene_path,
)

__all__ = [
    "BOUNDARY_KINDS", "SUITE_DIR", "Boundary", "Camera", "Medium", "PointLight", "Scene",
    "list_scenes", "load_scene", "scene_hash", "scene_path",
]
