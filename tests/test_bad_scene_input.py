"""Bad scene files through the command line: each case exits 2 with ONE line naming the file and the field,
and leaves no file behind (the ``cli`` fixture of :mod:`tests.test_bad_input`, which has the other inputs).

The cases: a scene file's keys and values, its mesh files (PLY, NPZ) and meshes that a smooth boundary cannot
take (open, non-manifold), and a scene that is not UTF-8.
"""

import numpy as np
import pytest

from tests.test_bad_input import GOOD, JADE, one_line_runner


@pytest.fixture
def cli(tmp_path, capsys, monkeypatch):
    return one_line_runner(tmp_path, capsys, monkeypatch)


def scene_dir(tmp_path, text, files=None, name="scene_under_test"):
    folder = tmp_path / name
    folder.mkdir(exist_ok=True)
    (folder / "scene.toml").write_text(text) if isinstance(text, str) else (folder / "scene.toml").write_bytes(text)
    for fname, writer in (files or {}).items():
        writer(folder / fname)
    return folder


def ply(path, vertices, faces):
    lines = ["ply", "format ascii 1.0", f"element vertex {len(vertices)}", "property float x", "property float y",
             "property float z", f"element face {len(faces)}", "property list uchar int vertex_indices",
             "end_header"] + [" ".join(map(str, p)) for p in vertices] + [f"3 {a} {b} {c}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")


def cube_ply(path, nan=False):
    v = [[-.5, -.5, -.5], [.5, -.5, -.5], [.5, .5, -.5], [-.5, .5, -.5],
         [-.5, -.5, .5], [.5, -.5, .5], [.5, .5, .5], [-.5, .5, .5]]
    if nan:
        v[6] = ["nan", 0.5, 0.5]
    f = [(0, 2, 1), (0, 3, 2), (4, 5, 6), (4, 6, 7), (0, 1, 5), (0, 5, 4), (1, 2, 6), (1, 6, 5), (2, 3, 7),
         (2, 7, 6), (3, 0, 4), (3, 4, 7)]
    ply(path, v, f)


FILE_MESH = 'kind = "file"\npath = "m.ply"'
INDEX_MATCHED = 'kind = "index-matched"'
SMOOTH = 'kind = "dielectric"\neta = {eta}\nroughness = 0.0'
SPHERE_MESH = 'kind = "sphere"\nradius = 1.0\nsubdivisions = 4'


