"""The typed scene format (harness.scene.model): the suite hashes as before, the JSON Schema that
editors use agrees with the loader, and ``[mesh] repair = "close-holes"`` closes a hole made here."""

import json
from pathlib import Path

import jsonschema
import numpy as np
import pymeshlab
import pytest
import tomllib

from harness.errors import InputError
from harness.reference.committed import find_committed_reference, small_scene
from harness.scene import SUITE_DIR, list_scenes, load_scene
from harness.scene.model import schema_text

DATA = Path(__file__).resolve().parent / "data"
BEFORE = json.loads((DATA / "suite_hashes.json").read_text())["hashes"]


class TestSuiteHashes:
    """Every committed reference and cached one is found by the scene's content hash: it must not move."""

    @pytest.mark.parametrize("name", sorted(BEFORE))
    def test_same_hash_as_the_hand_written_loader(self, name):
        s = load_scene(name)
        assert s.content_hash == BEFORE[name]["scene"]
        assert s.with_resolution(64, 64).content_hash == BEFORE[name]["64x64"]

    @pytest.mark.parametrize("name", list_scenes())
    def test_committed_reference_still_matches(self, name):
        small = small_scene(load_scene(name))          # 64x64; a non-square scene keeps its aspect
        if not (SUITE_DIR.parent / "baselines" / "refs" / name).is_dir():
            pytest.skip(f"{name} has no committed small reference")
        assert find_committed_reference(small) is not None, f"{name}: the committed reference no longer matches"


class TestSchema:
    def test_committed_schema_is_the_models(self):
        committed = (SUITE_DIR / "scene.schema.json").read_text()
        assert committed == schema_text(), "run `sslpv-harness scenes --schema > reference_scenes/scene.schema.json`"

    def test_suite_scenes_are_valid_for_an_editor(self):
        validator = jsonschema.Draft7Validator(json.loads(schema_text()))
        for name in list_scenes():
            data = tomllib.loads((SUITE_DIR / name / "scene.toml").read_text())
            errors = [e.message for e in validator.iter_errors(data)]
            assert not errors, (name, errors)

    @pytest.mark.parametrize("edit", [
        lambda d: d["camera"].update(fovy=60),
        lambda d: d["mesh"].update(radius="big"),
        lambda d: d["medium"]["sigma_t"].update(kind="perlin"),
        lambda d: d["camera"].update(width=100000),
        lambda d: d.update(lights=[]),
    ], ids=["unknown-key", "string-number", "unknown-kind", "too-wide", "no-lights"])
    def test_schema_and_loader_refuse_the_same(self, tmp_path, edit):
        """An independent validator (jsonschema) reading the exported schema refuses what the loader refuses."""
        data = tomllib.loads((SUITE_DIR / "sphere_homogeneous" / "scene.toml").read_text())
        edit(data)
        assert list(jsonschema.Draft7Validator(json.loads(schema_text())).iter_errors(data))
        from harness.scene.model import SceneFile
        from harness.validation import validate

        with pytest.raises(InputError):
            validate(SceneFile, data, "scene.toml")


# --------------------------------------------------------------------------- mesh repair

SCENE = (SUITE_DIR / "sphere_homogeneous" / "scene.toml").read_text().replace(
    'kind = "sphere"\nradius = 1.0\nsubdivisions = 4', 'kind = "file"\npath = "holey.ply"{repair}').replace(
    "resolution = [64, 64, 64]", "resolution = [16, 16, 16]")


def holey_sphere(path, drop=(0, 1, 2, 3, 4)):
    """An icosphere with a hole: a few adjacent faces removed (the fan around vertex 0)."""
    ms = pymeshlab.MeshSet()
    ms.create_sphere(radius=1.0, subdiv=3)
    v, f = ms.current_mesh().vertex_matrix(), ms.current_mesh().face_matrix()
    around = np.flatnonzero((f == 0).any(axis=1))
    keep = np.setdiff1d(np.arange(len(f)), around[list(drop)])
    ms2 = pymeshlab.MeshSet()
    ms2.add_mesh(pymeshlab.Mesh(vertex_matrix=v, face_matrix=f[keep]))
    ms2.save_current_mesh(str(path), binary=False)
    return len(f), len(keep)


def write(tmp_path, repair):
    folder = tmp_path / "holey"
    folder.mkdir(exist_ok=True)
    (folder / "scene.toml").write_text(SCENE.replace("{repair}", repair))
    return folder


def test_hole_is_refused_and_repair_is_suggested(tmp_path):
    folder = write(tmp_path, "")
    holey_sphere(folder / "holey.ply")
    with pytest.raises(InputError, match=r'mesh: is not closed \(\d+ boundary edges.*add repair = "close-holes"'):
        load_scene(folder)


def test_close_holes_repairs_and_records_what_it_changed(tmp_path):
    folder = write(tmp_path, '\nrepair = "close-holes"')
    n_all, n_kept = holey_sphere(folder / "holey.ply")
    scene = load_scene(folder)
    rep = scene.mesh.repair
    assert rep["method"] == "close-holes" and rep["boundary_edges_before"] > 0 and rep["boundary_edges_after"] == 0
    # One simple hole of n boundary edges is closed by n - 2 triangles.
    assert rep["holes_before"] == 1 and rep["faces_added"] == rep["boundary_edges_before"] - 2
    assert len(scene.mesh.faces) == n_kept + rep["faces_added"] and n_all - n_kept == 5
    # The closed mesh is a valid object: its volume is within 1 % of the closed icosphere's.
    from harness.scene.geometry import signed_volume
    whole = load_scene("sphere_homogeneous").mesh
    assert signed_volume(scene.mesh) == pytest.approx(signed_volume(whole), rel=0.01)
    # ... and the reference's metadata says what changed.
    from harness.reference.mitsuba_scene import scene_notes
    assert scene_notes(scene)["mesh_repair"] == rep
    assert scene_notes(load_scene("sphere_homogeneous"))["mesh_repair"] is None


def test_a_mesh_that_stays_open_is_refused(tmp_path):
    """Two triangles that only share an edge: no hole to close, the edge is non-manifold."""
    folder = write(tmp_path, '\nrepair = "close-holes"')
    v = np.array([[0, 0, 0], [.5, 0, 0], [0, .5, 0], [0, 0, .5], [0, -.5, 0]], float)
    f = np.array([[0, 1, 2], [0, 1, 3], [0, 1, 4]], np.int32)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=v, face_matrix=f))
    ms.save_current_mesh(str(folder / "holey.ply"), binary=False)
    with pytest.raises(InputError, match=r'mesh: is still not closed after repair = "close-holes"'):
        load_scene(folder)
