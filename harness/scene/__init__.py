"""The scene stage: a ``scene.toml`` read once into a validated, immutable :class:`Scene`.

=====================  ======================================================================
module                 job
=====================  ======================================================================
:mod:`.model`          the ``scene.toml`` format as typed models, its derived checks, its JSON Schema
:mod:`.load`           reading a scene into the immutable :class:`Scene`, and its hash
:mod:`.geometry`       meshes: the ``[mesh]`` models, shapes and files, repair, closedness, inside tests
:mod:`.fields`         the medium field models and their grids (sigma_t, albedo, g)
=====================  ======================================================================

Both renderers (Mitsuba in :mod:`harness.reference`, SSLPV in :mod:`sslpv_gl`) are
built from the one :class:`Scene`; this package imports neither of them.
"""

from harness.scene.model import BOUNDARY_KINDS, SceneFile, json_schema
from harness.scene.load import (
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
    unknown_scene_fix,
)

__all__ = [
    "BOUNDARY_KINDS", "SUITE_DIR", "Boundary", "Camera", "Medium", "PointLight", "Scene",
    "list_scenes", "load_scene", "scene_hash", "scene_path", "unknown_scene_fix", "SceneFile", "json_schema",
]