# --------------------------------------------------------------------------- scene files
# (id, scene text, expected field, expected words); rendered with `render SCENE --out o`.
SCENE_CASES = [
    # unknown keys inside tables (the issue: silently ignored before)
    ("fovy-in-camera", GOOD.replace("fov_y = 34.0", "fov_y = 34.0\nfovy = 60"), "camera.fovy", "not a known field"),
    ("sigma_s-in-medium", GOOD.replace("[medium]", "[medium]\nsigma_s = 3.0"), "medium.sigma_s", "not a known field"),
    ("radiuss-in-mesh", GOOD.replace("radius = 1.0", "radiuss = 1.0"), "mesh.radiuss", "not a known field"),
    ("unknown-top-level", "colour = 3\n" + GOOD, "colour", "not a known field"),
    ("unknown-in-lights", GOOD.replace("intensity = [12.0", "power = 3\nintensity = [12.0"), "lights[0].power",
     "not a known field"),
    ("unknown-in-tolerances", GOOD.replace("[tolerances]", "[tolerances]\nssim = 0.9"), "tolerances.ssim",
     "not a known field"),
    ("unknown-in-field", GOOD.replace('value = [8.0, 8.0, 8.0]}', 'value = [8.0, 8.0, 8.0], seed = 2}'),
     "medium.sigma_t.seed", "not a known field"),
    ("eta-under-index-matched", GOOD.replace('kind = "index-matched"', 'kind = "index-matched"\neta = 1.3'),
     "boundary.eta", "not a known field"),
    # wrong types (the issue: tracebacks before)
    ("origin-string", GOOD.replace("origin = [0.0, 0.3, 4.2]", 'origin = ["a", 0.3, 4.2]'), "camera.origin[0]",
     "must be a number"),
    ("intensity-string", GOOD.replace("intensity = [12.0, 12.0, 12.0]", 'intensity = "bright"'),
     "lights[0].intensity", "must be a list of 3 numbers"),
    ("field-value-string", GOOD.replace("value = [8.0, 8.0, 8.0]", 'value = ["x", 8, 8]'),
     "medium.sigma_t.value[0]", "must be a number"),
    ("frequency-string", JADE.replace("frequency = 1.2", 'frequency = "high"', 1), "medium.sigma_t.frequency",
     "must be a number"),
    ("lights-of-strings", GOOD.replace("[[lights]]\nposition = [2.5, 1.8, 2.2]\nintensity = [12.0, 12.0, 12.0]\n",
                                       "").replace("tags = ", 'lights = ["a"]\ntags = '), "lights[0]",
     "must be a table"),
    ("rel-se-string", GOOD.replace("reference_rel_se = 0.05", 'reference_rel_se = "tight"'),
     "tolerances.reference_rel_se", "must be a number in (0, 1)"),
    ("radius-string-not-evaluated", GOOD.replace("radius = 1.0", "radius = \"__import__('os')\""), "mesh.radius",
     "must be a number"),
    ("width-bool", GOOD.replace("width = 128", "width = true"), "camera.width", "must be an integer"),
    ("camera-not-table", GOOD.replace("[camera]\n", "camera = 5\n[cam]\n"), "mesh.camera", "not a known field"),
    ("g-not-table", GOOD.replace('g = {kind = "constant", value = [0.0, 0.0, 0.0]}', "g = 0.5"), "medium.g",
     "must be a table"),
    ("tags-string", GOOD.replace('tags = ["homogeneous", "high-albedo"]', 'tags = "abc"'), "tags",
     "must be a list of strings"),
    # ranges
    ("fov-180", GOOD.replace("fov_y = 34.0", "fov_y = 180"), "camera.fov_y", "(0, 180)"),
    ("fov-nan", GOOD.replace("fov_y = 34.0", "fov_y = nan"), "camera.fov_y", "got nan"),
    ("width-over-8192", GOOD.replace("width = 128", "width = 100000"), "camera.width", "[1, 8192]"),
    ("negative-intensity", GOOD.replace("intensity = [12.0, 12.0, 12.0]", "intensity = [12.0, -1.0, 12.0]"),
     "lights[0].intensity[1]", ">= 0"),
    ("resolution-two", GOOD.replace("resolution = [16, 16, 16]", "resolution = [16, 16]"), "medium.resolution",
     "3 integers"),
    ("subdivisions-9", GOOD.replace("subdivisions = 4", "subdivisions = 9"), "mesh.subdivisions", "[1, 6]"),
    ("eta-below-one", GOOD.replace('kind = "index-matched"', 'kind = "dielectric"\neta = 0.5'), "boundary.eta",
     "(1, 3]"),
    ("units-empty", GOOD.replace('units = "cm"', 'units = ""'), "units", "must not be empty"),
    ("negative-sigma-t", GOOD.replace("value = [8.0, 8.0, 8.0]", "value = [8.0, -1.0, 8.0]"), "medium.sigma_t",
     "outside [0.0, inf]"),
    ("albedo-above-one", GOOD.replace("[0.99, 0.99, 0.99]", "[1.2, 0.99, 0.99]"), "medium.albedo",
     "outside [0.0, 1.0]"),
    ("negative-seed", JADE.replace("seed = 7", "seed = -1", 1), "medium.sigma_t.seed", "[0, 4294967295]"),
    # kinds and missing tables
    ("mesh-kind", GOOD.replace('kind = "sphere"', 'kind = "cube"'), "mesh.kind", "unknown kind 'cube'"),
    ("boundary-kind", GOOD.replace('kind = "index-matched"', 'kind = "mirror"'), "boundary.kind", "mirror"),
    ("field-kind", GOOD.replace('g = {kind = "constant"', 'g = {kind = "perlin"'), "medium.g.kind", "perlin"),
    ("medium-missing", GOOD[:GOOD.index("[medium]")], "medium", "is missing"),
    ("units-missing", GOOD.replace('units = "cm"\n', ""), "units", "is missing"),
    # derived checks (model validators) and their messages
    ("direction-zero", JADE.replace("direction = [1.0, 0.6, 0.3]", "direction = [0, 0, 0]", 1),
     "medium.sigma_t.direction", "its length is 0"),
    ("up-parallel", GOOD.replace("up = [0.0, 1.0, 0.0]", "up = [0.0, 0.3, 4.2]"), "camera.up", "parallel"),
    ("box-too-small", GOOD.replace("bbox_min = [-1.05, -1.05, -1.05]", "bbox_min = [-0.9, -0.9, -0.9]").replace(
        "bbox_max = [1.05, 1.05, 1.05]", "bbox_max = [0.9, 0.9, 0.9]"), "medium.bbox_min/bbox_max",
     "does not enclose the mesh"),
    ("box-not-cube", GOOD.replace("bbox_max = [1.05, 1.05, 1.05]", "bbox_max = [1.05, 1.05, 2.05]"),
     "medium.bbox_max", "not a cube"),
    ("camera-inside", GOOD.replace("origin = [0.0, 0.3, 4.2]", "origin = [0.0, 0.3, 0.2]"), "camera.origin",
     "inside the mesh"),
    ("light-inside", GOOD.replace("position = [2.5, 1.8, 2.2]", "position = [0.1, 0.1, 0.1]"),
     "lights[0].position", "inside the mesh"),
    ("torus-radii", GOOD.replace(SPHERE_MESH, 'kind = "torus"\nmajor_radius = 0.3\nminor_radius = 0.5'),
     "mesh.minor_radius", "smaller than major_radius"),
    # a dielectric boundary (issue 10): eta a supported index, a smooth boundary with eta = 1 is index-matched
    ("eta-zero", GOOD.replace(INDEX_MATCHED, SMOOTH.format(eta=0)), "boundary.eta",
     "eta = 0 is not a refractive index (must be > 0); give the medium's index"),
    ("eta-negative", GOOD.replace(INDEX_MATCHED, SMOOTH.format(eta=-1.4)), "boundary.eta", "not a refractive index"),
    ("eta-below-one-smooth", GOOD.replace(INDEX_MATCHED, SMOOTH.format(eta=0.8)), "boundary.eta",
     "outside the supported range (1, 3]; use kind = \"index-matched\" for eta = 1; media less dense"),
    ("eta-above-three", GOOD.replace(INDEX_MATCHED, SMOOTH.format(eta=3.5)), "boundary.eta",
     "outside the supported range (1, 3]"),
    ("smooth-eta-one", GOOD.replace(INDEX_MATCHED, SMOOTH.format(eta=1.0)), "boundary.eta",
     "eta = 1 with roughness = 0 is an index-matched boundary; use kind = \"index-matched\""),
    ("rough-eta-one", GOOD.replace(INDEX_MATCHED, SMOOTH.format(eta=1.0).replace("0.0", "0.2")), "boundary.eta",
     "eta = 1 is outside the supported range"),
    ("roughness-negative", GOOD.replace(INDEX_MATCHED, SMOOTH.format(eta=1.4).replace("0.0", "-0.1")),
     "boundary.roughness", "must be a number in [0, 1], got -0.1"),
    ("roughness-above-one", GOOD.replace(INDEX_MATCHED, SMOOTH.format(eta=1.4).replace("0.0", "1.5")),
     "boundary.roughness", "[0, 1]"),
    ("eta-string", GOOD.replace(INDEX_MATCHED, SMOOTH.format(eta='"glass"')), "boundary.eta", "must be a number"),
    # the longest chain of refractions of the exact reference
    ("max-crossings-zero", GOOD.replace(INDEX_MATCHED, SMOOTH.format(eta=1.4) + "\nmax_crossings = 0"),
     "boundary.max_crossings", "must be an integer in [1, 9], got 0"),
    ("max-crossings-above-limit", GOOD.replace(INDEX_MATCHED, SMOOTH.format(eta=1.4) + "\nmax_crossings = 10"),
     "boundary.max_crossings", "must be an integer in [1, 9], got 10"),
    # specular manifold sampling of the exact reference
    ("sms-trials-negative", GOOD.replace(INDEX_MATCHED, SMOOTH.format(eta=1.4) + "\nsms_trials = -1"),
     "boundary.sms_trials", "must be an integer in [0, 4096], got -1"),
    ("sms-trials-above-limit", GOOD.replace(INDEX_MATCHED, SMOOTH.format(eta=1.4) + "\nsms_trials = 5000"),
     "boundary.sms_trials", "[0, 4096]"),
    ("sms-chain-ends-inside", GOOD.replace(INDEX_MATCHED, SMOOTH.format(eta=1.4) + '\nsms_chains = "T,TT"'),
     "boundary.sms_chains", "'TT' ends inside the medium"),
    ("sms-chain-reflects-outside-first", GOOD.replace(INDEX_MATCHED, SMOOTH.format(eta=1.4) + '\nsms_chains = "rT"'),
     "boundary.sms_chains", "cannot follow a segment inside"),
]


