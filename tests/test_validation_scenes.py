"""The validation scenes outside the suite (``validation_scenes/``): each loads in the suite's format, its mesh
is closed and two-manifold, the scanned mesh is the one its recipe describes, and none is taken by the suite."""

from pathlib import Path

import numpy as np
import pytest

from harness.scene import list_scenes, load_scene
from harness.scene.geometry import points_inside

ROOT = Path(__file__).resolve().parent.parent
FOLDERS = sorted(p.parent for p in (ROOT / "validation_scenes").glob("*/scene.toml"))


def _edges(faces):
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    return counts


@pytest.mark.parametrize("folder", FOLDERS, ids=[f.name for f in FOLDERS])
def test_loads_closed_and_outside_the_suite(folder):
    scene = load_scene(folder)
    assert folder.name not in list_scenes()
    faces = np.asarray(scene.mesh.faces)
    assert np.all(_edges(faces) == 2), "every edge of a closed two-manifold mesh has exactly two triangles"
    lo, hi = np.asarray(scene.medium.bbox_min), np.asarray(scene.medium.bbox_max)
    v = np.asarray(scene.mesh.vertices)
    assert np.all(v >= lo) and np.all(v <= hi)
    outside = np.array([scene.camera.origin] + [light.position for light in scene.lights], np.float64)
    assert not points_inside(scene.mesh, outside).any()


def test_bunny_is_the_recipes_mesh():
    """4,000 faces (the recipe's target), genus 0 (Euler characteristic 2) and one component."""
    scene = load_scene(ROOT / "validation_scenes" / "bunny_dielectric")
    faces = np.asarray(scene.mesh.faces)
    V = len(np.unique(faces))
    E = len(_edges(faces))
    assert len(faces) == 4000 and V - E + len(faces) == 2
    assert scene.boundary.kind == "dielectric" and scene.boundary.roughness == 0.0
