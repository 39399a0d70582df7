"""Scene loading and validation: the suite loads, and every kind of bad scene
gives one line naming the file, the field and the fix."""

import dataclasses
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from harness.errors import InputError
from harness.scene.geometry import grid_inside, points_inside
from harness.scene import SUITE_DIR, list_scenes, load_scene

GOOD = (SUITE_DIR / "sphere_homogeneous" / "scene.toml").read_text()


def write_scene(tmp_path, text, files=None):
    folder = tmp_path / "scene_under_test"
    folder.mkdir(exist_ok=True)
    (folder / "scene.toml").write_text(text)
    for name, writer in (files or {}).items():
        writer(folder / name)
    return folder


def expect_error(tmp_path, text, field_pattern, files=None):
    folder = write_scene(tmp_path, text, files)
    with pytest.raises(InputError) as info:
        load_scene(folder)
    msg = str(info.value)
    assert "\n" not in msg, msg
    assert str(folder / "scene.toml") in msg, msg
    assert re.search(field_pattern, msg), msg
    return msg


class TestSuite:
    def test_at_least_eight_scenes(self):
        assert len(list_scenes()) >= 8

    @pytest.mark.parametrize("name", list_scenes())
    def test_loads_and_is_consistent(self, name):
        s = load_scene(name)
        nx, ny, nz = s.medium.resolution
        for grid in (s.medium.sigma_t, s.medium.albedo, s.medium.g):
            assert grid.shape == (nz, ny, nx, 3) and grid.dtype == np.float32
        lo, hi = s.mesh.bbox
        assert np.all(lo >= s.medium.bbox_min) and np.all(hi <= s.medium.bbox_max)
        assert len(s.content_hash) == 64

    def test_hash_is_stable_and_sensitive(self):
        a, b = load_scene("sphere_homogeneous"), load_scene("sphere_homogeneous")
        assert a.content_hash == b.content_hash
        assert a.with_resolution(64, 64).content_hash != a.content_hash
        changed = a.with_medium(albedo=a.medium.albedo * np.float32(0.5))
        assert changed.content_hash != a.content_hash

    def test_a_replaced_copy_has_its_own_hash(self):
        """A copy by dataclasses.replace (how benchmarks and tests make an index-matched or eta -> 1 twin) hashes its
        own contents: the Mitsuba scenes of a reference are cached by the hash, and a stale one rendered the
        original in the copy's place."""
        from harness.scene import Boundary
        from harness.scene.load import scene_hash

        a = load_scene("skin_torus_dielectric")
        matched = dataclasses.replace(a, boundary=Boundary("index-matched"))
        assert matched.content_hash == scene_hash(matched) != a.content_hash
        renamed = dataclasses.replace(a, name="other", description="another text")
        assert renamed.content_hash == a.content_hash             # what does not change an image keeps the hash

    def test_suite_covers_the_issue(self):
        tags = {t for n in list_scenes() for t in load_scene(n).tags}
        assert {"homogeneous", "heterogeneous", "coloured", "back-lit", "low-albedo", "anisotropic",
                "two-lights", "thin", "scanned", "measured"} <= tags
        mixed = load_scene("mixed_phase").medium.g
        assert mixed.max() == pytest.approx(0.8) and mixed.min() == pytest.approx(-0.3)


class TestScannedMesh:
    """The suite's scanned mesh (``bunny_dielectric``) is the one its recipe describes (``reference_scenes/README.md``,
    "The scanned mesh")."""

    @staticmethod
    def _edge_uses(faces):
        e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
        return np.unique(e, axis=0, return_counts=True)[1]

    def test_closed_two_manifold_genus_0(self):
        """4,000 faces (the recipe's target), every edge shared by exactly two triangles, genus 0 (Euler
        characteristic 2), behind a smooth dielectric."""
        scene = load_scene("bunny_dielectric")
        faces = np.asarray(scene.mesh.faces)
        uses = self._edge_uses(faces)
        assert np.all(uses == 2), "every edge of a closed two-manifold mesh has exactly two triangles"
        assert len(faces) == 4000 and len(np.unique(faces)) - len(uses) + len(faces) == 2
        assert scene.boundary.kind == "dielectric" and scene.boundary.roughness == 0.0


