"""Scenes: one ``reference_scenes/<name>/scene.toml`` read once into a validated,
immutable :class:`Scene` from which both renderers are built.

A scene file is data (TOML): no ``eval``, no pickle. Every field is validated
once here, and a bad field raises :class:`~harness.errors.InputError` with one
line naming the file, the field, the allowed range and the fix.

Top-level tables: ``units``, ``description``, ``[mesh]`` (``harness.scene.geometry``),
``[camera]``, ``[[lights]]``, ``[boundary]``, ``[medium]`` (fields in
``harness.scene.fields``) and ``[tolerances]``. ``reference_scenes/README.md``
documents the format with an example.
"""

import dataclasses
import hashlib
import json
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from harness import paths
from harness.errors import InputError
from harness.scene.fields import evaluate_field
from harness.scene.geometry import Mesh, build_mesh, points_inside

SUITE_DIR = paths.SUITE_DIR
BOUNDARY_KINDS = ("index-matched", "dielectric")
_TOP_KEYS = {"units", "description", "mesh", "camera", "lights", "boundary", "medium", "tolerances", "tags"}


@dataclass(frozen=True)
class Camera:
    origin: tuple
    target: tuple
    up: tuple
    fov_y_deg: float
    width: int
    height: int


@dataclass(frozen=True)
class PointLight:
    position: tuple
    intensity: tuple  # W/sr, RGB


@dataclass(frozen=True)
class Boundary:
    kind: str
    eta: float = 1.0
    roughness: float = 0.0

    @property
    def index_matched(self):
        return self.kind == "index-matched"


@dataclass(frozen=True, eq=False)
class Medium:
    bbox_min: np.ndarray
    bbox_max: np.ndarray
    sigma_t: np.ndarray  # (nz, ny, nx, 3) float32, per scene unit
    albedo: np.ndarray   # (nz, ny, nx, 3) float32, in [0, 1]
    g: np.ndarray        # (nz, ny, nx, 3) float32, in (-1, 1)

    @property
    def resolution(self):
        nz, ny, nx, _ = self.sigma_t.shape
        return (nx, ny, nz)


@dataclass(frozen=True, eq=False)
class Scene:
    name: str
    path: Path
    units: str
    description: str
    mesh: Mesh
    camera: Camera
    lights: tuple
    boundary: Boundary
    medium: Medium
    tolerances: dict = field(default_factory=dict)
    tags: tuple = ()
    content_hash: str = ""

    def with_resolution(self, width, height):
        """The same scene rendered at another image size (the hash changes with the size)."""
        cam = dataclasses.replace(self.camera, width=int(width), height=int(height))
        out = dataclasses.replace(self, camera=cam, content_hash="")
        return dataclasses.replace(out, content_hash=scene_hash(out))

    def with_medium(self, **grids):
        """A copy with some medium grids replaced (used by tests and validation scenes)."""
        out = dataclasses.replace(self, medium=dataclasses.replace(self.medium, **grids), content_hash="")
        return dataclasses.replace(out, content_hash=scene_hash(out))


def scene_hash(scene):
    """sha256 over everything that changes an image: geometry, camera, lights, boundary and grids."""
    h = hashlib.sha256()
    meta = {
        "units": scene.units,
        "camera": dataclasses.asdict(scene.camera),
        "lights": [dataclasses.asdict(light) for light in scene.lights],
        "boundary": dataclasses.asdict(scene.boundary),
        "bbox": [list(map(float, scene.medium.bbox_min)), list(map(float, scene.medium.bbox_max))],
    }
    h.update(json.dumps(meta, sort_keys=True, default=float).encode())
    for arr in (scene.mesh.vertices, scene.mesh.faces, scene.mesh.normals,
                scene.medium.sigma_t, scene.medium.albedo, scene.medium.g):
        a = np.ascontiguousarray(arr)
        h.update(str((a.dtype.str, a.shape)).encode())
        h.update(a.tobytes())
    return h.hexdigest()


# --------------------------------------------------------------------------- validation helpers

def _vec(table, key, where, prefix, default=None):
    value = table.get(key, default)
    arr = np.asarray(value, dtype=np.float64) if isinstance(value, (list, tuple)) else None
    if arr is None or arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise InputError(where, f"{prefix}.{key}", f"must be three finite numbers, got {value!r}",
                         "write e.g. [0.0, 1.0, 0.0]")
    return arr


