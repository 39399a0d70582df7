"""Scenes: one ``reference_scenes/<name>/scene.toml`` read once into a validated,
immutable :class:`Scene` from which both renderers are built.

A scene file is data (TOML): no ``eval``, no pickle. The format is the typed model
:class:`harness.scene.model.SceneFile`; a bad field raises
:class:`~harness.errors.InputError` with one line naming the file, the field, the
problem and the fix (:func:`harness.validation.validate`).

Top-level tables: ``units``, ``description``, ``tags``, ``[mesh]`` (``harness.scene.geometry``),
``[camera]``, ``[[lights]]``, ``[boundary]``, ``[medium]`` (fields in
``harness.scene.fields``) and ``[tolerances]``. ``reference_scenes/README.md``
documents the format with an example; ``reference_scenes/scene.schema.json`` is its
JSON Schema.
"""

import dataclasses
import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from harness import paths
from harness.errors import InputError
from harness.scene.geometry import Mesh
from harness.scene.model import MAX_CROSSINGS_DEFAULT, SMS_CHAINS_DEFAULT, SceneFile
from harness.validation import read_toml, validate

SUITE_DIR = paths.SUITE_DIR


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
    max_crossings: int = MAX_CROSSINGS_DEFAULT
    sms_trials: int = 0
    sms_chains: str = SMS_CHAINS_DEFAULT

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

    def __post_init__(self):
        # The hash is always the contents' own: a copy made with dataclasses.replace (another boundary, another
        # medium) gets its own hash, so no cache keyed by it (Mitsuba scenes, references) can serve the original's.
        object.__setattr__(self, "content_hash", scene_hash(self))

    def with_resolution(self, width, height):
        """The same scene rendered at another image size (the hash changes with the size)."""
        cam = dataclasses.replace(self.camera, width=int(width), height=int(height))
        return dataclasses.replace(self, camera=cam)

    def with_medium(self, **grids):
        """A copy with some medium grids replaced (used by tests and validation scenes)."""
        return dataclasses.replace(self, medium=dataclasses.replace(self.medium, **grids))


def _boundary_key(boundary):
    """The boundary's fields for the hash; ``max_crossings`` only where it is not the default and the
    sampling fields only where it is on, so that the content hash of every scene written before the fields
    existed stays the same."""
    key = dataclasses.asdict(boundary)
    if key.get("max_crossings") == MAX_CROSSINGS_DEFAULT:
        del key["max_crossings"]
    if key.get("sms_trials") == 0:                    # off: the chains it would sample do not matter
        del key["sms_trials"]
        key.pop("sms_chains", None)
    return key


def scene_hash(scene):
    """sha256 over everything that changes an image: geometry, camera, lights, boundary and grids."""
    h = hashlib.sha256()
    meta = {
        "units": scene.units,
        "camera": dataclasses.asdict(scene.camera),
        "lights": [dataclasses.asdict(light) for light in scene.lights],
        "boundary": _boundary_key(scene.boundary),
        "bbox": [list(map(float, scene.medium.bbox_min)), list(map(float, scene.medium.bbox_max))],
    }
    h.update(json.dumps(meta, sort_keys=True, default=float).encode())
    for arr in (scene.mesh.vertices, scene.mesh.faces, scene.mesh.normals,
                scene.medium.sigma_t, scene.medium.albedo, scene.medium.g):
        a = np.ascontiguousarray(arr)
        h.update(str((a.dtype.str, a.shape)).encode())
        h.update(a.tobytes())
    return h.hexdigest()


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


def unknown_scene_fix(name, known=None):
    """The fix of an unknown scene's message: the closest suite names first (``difflib``), then the suite."""
    import difflib

    known = list_scenes() if known is None else list(known)
    close = difflib.get_close_matches(Path(str(name)).name, known, n=2, cutoff=0.6)
    hint = f"did you mean {' or '.join(close)}? " if close else ""
    return hint + (f"the suite's scenes: {', '.join(known)}" if known else "the suite has no scenes")


def load_scene(name_or_path):
    """Read and validate a scene; see the module docstring."""
    path = scene_path(name_or_path)
    known = ", ".join(list_scenes()) or "none"
    if not path.exists():
        raise InputError(path, "scene", "no such scene file", unknown_scene_fix(name_or_path))
    data = read_toml(path, "a scene.toml", f"give a scene folder or one of the suite's scenes: {known}")
    spec = validate(SceneFile, data, path, context={"scene_dir": path.parent})
    return scene_from_model(spec, path)


def scene_from_model(spec, path):
    """The immutable :class:`Scene` of a validated :class:`~harness.scene.model.SceneFile`
    (built with a scene folder in its context); the values are converted exactly as the
    hand-written loader did, so every content hash stays the same."""
    path = Path(path)
    cam = spec.camera
    camera = Camera(origin=tuple(np.asarray(cam.origin, dtype=np.float64)),
                    target=tuple(np.asarray(cam.target, dtype=np.float64)),
                    up=tuple(np.asarray(cam.up, dtype=np.float64)), fov_y_deg=float(cam.fov_y),
                    width=int(cam.width), height=int(cam.height))
    lights = tuple(PointLight(tuple(np.asarray(lt.position, dtype=np.float64)),
                              tuple(np.asarray(lt.intensity, dtype=np.float64))) for lt in spec.lights)
    b = spec.boundary
    boundary = Boundary(b.kind) if b.kind == "index-matched" else Boundary(b.kind, eta=float(b.eta),
                                                                          roughness=float(b.roughness),
                                                                          max_crossings=int(b.max_crossings),
                                                                          sms_trials=int(b.sms_trials),
                                                                          sms_chains=str(b.sms_chains))
    medium = Medium(np.asarray(spec.medium.bbox_min, dtype=np.float64), np.asarray(spec.medium.bbox_max,
                                                                                    dtype=np.float64),
                    **spec.medium.grids)
    scene = Scene(name=path.parent.name, path=path.parent, units=spec.units, description=spec.description,
                  mesh=spec.mesh.mesh, camera=camera, lights=lights, boundary=boundary, medium=medium,
                  tolerances=spec.tolerances.model_dump(exclude_none=True), tags=tuple(spec.tags))
    return scene