@pytest.mark.parametrize("text,field,words", [c[1:] for c in SCENE_CASES], ids=[c[0] for c in SCENE_CASES])
def test_bad_scene(cli, tmp_path, text, field, words):
    folder = scene_dir(tmp_path, text)
    cli(["render", folder, "--out", tmp_path / "o"], folder / "scene.toml", f": {field}: ", words)


FILE_CASES = [
    # (id, mesh table, files, expected field, expected words)
    ("nan-vertex", FILE_MESH, {"m.ply": lambda p: cube_ply(p, nan=True)}, "mesh.path", "NaN or infinite"),
    ("folder-as-mesh", 'kind = "file"\npath = "meshes"', {"meshes": lambda p: p.mkdir()}, "mesh.path",
     "is a folder"),
    ("missing-mesh", FILE_MESH, {}, "mesh.path", "does not exist"),
    ("mesh-leaves-folder", 'kind = "file"\npath = "../m.ply"', {}, "mesh.path", "leaves the scene folder"),
    ("not-a-mesh", FILE_MESH, {"m.ply": lambda p: p.write_text("hello\n")}, "mesh.path", "cannot read m.ply"),
    ("open-mesh", FILE_MESH, {"m.ply": lambda p: ply(p, [[-.5, -.5, 0], [.5, -.5, 0], [0, .5, 0]], [(0, 1, 2)])},
     "mesh", "add repair = \"close-holes\""),
    ("repair-on-a-sphere", SPHERE_MESH + '\nrepair = "close-holes"', {}, "mesh.repair", "not a known field"),
    ("repair-unknown", FILE_MESH + '\nrepair = "fill"', {"m.ply": cube_ply}, "mesh.repair", '"close-holes"'),
]


