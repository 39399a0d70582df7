"""Material fields of a scene: constants, named procedural fields and ``.npz`` grids.

Every field evaluates to a float32 grid of shape ``(nz, ny, nx, 3)`` over the
medium box, sampled at the voxel centres (``docs/conventions.md``). Procedural
fields are deterministic functions of their parameters and ``seed``. Each kind is a
typed model below (one table of ``[medium]``: ``sigma_t``, ``albedo`` or ``g``).

==========  ============================================================================
kind        parameters
==========  ============================================================================
constant    ``value`` (RGB)
gradient    ``axis`` (x|y|z), ``start``, ``end`` (RGB at the box's low and high face)
split       ``axis``, ``position`` (world coordinate), ``below``, ``above`` (RGB)
layers      ``axis``, ``period`` (scene units), ``values`` (list of RGB, cycled),
            ``warp`` (amplitude of a seeded noise displacement, 0), ``seed``
veins       ``base``, ``vein`` (RGB), ``frequency`` (1/scene units), ``sharpness``
            (exponent, 8), ``turbulence`` (2.0), ``direction`` ([1,1,0], not zero), ``seed``
npz         ``file`` (inside the scene folder), ``key`` (array name, 'data'); the
            array is (nz, ny, nx, 3) or (nz, ny, nx) (grey)
==========  ============================================================================

An RGB value is three numbers, or one number for grey.
"""

from typing import Annotated, Literal, Union

import numpy as np
from pydantic import BeforeValidator, Field, WithJsonSchema, field_validator
from scipy import ndimage

from harness.scene.geometry import resolve_inside
from harness.validation import FieldProblem, InputModel, Positive, Vec3

FIELD_KINDS = ("constant", "gradient", "split", "layers", "veins", "npz")
_AXES = {"x": 0, "y": 1, "z": 2}


def _grey_to_rgb(value):
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return [value, value, value]
    return value


#: Three numbers, or one number for all three channels.
RGB = Annotated[list[float], Field(min_length=3, max_length=3), BeforeValidator(_grey_to_rgb),
                WithJsonSchema({"anyOf": [{"type": "number"},
                                          {"type": "array", "items": {"type": "number"}, "minItems": 3,
                                           "maxItems": 3}]})]
Axis = Literal["x", "y", "z"]
Seed = Annotated[int, Field(ge=0, le=2**32 - 1)]
_AXIS = Field("y", description="axis the field varies along", examples=["y"])
_SEED = Field(0, description="seed of the procedural noise", examples=[7])


class ConstantField(InputModel):
    kind: Literal["constant"]
    value: RGB = Field(description="RGB value everywhere", examples=[[1.0, 1.0, 1.0]])


class GradientField(InputModel):
    kind: Literal["gradient"]
    axis: Axis = _AXIS
    start: RGB = Field(description="RGB at the box's low face", examples=[[1.0, 1.0, 1.0]])
    end: RGB = Field(description="RGB at the box's high face", examples=[[2.0, 2.0, 2.0]])


class SplitField(InputModel):
    kind: Literal["split"]
    axis: Axis = _AXIS
    position: float = Field(0.0, description="world coordinate of the split plane", examples=[0.0])
    below: RGB = Field(description="RGB below the plane", examples=[[0.8, 0.8, 0.8]])
    above: RGB = Field(description="RGB above the plane", examples=[[-0.3, -0.3, -0.3]])


class LayersField(InputModel):
    kind: Literal["layers"]
    axis: Axis = _AXIS
    period: Positive = Field(0.25, description="layer thickness, scene units", examples=[0.35])
    values: Annotated[list[RGB], Field(min_length=2)] = Field(
        description="RGB of each layer, cycled", examples=[[[9.0, 9.0, 9.0], [4.0, 5.0, 6.0]]])
    warp: float = Field(0.0, description="amplitude of a seeded noise displacement of the layers", examples=[0.08])
    seed: Seed = _SEED


class VeinsField(InputModel):
    kind: Literal["veins"]
    base: RGB = Field(description="RGB of the matrix", examples=[[9.0, 9.0, 9.0]])
    vein: RGB = Field(description="RGB of the veins", examples=[[3.0, 3.0, 3.0]])
    frequency: float = Field(3.0, description="veins per scene unit along direction", examples=[1.2])
    sharpness: Positive = Field(8.0, description="exponent that thins the veins", examples=[6.0])
    turbulence: float = Field(2.0, description="amplitude of the seeded noise that bends the veins", examples=[1.5])
    direction: Vec3 = Field([1.0, 1.0, 0.0], description="direction across the veins (not zero)",
                            examples=[[1.0, 0.6, 0.3]])
    seed: Seed = _SEED

    @field_validator("direction")
    @classmethod
    def _not_zero(cls, v):
        if not np.linalg.norm(np.asarray(v, float)) > 0:
            raise FieldProblem((), f"{v} has no direction (its length is 0)", "write e.g. direction = [1.0, 1.0, 0.0]")
        return v