class TestBadScenes:
    def test_negative_sigma_t(self, tmp_path):
        expect_error(tmp_path, GOOD.replace("value = [8.0, 8.0, 8.0]", "value = [8.0, -1.0, 8.0]"),
                     r"medium\.sigma_t.*outside \[0\.0, inf\]")

    def test_nan_sigma_t(self, tmp_path):
        expect_error(tmp_path, GOOD.replace("value = [8.0, 8.0, 8.0]", "value = [8.0, nan, 8.0]"),
                     r"medium\.sigma_t.*(NaN|finite)")

    def test_albedo_out_of_range(self, tmp_path):
        expect_error(tmp_path, GOOD.replace("[0.99, 0.99, 0.99]", "[1.2, 0.99, 0.99]"),
                     r"medium\.albedo.*outside \[0\.0, 1\.0\]")

    def test_g_magnitude_one(self, tmp_path):
        expect_error(tmp_path, GOOD.replace("value = [0.0, 0.0, 0.0]", "value = [1.0, 0.0, 0.0]"),
                     r"medium\.g.*outside \(-1\.0, 1\.0\)")

    def test_grid_shape_disagrees_with_resolution(self, tmp_path):
        text = GOOD.replace('sigma_t = {kind = "constant", value = [8.0, 8.0, 8.0]}',
                            'sigma_t = {kind = "npz", file = "sigma.npz"}')
        expect_error(tmp_path, text, r"medium\.sigma_t\.file.*shape \(8, 8, 8, 3\).*\(64, 64, 64, 3\)",
                     files={"sigma.npz": lambda p: np.savez(p, data=np.ones((8, 8, 8, 3)))})

    def test_npz_grid_accepted(self, tmp_path):
        text = GOOD.replace('sigma_t = {kind = "constant", value = [8.0, 8.0, 8.0]}',
                            'sigma_t = {kind = "npz", file = "sigma.npz"}')
        folder = write_scene(tmp_path, text, {"sigma.npz": lambda p: np.savez(p, data=np.full((64, 64, 64), 3.0))})
        assert float(load_scene(folder).medium.sigma_t.mean()) == pytest.approx(3.0)

    def test_box_does_not_enclose_mesh(self, tmp_path):
        text = GOOD.replace("bbox_max = [1.05, 1.05, 1.05]", "bbox_max = [0.9, 0.9, 0.9]")
        expect_error(tmp_path, text.replace("bbox_min = [-1.05, -1.05, -1.05]", "bbox_min = [-0.9, -0.9, -0.9]"),
                     r"bbox.*does not enclose the mesh.*grow the box")

    def test_camera_inside_mesh(self, tmp_path):
        expect_error(tmp_path, GOOD.replace("origin = [0.0, 0.3, 4.2]", "origin = [0.0, 0.3, 0.2]"),
                     r"camera\.origin.*inside the mesh")

    def test_light_inside_mesh(self, tmp_path):
        expect_error(tmp_path, GOOD.replace("position = [2.5, 1.8, 2.2]", "position = [0.1, 0.1, 0.1]"),
                     r"lights\[0\]\.position.*inside the mesh")

    def test_missing_file(self, tmp_path):
        text = GOOD.replace('kind = "sphere"\nradius = 1.0\nsubdivisions = 4', 'kind = "file"\npath = "bunny.ply"')
        expect_error(tmp_path, text, r"mesh\.path.*does not exist")

    def test_path_leaving_the_folder(self, tmp_path):
        (tmp_path / "outside.ply").write_text("ply\n")
        text = GOOD.replace('kind = "sphere"\nradius = 1.0\nsubdivisions = 4', 'kind = "file"\npath = "../outside.ply"')
        expect_error(tmp_path, text, r"mesh\.path.*leaves the scene folder")

    def test_open_mesh_refused(self, tmp_path):
        def open_mesh(path):
            # A box with its top face missing: 10 triangles, a hole of four edges.
            v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
                         float) * 0.5
            f = [(0, 2, 1), (0, 3, 2), (0, 1, 5), (0, 5, 4), (1, 2, 6), (1, 6, 5), (2, 3, 7), (2, 7, 6),
                 (3, 0, 4), (3, 4, 7)]
            lines = ["ply", "format ascii 1.0", f"element vertex {len(v)}", "property float x", "property float y",
                     "property float z", f"element face {len(f)}", "property list uchar int vertex_indices",
                     "end_header"] + [" ".join(map(str, p)) for p in v] + [f"3 {a} {b} {c}" for a, b, c in f]
            path.write_text("\n".join(lines) + "\n")
        text = GOOD.replace('kind = "sphere"\nradius = 1.0\nsubdivisions = 4', 'kind = "file"\npath = "open.ply"')
        expect_error(tmp_path, text, r"mesh.*not closed.*boundary edges", files={"open.ply": open_mesh})

    def test_unknown_field(self, tmp_path):
        expect_error(tmp_path, "colour = 3\n" + GOOD, r"colour.*not a known field")

    def test_missing_units(self, tmp_path):
        expect_error(tmp_path, GOOD.replace('units = "cm"\n', ""), r"units.*missing")

    def test_bad_resolution(self, tmp_path):
        expect_error(tmp_path, GOOD.replace("resolution = [64, 64, 64]", "resolution = [64, 64]"),
                     r"medium\.resolution")

    def test_unknown_boundary(self, tmp_path):
        expect_error(tmp_path, GOOD.replace('kind = "index-matched"', 'kind = "mirror"'), r"boundary\.kind.*mirror")

    def test_bad_field_kind(self, tmp_path):
        expect_error(tmp_path, GOOD.replace('g = {kind = "constant"', 'g = {kind = "perlin"'), r"medium\.g\.kind")

    def test_no_eval_of_strings(self, tmp_path):
        # A string where a number belongs is refused as data, never evaluated.
        expect_error(tmp_path, GOOD.replace("radius = 1.0", 'radius = "__import__(\'os\')"'), r"mesh\.radius")

    def test_cli_prints_one_line(self, tmp_path):
        folder = write_scene(tmp_path, GOOD.replace("[0.99, 0.99, 0.99]", "[1.5, 0.99, 0.99]"))
        code = ("import sys; from harness.cli import main; "
                f"sys.exit(main(['render', {str(folder)!r}, '--out', {str(tmp_path / 'o')!r}]))")
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              cwd=Path(__file__).resolve().parent.parent)
        assert proc.returncode == 2, proc.stderr
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and "medium.albedo" in lines[0], proc.stderr
        assert not (tmp_path / "o").exists()