@pytest.mark.parametrize("mesh,files,field,words", [c[1:] for c in FILE_CASES], ids=[c[0] for c in FILE_CASES])
def test_bad_mesh_file(cli, tmp_path, mesh, files, field, words):
    text = GOOD.replace(SPHERE_MESH, mesh).replace("bbox_min = [-1.05, -1.05, -1.05]", "bbox_min = [-1.5, -1.5, "
                                                                                       "-1.5]")
    folder = scene_dir(tmp_path, text, files)
    cli(["render", folder, "--out", tmp_path / "o"], folder / "scene.toml", f": {field}", words)


# Two closed tetrahedra sharing one edge: no boundary edge, but four faces meet at it.
BOWTIE = ([[0, 0, 0], [.5, 0, 0], [0, .5, 0], [0, 0, .5], [0, -.5, 0], [0, 0, -.5]],
          [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3), (0, 1, 4), (0, 5, 1), (0, 4, 5), (1, 5, 4)])
SMOOTH_MESH_CASES = [
    ("open-mesh-smooth", {"m.ply": lambda p: ply(p, [[-.5, -.5, 0], [.5, -.5, 0], [0, .5, 0]], [(0, 1, 2)])},
     "is not closed (3 boundary edges"),
    ("non-manifold-smooth", {"m.ply": lambda p: ply(p, *BOWTIE)},
     "is not two-manifold (0 boundary edges, two-manifold=False); split or remove the non-manifold edges"),
]


@pytest.mark.parametrize("files,words", [c[1:] for c in SMOOTH_MESH_CASES], ids=[c[0] for c in SMOOTH_MESH_CASES])
def test_bad_mesh_under_smooth_boundary(cli, tmp_path, files, words):
    """A smooth boundary (rendered by manifold walks on the surface) needs a closed two-manifold mesh."""
    text = GOOD.replace(SPHERE_MESH, FILE_MESH).replace(INDEX_MATCHED, SMOOTH.format(eta=1.4))
    folder = scene_dir(tmp_path, text, files)
    cli(["render", folder, "--out", tmp_path / "o"], folder / "scene.toml", ": mesh: ", words)


def test_scene_not_utf8(cli, tmp_path):
    folder = scene_dir(tmp_path, GOOD.replace("Homogeneous", "Homog\xe9neous").encode("latin-1"))
    cli(["render", folder, "--out", tmp_path / "o"], folder / "scene.toml", "file: is not UTF-8")


def test_npz_bad_key_and_shape(cli, tmp_path):
    npz = GOOD.replace('sigma_t = {kind = "constant", value = [8.0, 8.0, 8.0]}',
                       'sigma_t = {kind = "npz", file = "s.npz", key = "sigma"}')
    folder = scene_dir(tmp_path, npz, {"s.npz": lambda p: np.savez(p, data=np.ones((16, 16, 16)))})
    cli(["render", folder, "--out", tmp_path / "o"], "medium.sigma_t.key", "has no array 'sigma'")
    (folder / "s.npz").unlink()
    np.savez(folder / "s.npz", sigma=np.ones((8, 8, 8)))
    cli(["render", folder, "--out", tmp_path / "o"], "medium.sigma_t.file", "shape (8, 8, 8, 3)")


# --------------------------------------------------------------------------- command-line values