class NpzField(InputModel):
    kind: Literal["npz"]
    file: Annotated[str, Field(min_length=1)] = Field(description=".npz file inside the scene folder",
                                                      examples=["sigma_t.npz"])
    key: Annotated[str, Field(min_length=1)] = Field("data", description="name of the array in the file",
                                                     examples=["data"])


FieldSpec = Annotated[Union[ConstantField, GradientField, SplitField, LayersField, VeinsField, NpzField],
                      Field(discriminator="kind")]


def _rgb(value):
    return np.broadcast_to(np.asarray(value, dtype=np.float64), (3,)).astype(np.float64)


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


def evaluate_field(spec, resolution, bbox_min, bbox_max, name, scene_dir):
    """Evaluate one validated field model of ``[medium]`` (``name``: ``sigma_t``, ...) into an
    (nz, ny, nx, 3) float32 grid; a :class:`FieldProblem` names ``name.<key>`` for a bad file."""
    nx, ny, nz = resolution
    x, y, z = voxel_centres(bbox_min, bbox_max, resolution)
    pos = (x, y, z)
    lo, hi = np.asarray(bbox_min, float), np.asarray(bbox_max, float)
    kind = spec.kind
    if kind == "constant":
        out = np.broadcast_to(_rgb(spec.value), (nz, ny, nx, 3))
    elif kind == "gradient":
        a = _AXES[spec.axis]
        t = ((pos[a] - lo[a]) / (hi[a] - lo[a]))[..., None]
        out = (1 - t) * _rgb(spec.start) + t * _rgb(spec.end)
    elif kind == "split":
        a = _AXES[spec.axis]
        out = np.where((pos[a] < float(spec.position))[..., None], _rgb(spec.below), _rgb(spec.above))
    elif kind == "layers":
        a = _AXES[spec.axis]
        colours = np.array([_rgb(v) for v in spec.values])
        warp = float(spec.warp) * value_noise(resolution, 4, int(spec.seed))
        index = np.floor((pos[a] - lo[a] + warp) / float(spec.period)).astype(int) % len(colours)
        out = colours[index]
    elif kind == "veins":
        direction = np.asarray(spec.direction, float)
        direction = direction / np.linalg.norm(direction)
        turb = float(spec.turbulence) * value_noise(resolution, 6, int(spec.seed))
        phase = 2 * np.pi * float(spec.frequency) * (direction[0] * x + direction[1] * y + direction[2] * z) \
            + turb * np.pi
        # Marble: thin bright veins where the turbulent sine crosses zero.
        t = (1 - np.abs(np.sin(phase))) ** float(spec.sharpness)
        t = t[..., None]
        out = (1 - t) * _rgb(spec.base) + t * _rgb(spec.vein)
    else:
        out = _read_npz(spec, resolution, name, scene_dir)
    return np.ascontiguousarray(out, dtype=np.float32)


def _read_npz(spec, resolution, name, scene_dir):
    nx, ny, nz = resolution
    path = resolve_inside(scene_dir, spec.file, (name, "file"))
    try:
        with np.load(path, allow_pickle=False) as data:
            if spec.key not in data:
                raise FieldProblem((name, "key"), f"{path.name} has no array {spec.key!r} "
                                   f"(it has {', '.join(data.files) or 'none'})", "name an array in the file")
            arr = np.asarray(data[spec.key], dtype=np.float64)
    except FieldProblem:
        raise
    except Exception as exc:  # not a zip, a pickled object array, a non-numeric array
        raise FieldProblem((name, "file"), f"cannot read {path.name} as .npz ({str(exc).splitlines()[0]})",
                           "save it with numpy.savez") from exc
    if arr.ndim == 3:
        arr = np.repeat(arr[..., None], 3, axis=-1)
    if arr.shape != (nz, ny, nx, 3):
        raise FieldProblem((name, "file"), f"{path.name}[{spec.key}] has shape {arr.shape}, but medium.resolution "
                           f"{list(resolution)} needs {(nz, ny, nx, 3)} ([z, y, x, rgb])",
                           "resample the grid or change medium.resolution")
    return arr