class TestInside:
    def test_sphere_points(self):
        mesh = load_scene("sphere_homogeneous").mesh
        pts = np.array([[0, 0, 0], [0.9, 0, 0], [0, 0, 1.2], [2, 2, 2]])
        assert points_inside(mesh, pts).tolist() == [True, True, False, False]

    def test_grid_matches_analytic_sphere(self):
        """Cell centres against |x| < r, away from the tessellated surface."""
        s = load_scene("sphere_homogeneous")
        n = 24
        mask = grid_inside(s.mesh, s.medium.bbox_min, s.medium.bbox_max, n)
        c = s.medium.bbox_min[0] + (np.arange(n) + 0.5) / n * (s.medium.bbox_max[0] - s.medium.bbox_min[0])
        z, y, x = np.meshgrid(c, c, c, indexing="ij")
        r = np.sqrt(x * x + y * y + z * z)
        clear = np.abs(r - 1.0) > 0.01  # the icosphere deviates < 0.5% from the sphere
        assert np.array_equal(mask[clear], (r < 1.0)[clear])

    def test_grid_matches_points_inside(self):
        s = load_scene("thin_ring")
        n = 16
        mask = grid_inside(s.mesh, s.medium.bbox_min, s.medium.bbox_max, n)
        c = s.medium.bbox_min[0] + (np.arange(n) + 0.5) / n * (s.medium.bbox_max[0] - s.medium.bbox_min[0])
        z, y, x = np.meshgrid(c, c, c, indexing="ij")
        pts = np.stack([x, y, z], -1).reshape(-1, 3)
        assert np.array_equal(mask.reshape(-1), points_inside(s.mesh, pts))


class TestBadMeshFields:
    @pytest.mark.parametrize("old,new,pattern", [
        ("subdivisions = 4", 'subdivisions = "x"', r"mesh\.subdivisions: must be an integer"),
        ("subdivisions = 4", "subdivisions = 9", r"mesh\.subdivisions: must be an integer in \[1, 6\]"),
        ('kind = "sphere"\nradius = 1.0\nsubdivisions = 4', 'kind = "torus"\nsegments = 5',
         r"mesh\.segments: must be a list of 2 integers in \[3, 1024\]"),
        ('kind = "sphere"\nradius = 1.0\nsubdivisions = 4', 'kind = "torus"\nrotate_x_deg = "a"',
         r"mesh\.rotate_x_deg: must be a number"),
        ('tags = ["homogeneous", "high-albedo"]', 'tags = "abc"', r"tags: must be a list of strings"),
        ("bbox_max = [1.05, 1.05, 1.05]", "bbox_max = [1.05, 1.05, 2.05]", r"medium\.bbox_max: .*not a cube"),
    ])
    def test_one_line(self, tmp_path, old, new, pattern):
        assert old in GOOD
        expect_error(tmp_path, GOOD.replace(old, new, 1), pattern)



def _dielectric(eta, roughness=None):
    extra = "" if roughness is None else f"\nroughness = {roughness}"
    return GOOD.replace('kind = "index-matched"', f'kind = "dielectric"\neta = {eta}{extra}')


class TestBoundary:
    """``[boundary]`` loads as written; its bad values are cases of ``tests/test_bad_scene_input.py``."""

    def test_smooth_and_rough_load(self, tmp_path):
        smooth = load_scene(write_scene(tmp_path, _dielectric(1.4, 0.0)))
        assert smooth.boundary.kind == "dielectric" and smooth.boundary.roughness == 0.0 and smooth.boundary.eta == 1.4
        assert load_scene(write_scene(tmp_path, _dielectric(1.4))).boundary.roughness == 0.1   # the default
