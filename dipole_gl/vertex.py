"""Hao & Varshney's per-vertex gather (ACM TOG 23(2), 2004, Secs. 2.2-2.3): the precomputation.

Three steps, all on the host, timed separately as the method's precomputation:

* ``remesh``: the *scattering vertices*. The scene mesh is remeshed isotropically
  (pymeshlab ``meshing_isotropic_explicit_remeshing``) to the edge length
  ``e = l' sqrt(2 / (sqrt(3) density))``, the edge of a uniform triangulation with
  ``density`` vertices per ``l'^2``. Each vertex represents one third of the area of its
  triangles (the paper's ``Delta A(x_i)`` for non-uniform vertices).
* ``neighbourhoods``: for each scattering vertex ``x_o``, every other vertex ``x_i`` with
  ``|x_i - x_o| <= range / sigma_tr`` (the paper's scattering neighbourhood ``N(x_o)``,
  its ``RANGE``), as compressed rows. The vertex itself is skipped, as in the paper's
  ``Find-Scalar-Integral`` (``if x_i == x_o ... skip``). For the standard dipole the
  factor ``R_d(|x_i - x_o|) / pi`` (Sec. 3.1's ``(1/pi) R_d``; the area is folded into
  the run-time flux) is precomputed per pair and colour; the directional dipole depends
  on the light direction, so only the neighbourhood is precomputed and the kernel is
  evaluated per frame (the paper's answer, precomputing per quantized light direction,
  Secs. 3.1-3.3, is not done).
* ``display``: the scene mesh is what the camera sees (so the image's coverage matches the
  reference); each of its vertices takes the barycentric weights of the closest point on
  the scattering mesh (as the paper's reference points, Sec. 4.2, take the barycentric
  weights of their simplified triangle), and the per-vertex result is interpolated across
  each triangle by the rasteriser (Gouraud, Sec. 3.2).

Per frame (``dipole_gl.renderer``): irradiance at the scattering vertices (shadow maps),
the neighbourhood sums, the transfer to the display vertices, the raster pass.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from harness.errors import InputError

from . import kernels
from .medium import lookup

__all__ = ["VertexPrecomp", "precompute", "edge_length", "MAX_PAIRS"]

#: A neighbourhood table with more (exit, entry) pairs than this is refused.
MAX_PAIRS = 30_000_000


def edge_length(density, mfp):
    """Edge of a uniform triangulation with ``density`` vertices per ``mfp^2`` (area per vertex ``sqrt(3)/2 e^2``)."""
    return float(mfp * math.sqrt(2.0 / (math.sqrt(3.0) * density)))


@dataclass(eq=False)
class VertexPrecomp:
    positions: np.ndarray        # (V, 3) scattering vertices
    normals: np.ndarray          # (V, 3)
    areas: np.ndarray            # (V,) one third of the adjacent triangles' area
    faces: np.ndarray            # (F, 3) of the scattering mesh
    offsets: np.ndarray          # (V + 1,) int64 rows of the neighbourhood table
    neighbours: np.ndarray       # (P,) int32 entry vertex of each pair
    factors: np.ndarray | None   # (P, 3) float32 R_d(r)/pi per pair (standard dipole), else None
    display_index: np.ndarray    # (D, 3) int32 scattering vertices of each display vertex
    display_weights: np.ndarray  # (D, 3) float64 barycentric weights
    radius: float                # the neighbourhood radius (scene units)
    edge: float                  # the target edge length
    times_ms: dict = field(default_factory=dict)
    density: float | None = None  # the vertex density it was made for (vertices per l'^2)

    @property
    def pairs(self):
        return int(self.offsets[-1])


def _remesh(mesh, edge):
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int32)))
    ms.meshing_merge_close_vertices()                  # the box's per-face vertices become one mesh
    ms.meshing_isotropic_explicit_remeshing(targetlen=pymeshlab.PureValue(edge), iterations=6)
    ms.compute_normal_per_vertex()
    m = ms.current_mesh()
    v = np.asarray(m.vertex_matrix(), dtype=np.float64)
    f = np.asarray(m.face_matrix(), dtype=np.int64)
    n = np.asarray(m.vertex_normal_matrix(), dtype=np.float64)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    tri = v[f]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    va = np.zeros(len(v))
    for k in range(3):
        np.add.at(va, f[:, k], area / 3.0)
    return v, n, va, f


def _neighbourhoods(pos, radius, chunk=512):
    V = len(pos)
    rows, counts = [], np.zeros(V, dtype=np.int64)
    for s in range(0, V, chunk):
        d2 = np.sum((pos[s:s + chunk, None, :] - pos[None, :, :]) ** 2, axis=-1)
        near = d2 <= radius * radius
        near[np.arange(near.shape[0]), np.arange(s, s + near.shape[0])] = False   # the vertex itself: skipped
        counts[s:s + chunk] = near.sum(axis=1)
        if counts.sum() > MAX_PAIRS:
            raise InputError("--range", "range", f"the neighbourhood table would exceed {MAX_PAIRS:,} pairs",
                             "lower --range or --density")
        rows.append(np.nonzero(near)[1].astype(np.int32))
    offsets = np.concatenate([[0], np.cumsum(counts)])
    return offsets, np.concatenate(rows) if rows else np.zeros(0, np.int32)


def _display_weights(points, sv, sf, k=8):
    """Per display point: the 3 vertices and barycentric weights of the closest point on the scattering mesh."""
    from scipy.spatial import cKDTree

    tri = sv[sf]                                          # (F, 3, 3)
    tree = cKDTree(tri.mean(axis=1))
    _, cand = tree.query(points, k=min(k, len(sf)))
    cand = np.atleast_2d(cand)
    if cand.shape[0] != len(points):
        cand = cand.T
    a, b, c = (tri[cand][..., i, :] for i in range(3))    # (D, k, 3)
    p = np.asarray(points, dtype=np.float64)[:, None, :]
    e0, e1, q = b - a, c - a, p - a
    d00, d01, d11 = (np.sum(x * y, axis=-1) for x, y in ((e0, e0), (e0, e1), (e1, e1)))
    d20, d21 = np.sum(q * e0, axis=-1), np.sum(q * e1, axis=-1)
    den = d00 * d11 - d01 * d01
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    bary = np.clip(np.stack([1.0 - v - w, v, w], axis=-1), 0.0, None)
    bary /= bary.sum(axis=-1, keepdims=True)              # the clamped projection: a point of the triangle
    closest = bary[..., 0:1] * a + bary[..., 1:2] * b + bary[..., 2:3] * c
    best = np.argmin(np.sum((closest - p) ** 2, axis=-1), axis=1)
    rows = np.arange(len(points))
    return sf[cand[rows, best]].astype(np.int32), bary[rows, best]


def precompute(scene, mat, kernel, density, range_, eta):
    """:class:`VertexPrecomp` of ``scene`` for one kernel, vertex density and range."""
    times = {}
    t = time.perf_counter()
    edge = edge_length(density, mat.mfp)
    pos, nrm, area, faces = _remesh(scene.mesh, edge)
    times["remesh"] = (time.perf_counter() - t) * 1e3
    t = time.perf_counter()
    radius = range_ * mat.diffusion_length
    if not math.isfinite(radius):                         # no absorption: every vertex is a neighbour
        radius = float(np.linalg.norm(pos.max(axis=0) - pos.min(axis=0))) * 2.0
    offsets, nbr = _neighbourhoods(pos, radius)
    factors = None
    if kernel == "dipole":
        sp, sa, st = lookup(mat, pos, nrm)
        m = kernels.material(sp, sa, eta, sigma_t=st)
        factors = np.empty((len(nbr), 3), dtype=np.float32)
        for o0 in range(0, len(pos), 256):                # the material of each exit vertex, in chunks
            o1 = min(o0 + 256, len(pos))
            lo, hi = offsets[o0], offsets[o1]
            exit_of = np.repeat(np.arange(o0, o1), np.diff(offsets[o0:o1 + 1]))
            r = np.linalg.norm(pos[exit_of] - pos[nbr[lo:hi]], axis=1)
            mp = {k: m[k][exit_of] for k in ("alpha_prime", "sigma_tr", "z_r", "z_v")}
            factors[lo:hi] = kernels.rd_dipole(r[:, None], mp) / np.pi
    times["neighbourhoods"] = (time.perf_counter() - t) * 1e3
    t = time.perf_counter()
    idx, w = _display_weights(scene.mesh.vertices, pos, faces)
    times["display"] = (time.perf_counter() - t) * 1e3
    return VertexPrecomp(pos, nrm, area, faces, offsets, nbr, factors, idx, w, float(radius), edge, times,
                         float(density))
