"""Closed triangle meshes: procedural shapes (pymeshlab), files, and the two
geometric queries the harness needs: is the mesh closed, and which points lie
inside it.

Mesh kinds accepted in ``scene.toml``'s ``[mesh]`` table:

============  =====================================================================
kind          parameters (defaults)
============  =====================================================================
``sphere``    ``radius`` (1.0), ``center`` ([0,0,0]), ``subdivisions`` (4)
``torus``     ``major_radius`` (0.8), ``minor_radius`` (0.25), ``center``,
              ``rotate_x_deg`` (0), ``segments`` ([96, 32]); axis is z before rotation
``box``       ``size`` ([1,1,1]), ``center``; faces carry flat normals
``file``      ``path`` (PLY/OBJ inside the scene folder), ``scale`` (1.0), ``translate``
============  =====================================================================

Inside/outside uses ray parity along +x; two independent voxelisations
(pymeshlab signed distance and Mitsuba ray parity) agreed on every cell of a
torus (``../shared/NOTES.md``).
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np
# Imported here, not lazily inside a function: the first import loads MeshLab's Qt plugins,
# and they must be loaded on a process's main thread (see harness.runs.sweep.ReleaseGL).
import pymeshlab

from harness.errors import InputError

MESH_KINDS = ("sphere", "torus", "box", "file")


@dataclass(frozen=True, eq=False)
class Mesh:
    vertices: np.ndarray  # (V, 3) float64, scene units
    faces: np.ndarray     # (F, 3) int32, counter-clockwise seen from outside
    normals: np.ndarray   # (V, 3) float64, outward, unit length

    @property
    def bbox(self):
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    def triangles(self):
        return self.vertices[self.faces]


def _vec3(spec, key, default, where):
    value = spec.get(key, default)
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise InputError(where, f"mesh.{key}", f"must be three finite numbers, got {value!r}", "write e.g. [0, 0, 0]")
    return arr


def _positive(spec, key, default, where):
    value = spec.get(key, default)
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not np.isfinite(value) or value <= 0:
        raise InputError(where, f"mesh.{key}", f"must be a positive number, got {value!r}", "use a value > 0")
    return float(value)


def _integer(spec, key, default, lo, hi, where):
    value = spec.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise InputError(where, f"mesh.{key}", f"must be an integer in [{lo}, {hi}], got {value!r}", "change the value")
    return value


def _number(spec, key, default, where):
    value = spec.get(key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise InputError(where, f"mesh.{key}", f"must be a finite number, got {value!r}", "change the value")
    return float(value)


def _from_meshset(ms):
    m = ms.current_mesh()
    return np.asarray(m.vertex_matrix(), dtype=np.float64), np.asarray(m.face_matrix(), dtype=np.int32)


def _vertex_normals(vertices, faces):
    """Area-weighted vertex normals (cross products are twice the face area)."""
    tri = vertices[faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    vn = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(vn, faces[:, k], fn)
    return vn / np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-300)


def _box(size, center):
    # Split vertices per face so that each face keeps its flat normal; a welded
    # 8-vertex cube would interpolate diagonal normals across every face.
    verts, faces, normals = [], [], []
    half = np.asarray(size) / 2
    for axis in range(3):
        for sign in (-1.0, 1.0):
            n = np.zeros(3)
            n[axis] = sign
            u, v = [a for a in range(3) if a != axis]
            quad = []
            for du, dv in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p = np.zeros(3)
                p[axis], p[u], p[v] = sign * half[axis], du * half[u], dv * half[v]
                quad.append(p + center)
            base = len(verts)
            verts += quad
            normals += [n] * 4
            tri = [(0, 1, 2), (0, 2, 3)]
            # Orient counter-clockwise seen from outside.
            if np.dot(np.cross(quad[1] - quad[0], quad[2] - quad[0]), n) < 0:
                tri = [(0, 2, 1), (0, 3, 2)]
            faces += [(base + a, base + b, base + c) for a, b, c in tri]
    return np.array(verts), np.array(faces, dtype=np.int32), np.array(normals)


def build_mesh(spec, where, scene_dir):
    """Build the mesh described by the ``[mesh]`` table; refuse open meshes."""
    kind = spec.get("kind")
    if kind not in MESH_KINDS:
        raise InputError(where, "mesh.kind", f"unknown kind {kind!r}", f"use one of: {', '.join(MESH_KINDS)}")
    center = _vec3(spec, "center", [0, 0, 0], where)
    ms = pymeshlab.MeshSet()
    normals = None
    if kind == "sphere":
        subdiv = _integer(spec, "subdivisions", 4, 1, 6, where)
        ms.create_sphere(radius=_positive(spec, "radius", 1.0, where), subdiv=subdiv)
        v, f = _from_meshset(ms)
        v = v + center
    elif kind == "torus":
        major, minor = _positive(spec, "major_radius", 0.8, where), _positive(spec, "minor_radius", 0.25, where)
        if minor >= major:
            raise InputError(where, "mesh.minor_radius", f"{minor} must be smaller than major_radius {major}",
                             "lower minor_radius")
        segments = spec.get("segments", [96, 32])
        if (not isinstance(segments, list) or len(segments) != 2
                or not all(isinstance(n, int) and not isinstance(n, bool) and 3 <= n <= 1024 for n in segments)):
            raise InputError(where, "mesh.segments", f"must be two integers in [3, 1024], got {segments!r}",
                             "write e.g. [96, 32]")
        ms.create_torus(hradius=major, vradius=minor, hsubdiv=segments[0], vsubdiv=segments[1])
        v, f = _from_meshset(ms)
        angle = np.radians(_number(spec, "rotate_x_deg", 0.0, where))
        c, s = np.cos(angle), np.sin(angle)
        v = v @ np.array([[1, 0, 0], [0, c, s], [0, -s, c]]) + center
    elif kind == "box":
        v, f, normals = _box(_vec3(spec, "size", [1, 1, 1], where), center)
    else:
        path = resolve_inside(scene_dir, spec.get("path"), where, "mesh.path")
        try:
            ms.load_new_mesh(str(path))
        except Exception as exc:
            raise InputError(where, "mesh.path", f"cannot read {path.name} ({exc})", "give a PLY or OBJ file") from exc
        v, f = _from_meshset(ms)
        v = v * _positive(spec, "scale", 1.0, where) + _vec3(spec, "translate", [0, 0, 0], where)
    if len(f) == 0:
        raise InputError(where, "mesh", "has no faces", "give a closed triangle mesh")
    check_closed(v, f, where)
    if normals is None:
        normals = _vertex_normals(v, f)
    mesh = Mesh(v, f, normals)
    if signed_volume(mesh) < 0:
        mesh = Mesh(v, f[:, ::-1].copy(), -normals)
    return mesh


def check_closed(vertices, faces, where):
    """Raise unless the mesh (after welding coincident vertices) is closed and two-manifold."""
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=vertices, face_matrix=faces))
    ms.meshing_merge_close_vertices(threshold=pymeshlab.PercentageValue(1e-4))
    topo = ms.get_topological_measures()
    if topo["boundary_edges"] > 0 or not topo["is_mesh_two_manifold"]:
        raise InputError(where, "mesh", f"is not closed ({topo['boundary_edges']} boundary edges, "
                         f"two-manifold={topo['is_mesh_two_manifold']})",
                         "close the holes, e.g. with MeshLab's 'Close Holes', so inside and outside are defined")


def signed_volume(mesh):
    tri = mesh.triangles()
    return float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0)


def resolve_inside(scene_dir, rel, where, field):
    """Resolve a file named in a scene; refuse missing files and paths that leave the folder."""
    if not isinstance(rel, str) or not rel:
        raise InputError(where, field, "must name a file", "give a path relative to the scene folder")
    scene_dir = Path(scene_dir).resolve()
    path = (scene_dir / rel).resolve()
    if not path.is_relative_to(scene_dir):
        raise InputError(where, field, f"path {rel!r} leaves the scene folder", "put the file inside the scene folder")
    if not path.is_file():
        raise InputError(where, field, f"file {rel!r} does not exist", "check the name or add the file")
    return path


# A direction off every axis and diagonal, so parity rays do not graze edges of
# axis-aligned boxes or pass exactly through tessellation vertices.
_JITTER = np.array([0.0, 1.3719e-7, 2.7183e-7])


def _x_crossings(tri, y, z):
    """x coordinates where the line {(t, y, z)} crosses each triangle (NaN where it misses)."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    # Barycentric coordinates of (y, z) in the triangle projected on the yz plane.
    d = (b[:, 1] - a[:, 1]) * (c[:, 2] - a[:, 2]) - (c[:, 1] - a[:, 1]) * (b[:, 2] - a[:, 2])
    with np.errstate(divide="ignore", invalid="ignore"):
        w1 = ((y - a[:, 1]) * (c[:, 2] - a[:, 2]) - (c[:, 1] - a[:, 1]) * (z - a[:, 2])) / d
        w2 = ((b[:, 1] - a[:, 1]) * (z - a[:, 2]) - (y - a[:, 1]) * (b[:, 2] - a[:, 2])) / d
        w0 = 1 - w1 - w2
        hit = (d != 0) & (w0 >= 0) & (w1 >= 0) & (w2 >= 0)
        x = w0 * a[:, 0] + w1 * b[:, 0] + w2 * c[:, 0]
    return np.where(hit, x, np.nan)


