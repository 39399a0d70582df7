"""The scene's medium as the dipole kernels see it: reduced coefficients per voxel, and one choice.

Both kernels are derived for a homogeneous half-space. For a heterogeneous medium this
package uses **the material at the exit point** (a documented limitation,
``docs/dipole_rivals.md``): the kernel between an entry point ``x_i`` and an exit point
``x_o`` takes the coefficients of the voxel that holds ``x_o - (h/2) n_o`` (``h`` the
voxel size, so the lookup lands inside the object), whatever lies between the two points.
The vertex gather takes them at each exit (scattering) vertex the same way.

:func:`scene_material` also refuses, with one line, a scene the kernels cannot represent:
a voxel inside the mesh with ``sigma_s' = 0`` (albedo 0: the dipoles' ``alpha' = 0`` leaves
no diffusion, and the directional dipole's ``d_e = 2.131 D / sqrt(alpha')`` is undefined).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from harness.errors import InputError
from harness.scene.geometry import grid_inside

__all__ = ["SceneMaterial", "scene_material", "lookup"]


@dataclass(frozen=True, eq=False)
class SceneMaterial:
    sigma_s_prime: np.ndarray    # (nz, ny, nx, 3) float64, sigma_s (1 - g)
    sigma_a: np.ndarray          # (nz, ny, nx, 3)
    sigma_t: np.ndarray          # (nz, ny, nx, 3), unreduced (the directional dipole's back-lit offset)
    inside: np.ndarray           # (nz, ny, nx) bool, voxel centre inside the mesh
    bbox_min: np.ndarray
    bbox_max: np.ndarray
    mfp: float                   # smallest reduced mean free path 1/sigma_t' inside (scene units)
    diffusion_length: float      # largest 1/sigma_tr inside (inf without absorption)
    homogeneous: bool


def scene_material(scene, method="dipole"):
    """:class:`SceneMaterial` of ``scene``, or an InputError naming why ``method`` cannot render it."""
    med = scene.medium
    st = np.asarray(med.sigma_t, dtype=np.float64)
    al = np.asarray(med.albedo, dtype=np.float64)
    g = np.asarray(med.g, dtype=np.float64)
    ss = st * al
    sa = st - ss
    sp = ss * (1.0 - g)
    nx, ny, nz = med.resolution
    inside = grid_inside(scene.mesh, med.bbox_min, med.bbox_max, (nx, ny, nz))
    if not inside.any():                               # a mesh thinner than one voxel: take every voxel
        inside = np.ones((nz, ny, nx), dtype=bool)
    sel_sp, sel_sa = sp[inside], sa[inside]
    bad = np.count_nonzero(np.any(sel_sp <= 0.0, axis=-1))
    if bad:
        worst = "albedo 0" if np.any(al[inside] <= 0.0) else "sigma_t 0" if np.any(st[inside] <= 0.0) else \
            "sigma_s (1 - g) = 0"
        raise InputError(scene.path / "scene.toml" if scene.path else scene.name, "medium.albedo",
                         f"method {method} needs a scattering medium (sigma_s' > 0) everywhere inside the mesh, "
                         f"{bad} of {int(inside.sum())} inside voxels have {worst}",
                         "render this scene with --method sslpv, or give the medium albedo > 0")
    stp = sel_sp + sel_sa
    sigma_tr = np.sqrt(3.0 * sel_sa * stp)
    mfp = float(1.0 / stp.max())
    dl = float(1.0 / sigma_tr.min()) if sigma_tr.min() > 0 else float("inf")
    homogeneous = bool(np.all(sp == sp.reshape(-1, 3)[0]) and np.all(sa == sa.reshape(-1, 3)[0]))
    return SceneMaterial(sp, sa, st, inside, np.asarray(med.bbox_min, float), np.asarray(med.bbox_max, float),
                         mfp, dl, homogeneous)


def voxel_of(mat, points, normals):
    """``(k, j, i)`` index arrays of the voxel holding ``p - (h/2) n`` for each point (clamped to the grid)."""
    nz, ny, nx = mat.inside.shape
    size = mat.bbox_max - mat.bbox_min
    h = size / np.array([nx, ny, nz], dtype=np.float64)
    p = np.asarray(points, dtype=np.float64) - 0.5 * h * np.asarray(normals, dtype=np.float64)
    idx = np.floor((p - mat.bbox_min) / size * np.array([nx, ny, nz])).astype(np.int64)
    idx = np.clip(idx, 0, np.array([nx, ny, nz]) - 1)
    return idx[..., 2], idx[..., 1], idx[..., 0]


def lookup(mat, points, normals):
    """``(sigma_s', sigma_a, sigma_t)`` at the exit points -> three (..., 3) float64 arrays."""
    k, j, i = voxel_of(mat, points, normals)
    return mat.sigma_s_prime[k, j, i], mat.sigma_a[k, j, i], mat.sigma_t[k, j, i]
