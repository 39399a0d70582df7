"""Material fields of a scene: constants, named procedural fields and ``.npz`` grids.

Every field evaluates to a float32 grid of shape ``(nz, ny, nx, 3)`` over the
medium box, sampled at the voxel centres (``docs/conventions.md``). Procedural
fields are deterministic functions of their parameters and ``seed``.

==========  ============================================================================
kind        parameters
==========  ============================================================================
constant    ``value`` (RGB)
gradient    ``axis`` (x|y|z), ``start``, ``end`` (RGB at the box's low and high face)
split       ``axis``, ``position`` (world coordinate), ``below``, ``above`` (RGB)
layers      ``axis``, ``period`` (scene units), ``values`` (list of RGB, cycled),
            ``warp`` (amplitude of a seeded noise displacement, 0), ``seed``
veins       ``base``, ``vein`` (RGB), ``frequency`` (1/scene units), ``sharpness``
            (exponent, 8), ``turbulence`` (2.0), ``direction`` ([1,1,0]), ``seed``
npz         ``file`` (inside the scene folder), ``key`` (array name, 'data'); the
            array is (nz, ny, nx, 3) or (nz, ny, nx) (grey)
==========  ============================================================================
"""

import numpy as np
from scipy import ndimage

from harness.errors import InputError
from harness.scene.geometry import resolve_inside

FIELD_KINDS = ("constant", "gradient", "split", "layers", "veins", "npz")
_AXES = {"x": 0, "y": 1, "z": 2}


def _rgb(spec, key, where, field):
    value = spec.get(key)
    arr = np.asarray(value, dtype=np.float64) if value is not None else None
    if arr is None or arr.shape not in ((3,), ()) or not np.all(np.isfinite(arr)):
        raise InputError(where, f"{field}.{key}", f"must be an RGB triple of finite numbers, got {value!r}",
                         "write e.g. [1.0, 0.5, 0.25]")
    return np.broadcast_to(arr, (3,)).astype(np.float64)


def _axis(spec, where, field):
    axis = spec.get("axis", "y")
    if axis not in _AXES:
        raise InputError(where, f"{field}.axis", f"unknown axis {axis!r}", "use x, y or z")
    return _AXES[axis]


def voxel_centres(bbox_min, bbox_max, resolution):
    """World coordinates of voxel centres as three (nz, ny, nx) arrays (x, y, z)."""
    nx, ny, nz = resolution
    lo, hi = np.asarray(bbox_min, float), np.asarray(bbox_max, float)
    axes = [lo[a] + (np.arange(n) + 0.5) / n * (hi[a] - lo[a]) for a, n in enumerate((nx, ny, nz))]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    return x, y, z


def value_noise(resolution, cells, seed):
    """Seeded smooth noise in [-1, 1]: a random lattice of ``cells`` per axis, cubic-interpolated."""
    rng = np.random.default_rng(seed)
    lattice = rng.uniform(-1.0, 1.0, size=(cells + 3,) * 3)
    nx, ny, nz = resolution
    coords = np.meshgrid(*[1 + (np.arange(n) + 0.5) / n * cells for n in (nz, ny, nx)], indexing="ij")
    return ndimage.map_coordinates(lattice, coords, order=3, mode="nearest")


def evaluate_field(spec, resolution, bbox_min, bbox_max, where, field, scene_dir):
    """Evaluate one field table of ``[medium]`` into an (nz, ny, nx, 3) float32 grid."""
    if not isinstance(spec, dict):
        raise InputError(where, field, f"must be a table with a 'kind', got {spec!r}",
                         'write e.g. {kind = "constant", value = [1, 1, 1]}')
    kind = spec.get("kind")
    nx, ny, nz = resolution
    x, y, z = voxel_centres(bbox_min, bbox_max, resolution)
    pos = (x, y, z)
    lo, hi = np.asarray(bbox_min, float), np.asarray(bbox_max, float)
    if kind == "constant":
        out = np.broadcast_to(_rgb(spec, "value", where, field), (nz, ny, nx, 3))
    elif kind == "gradient":
        a = _axis(spec, where, field)
        t = ((pos[a] - lo[a]) / (hi[a] - lo[a]))[..., None]
        out = (1 - t) * _rgb(spec, "start", where, field) + t * _rgb(spec, "end", where, field)
    elif kind == "split":
        a = _axis(spec, where, field)
        position = float(spec.get("position", 0.0))
        out = np.where((pos[a] < position)[..., None], _rgb(spec, "below", where, field),
                       _rgb(spec, "above", where, field))
    elif kind == "layers":
        a = _axis(spec, where, field)
        values = spec.get("values")
        if not isinstance(values, list) or len(values) < 2:
            raise InputError(where, f"{field}.values", "needs at least two RGB values", "list two or more triples")
        colours = np.array([_rgb({"v": v}, "v", where, f"{field}.values") for v in values])
        period = float(spec.get("period", 0.25))
        if period <= 0:
            raise InputError(where, f"{field}.period", f"must be > 0, got {period}", "use a positive length")
        warp = float(spec.get("warp", 0.0)) * value_noise(resolution, 4, int(spec.get("seed", 0)))
        index = np.floor((pos[a] - lo[a] + warp) / period).astype(int) % len(colours)
        out = colours[index]
    elif kind == "veins":
        direction = np.asarray(spec.get("direction", [1.0, 1.0, 0.0]), float)
        direction = direction / np.linalg.norm(direction)
        freq = float(spec.get("frequency", 3.0))
        turb = float(spec.get("turbulence", 2.0)) * value_noise(resolution, 6, int(spec.get("seed", 0)))
        phase = 2 * np.pi * freq * (direction[0] * x + direction[1] * y + direction[2] * z) + turb * np.pi
        # Marble: thin bright veins where the turbulent sine crosses zero.
        t = (1 - np.abs(np.sin(phase))) ** float(spec.get("sharpness", 8.0))
        t = t[..., None]
        out = (1 - t) * _rgb(spec, "base", where, field) + t * _rgb(spec, "vein", where, field)
    elif kind == "npz":
        path = resolve_inside(scene_dir, spec.get("file"), where, f"{field}.file")
        key = spec.get("key", "data")
        try:
            with np.load(path, allow_pickle=False) as data:
                if key not in data:
                    raise InputError(where, f"{field}.key", f"{path.name} has no array {key!r} "
                                     f"(it has {', '.join(data.files)})", "name an array in the file")
                arr = np.asarray(data[key], dtype=np.float64)
        except InputError:
            raise
        except Exception as exc:
            raise InputError(where, f"{field}.file", f"cannot read {path.name} as .npz ({exc})",
                             "save it with numpy.savez") from exc
        if arr.ndim == 3:
            arr = np.repeat(arr[..., None], 3, axis=-1)
        if arr.shape != (nz, ny, nx, 3):
            raise InputError(where, f"{field}.file", f"{path.name}[{key}] has shape {arr.shape}, but "
                             f"medium.resolution {list(resolution)} needs {(nz, ny, nx, 3)} ([z, y, x, rgb])",
                             "resample the grid or change medium.resolution")
        out = arr
    else:
        raise InputError(where, f"{field}.kind", f"unknown kind {kind!r}", f"use one of: {', '.join(FIELD_KINDS)}")
    return np.ascontiguousarray(out, dtype=np.float32)
