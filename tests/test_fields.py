"""Procedural medium fields (``harness.scene.fields``) against their closed forms at chosen points.

Each field is evaluated on a small grid whose voxel centres are known by hand
(``bbox_min + (i + 0.5) / n * extent``, ``docs/conventions.md``) and compared,
voxel by voxel, with its formula written out here: a gradient is ``start`` at the
low face and ``end`` at the high face, a split is ``below`` strictly below its
position, layers cycle their values every ``period`` from the low face, veins are
``(1 - |sin(2 pi f d.x)|)^sharpness`` without turbulence. Exact up to float32.
"""

import numpy as np
import pytest

from pydantic import TypeAdapter

from harness.scene.fields import FieldSpec, evaluate_field, voxel_centres

LO, HI = np.array([-1.0, 0.0, 2.0]), np.array([3.0, 2.0, 4.0])
RES = (4, 2, 8)                                   # nx, ny, nz
#: voxel centres per axis, by hand
CENTRES = {"x": np.array([-0.5, 0.5, 1.5, 2.5]), "y": np.array([0.5, 1.5]),
           "z": 2.0 + (np.arange(8) + 0.5) * 0.25}
AXIS = {"x": 0, "y": 1, "z": 2}


def field(spec):
    """The field of a ``[medium]`` table (validated by the scene model's own FieldSpec) on the test grid."""
    model = TypeAdapter(FieldSpec).validate_python(spec)
    return evaluate_field(model, RES, LO, HI, "sigma_t", None).astype(np.float64)


def along(grid, axis):
    """The (n, 3) values along one axis (the field varies only along it)."""
    if axis == "x":
        return grid[0, 0, :, :]
    if axis == "y":
        return grid[0, :, 0, :]
    return grid[:, 0, 0, :]


def test_voxel_centres_by_hand():
    x, y, z = voxel_centres(LO, HI, RES)
    assert x.shape == (8, 2, 4)
    np.testing.assert_allclose(x[0, 0], CENTRES["x"], atol=1e-15)
    np.testing.assert_allclose(y[0, :, 0], CENTRES["y"], atol=1e-15)
    np.testing.assert_allclose(z[:, 0, 0], CENTRES["z"], atol=1e-15)


@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_gradient(axis):
    start, end = np.array([1.0, 2.0, 30.0]), np.array([5.0, 0.5, 10.0])
    grid = field({"kind": "gradient", "axis": axis, "start": start.tolist(), "end": end.tolist()})
    a = AXIS[axis]
    t = (CENTRES[axis] - LO[a]) / (HI[a] - LO[a])        # 0 at the low face, 1 at the high face
    want = (1 - t)[:, None] * start + t[:, None] * end
    err = np.abs(along(grid, axis) / want - 1).max()
    assert err <= 1e-6, f"gradient along {axis}: off by {err:.2e} (relative) from start + t (end - start)"
    # and the field does not vary across the other axes
    assert np.ptp(grid, axis=tuple(i for i in range(3) if i != 2 - a)).max() == 0.0


@pytest.mark.parametrize("axis,position", [("x", 1.0), ("x", 0.1), ("z", 3.3)])
def test_split(axis, position):
    below, above = [0.8, 0.1, 0.2], [-0.3, 0.4, 0.9]
    grid = field({"kind": "split", "axis": axis, "position": position, "below": below, "above": above})
    under = CENTRES[axis] < position
    want = np.where(under[:, None], below, above)
    wrong = np.flatnonzero(np.abs(along(grid, axis) - want).max(axis=1) > 1e-6)
    assert wrong.size == 0, (f"split along {axis} at {position}: voxel centres {CENTRES[axis][wrong]} hold the "
                             "wrong side's value")
    assert under.any() and (~under).any()


def test_layers_without_warp():
    values = [[1.0, 1.0, 1.0], [4.0, 5.0, 6.0], [9.0, 0.0, 2.0]]
    grid = field({"kind": "layers", "axis": "z", "period": 0.6, "values": values})
    index = np.floor((CENTRES["z"] - LO[2]) / 0.6).astype(int) % 3
    assert list(index) == [0, 0, 1, 1, 1, 2, 2, 0]   # offsets 0.125 + 0.25 i over 0.6
    np.testing.assert_allclose(along(grid, "z"), np.array(values)[index], rtol=1e-6)


def test_veins_without_turbulence():
    base, vein = np.array([1.0, 2.0, 3.0]), np.array([10.0, 0.0, 5.0])
    d = np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
    grid = field({"kind": "veins", "base": base.tolist(), "vein": vein.tolist(), "frequency": 0.7,
                  "sharpness": 3.0, "turbulence": 0.0, "direction": [1.0, 1.0, 0.0]})
    for k, j, i in [(0, 0, 0), (3, 1, 2), (7, 0, 3), (5, 1, 1)]:
        p = np.array([CENTRES["x"][i], CENTRES["y"][j], CENTRES["z"][k]])
        t = (1 - abs(np.sin(2 * np.pi * 0.7 * (d @ p)))) ** 3.0
        np.testing.assert_allclose(grid[k, j, i], (1 - t) * base + t * vein, rtol=1e-6, err_msg=str((k, j, i)))


def test_constant():
    grid = field({"kind": "constant", "value": [0.25, 0.5, 0.75]})
    assert grid.shape == (8, 2, 4, 3)
    np.testing.assert_array_equal(grid.reshape(-1, 3), np.tile([0.25, 0.5, 0.75], (64, 1)))