def _num(table, key, where, prefix, lo, hi, default=None, integer=False, lo_open=False, hi_open=False):
    value = table.get(key, default)
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and np.isfinite(value)
    if integer:
        ok = ok and float(value).is_integer()
    if ok:
        ok = (value > lo if lo_open else value >= lo) and (value < hi if hi_open else value <= hi)
    if not ok:
        lb, rb = ("(" if lo_open else "["), (")" if hi_open else "]")
        kind = "an integer" if integer else "a number"
        raise InputError(where, f"{prefix}.{key}", f"must be {kind} in {lb}{lo}, {hi}{rb}, got {value!r}",
                         "change the value")
    return int(value) if integer else float(value)


def _table(data, key, where):
    value = data.get(key)
    if not isinstance(value, dict):
        raise InputError(where, key, "is missing or is not a table", f"add a [{key}] table")
    return value


def _check_grid(name, arr, lo, hi, where, lo_open=False, hi_open=False):
    bad = ~np.isfinite(arr)
    if bad.any():
        raise InputError(where, f"medium.{name}", f"contains {int(bad.sum())} NaN or Inf values",
                         "fix the grid")
    below = arr <= lo if lo_open else arr < lo
    above = arr >= hi if hi_open else arr > hi
    if below.any() or above.any():
        lb, rb = ("(" if lo_open else "["), (")" if hi_open else "]")
        worst = float(arr[below | above].flat[0])
        raise InputError(where, f"medium.{name}", f"has {int((below | above).sum())} values outside "
                         f"{lb}{lo}, {hi}{rb} (e.g. {worst:g})", f"keep {name} within {lb}{lo}, {hi}{rb}")


# --------------------------------------------------------------------------- loading

def scene_path(name_or_path):
    """A scene name from the suite, a scene folder, or a scene.toml path -> the scene.toml path."""
    p = Path(name_or_path)
    if p.suffix == ".toml":
        return p
    if p.is_dir():
        return p / "scene.toml"
    return SUITE_DIR / str(name_or_path) / "scene.toml"


def list_scenes(suite_dir=SUITE_DIR):
    """Names of the scenes in the suite folder, sorted."""
    return sorted(p.parent.name for p in Path(suite_dir).glob("*/scene.toml"))