def points_inside(mesh, points):
    """Boolean array: which of ``points`` (P, 3) lie inside the closed mesh (ray parity along +x)."""
    tri = mesh.triangles()
    pts = np.atleast_2d(np.asarray(points, dtype=np.float64)) + _JITTER
    out = np.zeros(len(pts), dtype=bool)
    for i, (px, py, pz) in enumerate(pts):
        xs = _x_crossings(tri, py, pz)
        out[i] = np.count_nonzero(xs > px) % 2 == 1
    return out


def grid_inside(mesh, bbox_min, bbox_max, n):
    """Inside mask of the cell centres of an ``n``-cube grid over the box, shape (n, n, n) as [z, y, x]."""
    nx, ny, nz = (n, n, n) if np.isscalar(n) else n
    lo, hi = np.asarray(bbox_min, float), np.asarray(bbox_max, float)
    xs = lo[0] + (np.arange(nx) + 0.5) / nx * (hi[0] - lo[0])
    ys = lo[1] + (np.arange(ny) + 0.5) / ny * (hi[1] - lo[1]) + _JITTER[1]
    zs = lo[2] + (np.arange(nz) + 0.5) / nz * (hi[2] - lo[2]) + _JITTER[2]
    tri = mesh.triangles()
    # Only triangles whose yz extent covers a line can cross it: prefilter per row.
    tmin, tmax = tri.min(axis=1), tri.max(axis=1)
    mask = np.zeros((nz, ny, nx), dtype=bool)
    for k, z in enumerate(zs):
        rows = (tmin[:, 2] <= z) & (tmax[:, 2] >= z)
        tz = tri[rows]
        if len(tz) == 0:
            continue
        for j, y in enumerate(ys):
            sel = (tz[:, :, 1].min(axis=1) <= y) & (tz[:, :, 1].max(axis=1) >= y)
            if not sel.any():
                continue
            xc = _x_crossings(tz[sel], y, z)
            xc = np.sort(xc[np.isfinite(xc)])
            # Cells with an odd number of crossings to their right are inside.
            mask[k, j] = (len(xc) - np.searchsorted(xc, xs, side="right")) % 2 == 1
    return mask