def load_scene(name_or_path):
    """Read and validate a scene; see the module docstring."""
    path = scene_path(name_or_path)
    if not path.is_file():
        known = ", ".join(list_scenes()) or "none"
        raise InputError(path, "scene", f"no scene file {path}", f"choose one of the suite's scenes: {known}")
    where = str(path)
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise InputError(where, "toml", f"is not valid TOML ({exc})", "fix the syntax") from exc
    unknown = set(data) - _TOP_KEYS
    if unknown:
        raise InputError(where, sorted(unknown)[0], "is not a known field",
                         f"use only: {', '.join(sorted(_TOP_KEYS))}")
    scene_dir = path.parent
    units = data.get("units")
    if not isinstance(units, str) or not units:
        raise InputError(where, "units", "is missing", 'state the scene unit, e.g. units = "cm"')

    mesh = build_mesh(_table(data, "mesh", where), where, scene_dir)

    cam_t = _table(data, "camera", where)
    camera = Camera(
        origin=tuple(_vec(cam_t, "origin", where, "camera")),
        target=tuple(_vec(cam_t, "target", where, "camera")),
        up=tuple(_vec(cam_t, "up", where, "camera", [0, 1, 0])),
        fov_y_deg=_num(cam_t, "fov_y", where, "camera", 0, 180, lo_open=True, hi_open=True),
        width=_num(cam_t, "width", where, "camera", 1, 8192, integer=True),
        height=_num(cam_t, "height", where, "camera", 1, 8192, integer=True),
    )
    fwd = np.subtract(camera.target, camera.origin)
    if np.linalg.norm(fwd) == 0 or np.linalg.norm(np.cross(fwd, camera.up)) < 1e-9 * np.linalg.norm(fwd):
        raise InputError(where, "camera.up", "is parallel to the viewing direction (or target == origin)",
                         "choose an up vector not parallel to target - origin")

    lights_t = data.get("lights")
    if not isinstance(lights_t, list) or not lights_t:
        raise InputError(where, "lights", "needs at least one [[lights]] entry", "add a point light")
    lights = []
    for i, lt in enumerate(lights_t):
        pos = _vec(lt, "position", where, f"lights[{i}]")
        inten = np.asarray(lt.get("intensity", []), dtype=np.float64)
        if inten.shape != (3,) or not np.all(np.isfinite(inten)) or np.any(inten < 0):
            raise InputError(where, f"lights[{i}].intensity", f"must be three non-negative W/sr values, "
                             f"got {lt.get('intensity')!r}", "write e.g. [10, 10, 10]")
        lights.append(PointLight(tuple(pos), tuple(inten)))

    b_t = _table(data, "boundary", where)
    kind = b_t.get("kind")
    if kind not in BOUNDARY_KINDS:
        raise InputError(where, "boundary.kind", f"unknown kind {kind!r}", f"use one of: {', '.join(BOUNDARY_KINDS)}")
    if kind == "index-matched":
        boundary = Boundary(kind)
    else:
        boundary = Boundary(kind, eta=_num(b_t, "eta", where, "boundary", 1.0, 3.0, lo_open=True),
                            roughness=_num(b_t, "roughness", where, "boundary", 0.0, 1.0, default=0.1,
                                           lo_open=True))

    m_t = _table(data, "medium", where)
    bmin, bmax = _vec(m_t, "bbox_min", where, "medium"), _vec(m_t, "bbox_max", where, "medium")
    if np.any(bmax <= bmin):
        raise InputError(where, "medium.bbox_max", "must be larger than bbox_min on every axis", "swap or widen them")
    res = m_t.get("resolution")
    if (not isinstance(res, list) or len(res) != 3
            or not all(isinstance(r, int) and not isinstance(r, bool) and 1 <= r <= 512 for r in res)):
        raise InputError(where, "medium.resolution", f"must be three integers in [1, 512] (nx, ny, nz), got {res!r}",
                         "write e.g. [64, 64, 64]")
    extent = bmax - bmin
    if np.ptp(extent) > 1e-9 * extent.max():
        raise InputError(where, "medium.bbox_max", f"box extent {_fmt(extent)} is not a cube; SSLPV's LPV cells are "
                         "cubes over this box", "give the box the same size on every axis")
    mlo, mhi = mesh.bbox
    if np.any(mlo < bmin) or np.any(mhi > bmax):
        raise InputError(where, "medium.bbox_min/bbox_max", f"box [{_fmt(bmin)}]..[{_fmt(bmax)}] does not enclose "
                         f"the mesh [{_fmt(mlo)}]..[{_fmt(mhi)}]", "grow the box to enclose the mesh")
    grids = {}
    for name in ("sigma_t", "albedo", "g"):
        if name not in m_t:
            raise InputError(where, f"medium.{name}", "is missing", 'add e.g. {kind = "constant", value = [1, 1, 1]}')
        grids[name] = evaluate_field(m_t[name], tuple(res), bmin, bmax, where, f"medium.{name}", scene_dir)
    _check_grid("sigma_t", grids["sigma_t"], 0.0, np.inf, where)
    _check_grid("albedo", grids["albedo"], 0.0, 1.0, where)
    _check_grid("g", grids["g"], -1.0, 1.0, where, lo_open=True, hi_open=True)
    medium = Medium(bmin, bmax, **grids)

    probes = [("camera.origin", camera.origin)] + [(f"lights[{i}].position", lt.position) for i, lt in enumerate(lights)]
    inside = points_inside(mesh, np.array([p for _, p in probes]))
    for (label, p), flag in zip(probes, inside):
        if flag:
            raise InputError(where, label, f"{_fmt(p)} lies inside the mesh", "move it outside the object")

    tags = data.get("tags", [])
    if not isinstance(tags, list) or not all(isinstance(t, str) for t in tags):
        raise InputError(where, "tags", f"must be a list of strings, got {tags!r}", 'write e.g. tags = ["thin"]')
    tol = data.get("tolerances", {})
    if not isinstance(tol, dict):
        raise InputError(where, "tolerances", "must be a table", "write [tolerances]")
    scene = Scene(name=path.parent.name, path=scene_dir, units=units, description=str(data.get("description", "")),
                  mesh=mesh, camera=camera, lights=tuple(lights), boundary=boundary, medium=medium,
                  tolerances=dict(tol), tags=tuple(tags))
    return dataclasses.replace(scene, content_hash=scene_hash(scene))


def _fmt(v):
    return ", ".join(f"{float(x):g}" for x in v)
