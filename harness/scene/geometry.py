"""Closed triangle meshes: the ``[mesh]`` table's typed models, procedural shapes
(pymeshlab), files, the optional repair of files with holes, and the two geometric
queries the harness needs: is the mesh closed, and which points lie inside it.

Mesh kinds accepted in ``scene.toml``'s ``[mesh]`` table (one model each, below):

============  =====================================================================
kind          parameters (defaults)
============  =====================================================================
``sphere``    ``radius`` (1.0), ``center`` ([0,0,0]), ``subdivisions`` (4)
``torus``     ``major_radius`` (0.8), ``minor_radius`` (0.25), ``center``,
              ``rotate_x_deg`` (0), ``segments`` ([96, 32]); axis is z before rotation
``box``       ``size`` ([1,1,1]), ``center``; faces carry flat normals
``file``      ``path`` (PLY/OBJ inside the scene folder), ``scale`` (1.0), ``translate``,
              ``repair`` (none; ``"close-holes"`` closes holes with pymeshlab)
============  =====================================================================

Every mesh must be closed and two-manifold, or inside and outside are undefined.
``repair = "close-holes"`` (opt-in, files only) welds coincident vertices, removes
unreferenced ones and closes holes of up to :data:`MAX_HOLE_EDGES` edges with
pymeshlab (``meshing_close_holes``, self-intersection test off, repeated while it
helps: one pass leaves a last small hole on the Stanford bunny, ``../shared/NOTES.md``).
A mesh that is still open afterwards is refused. What the repair changed is kept in
:attr:`Mesh.repair` and written into each reference's ``reference.json``.

Inside/outside uses ray parity along +x; two independent voxelisations
(pymeshlab signed distance and Mitsuba ray parity) agreed on every cell of a
torus (``../shared/NOTES.md``).
"""

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal, Optional, Union

import numpy as np
# Imported here, not lazily inside a function: the first import loads MeshLab's Qt plugins,
# and they must be loaded on a process's main thread (see harness.runs.sweep.ReleaseGL).
import pymeshlab
from pydantic import Field, PrivateAttr, ValidationInfo, model_validator

from harness.validation import FieldProblem, InputModel, Positive, Vec3

MESH_KINDS = ("sphere", "torus", "box", "file")
REPAIRS = ("close-holes",)
#: ``repair = "close-holes"`` closes holes of at most this many boundary edges.
MAX_HOLE_EDGES = 1000
_PASSES = 4


@dataclass(frozen=True, eq=False)
class Mesh:
    vertices: np.ndarray  # (V, 3) float64, scene units
    faces: np.ndarray     # (F, 3) int32, counter-clockwise seen from outside
    normals: np.ndarray   # (V, 3) float64, outward, unit length
    repair: dict = None   # what ``repair = "close-holes"`` changed (None: the mesh as given)

    @property
    def bbox(self):
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    def triangles(self):
        return self.vertices[self.faces]


# --------------------------------------------------------------------------- the [mesh] table

_CENTER = Field(default=[0.0, 0.0, 0.0], description="centre, scene units", examples=[[0.0, 0.0, 0.0]])


class _MeshSpec(InputModel):
    """Builds the mesh once the table is valid (only when the scene folder is in the context)."""

    _mesh: Mesh = PrivateAttr(default=None)

    def _check(self):
        """Rules between this table's own fields (a type checks each field alone)."""

    @model_validator(mode="after")
    def _build(self, info: ValidationInfo):
        self._check()
        scene_dir = (info.context or {}).get("scene_dir")
        if scene_dir is not None:
            self._mesh = build_mesh(self, scene_dir)
        return self

    @property
    def mesh(self):
        return self._mesh


class SphereMesh(_MeshSpec):
    """An icosphere (pymeshlab ``create_sphere``)."""

    kind: Literal["sphere"]
    radius: Positive = Field(1.0, description="radius, scene units", examples=[1.0])
    center: Vec3 = _CENTER
    subdivisions: Annotated[int, Field(ge=1, le=6)] = Field(4, description="icosphere subdivisions", examples=[4])


class TorusMesh(_MeshSpec):
    """A torus around z, then rotated about x (pymeshlab ``create_torus``)."""

    kind: Literal["torus"]
    major_radius: Positive = Field(0.8, description="ring radius, scene units", examples=[0.8])
    minor_radius: Positive = Field(0.25, description="tube radius, scene units; < major_radius", examples=[0.25])
    center: Vec3 = _CENTER
    rotate_x_deg: float = Field(0.0, description="rotation about x, degrees", examples=[-60.0])
    segments: Annotated[list[Annotated[int, Field(ge=3, le=1024)]], Field(min_length=2, max_length=2)] = Field(
        [96, 32], description="subdivisions along the ring and around the tube", examples=[[96, 32]])

    def _check(self):
        if self.minor_radius >= self.major_radius:
            raise FieldProblem("minor_radius", f"{self.minor_radius:g} must be smaller than major_radius "
                               f"{self.major_radius:g}", "lower minor_radius")


class BoxMesh(_MeshSpec):
    """An axis-aligned box with flat faces."""

    kind: Literal["box"]
    size: Annotated[list[Positive], Field(min_length=3, max_length=3)] = Field(
        [1.0, 1.0, 1.0], description="edge lengths x, y, z, scene units", examples=[[1.8, 1.8, 0.3]])
    center: Vec3 = _CENTER


class FileMesh(_MeshSpec):
    """A PLY or OBJ file inside the scene folder."""

    kind: Literal["file"]
    path: Annotated[str, Field(min_length=1)] = Field(description="PLY or OBJ file, relative to the scene folder",
                                                      examples=["bunny.ply"])
    scale: Positive = Field(1.0, description="uniform scale applied to the file's coordinates", examples=[1.0])
    translate: Vec3 = Field([0.0, 0.0, 0.0], description="offset added after scaling", examples=[[0.0, 0.0, 0.0]])
    repair: Optional[Literal["close-holes"]] = Field(
        None, description="close the file's holes with pymeshlab (opt-in); a mesh still open after it is refused",
        examples=["close-holes"])


MeshSpec = Annotated[Union[SphereMesh, TorusMesh, BoxMesh, FileMesh], Field(discriminator="kind")]


# --------------------------------------------------------------------------- building

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


def build_mesh(spec, scene_dir):
    """The closed, outward-facing :class:`Mesh` of a validated ``[mesh]`` model.

    Raises :class:`~harness.validation.FieldProblem` (paths relative to ``[mesh]``) for
    a file that cannot be used and for a mesh that is not closed.
    """
    center = np.asarray(getattr(spec, "center", [0.0, 0.0, 0.0]), dtype=np.float64)
    ms = pymeshlab.MeshSet()
    normals, repair = None, None
    if spec.kind == "sphere":
        ms.create_sphere(radius=float(spec.radius), subdiv=int(spec.subdivisions))
        v, f = _from_meshset(ms)
        v = v + center
    elif spec.kind == "torus":
        ms.create_torus(hradius=float(spec.major_radius), vradius=float(spec.minor_radius),
                        hsubdiv=spec.segments[0], vsubdiv=spec.segments[1])
        v, f = _from_meshset(ms)
        angle = np.radians(float(spec.rotate_x_deg))
        c, s = np.cos(angle), np.sin(angle)
        v = v @ np.array([[1, 0, 0], [0, c, s], [0, -s, c]]) + center
    elif spec.kind == "box":
        v, f, normals = _box(np.asarray(spec.size, dtype=np.float64), center)
    else:
        path = resolve_inside(scene_dir, spec.path, "path")
        try:
            ms.load_new_mesh(str(path))
        except Exception as exc:  # pymeshlab raises its own PyMeshLabException
            raise FieldProblem("path", f"cannot read {path.name} ({str(exc).strip() or type(exc).__name__})",
                               "give a PLY or OBJ file") from exc
        v, f = _from_meshset(ms)
        declared = _declared_vertices(path)
        if declared is not None and len(v) < declared:
            # MeshLab drops vertices whose coordinates are not finite numbers (and the faces
            # that use them): left alone, that is reported as a mesh that is not closed.
            raise FieldProblem("path", f"{path.name} declares {declared} vertices but only {len(v)} have finite "
                               "coordinates (NaN or infinite ones are dropped on reading)",
                               "fix or remove those vertices in the file")
        bad = ~np.isfinite(v).all(axis=1)
        if bad.any():
            raise FieldProblem("path", f"{path.name} has {int(bad.sum())} vertices with NaN or infinite "
                               f"coordinates (the first is vertex {int(np.flatnonzero(bad)[0])})",
                               "fix or remove those vertices in the file")
        if spec.repair == "close-holes" and len(f):
            v, f, repair = close_holes(v, f)
        v = v * float(spec.scale) + np.asarray(spec.translate, dtype=np.float64)
    if len(f) == 0:
        raise FieldProblem((), "has no faces", "give a closed triangle mesh")
    check_closed(v, f, repaired=repair is not None, file=spec.kind == "file")
    if normals is None:
        normals = _vertex_normals(v, f)
    mesh = Mesh(v, f, normals, repair)
    if signed_volume(mesh) < 0:
        mesh = Mesh(v, f[:, ::-1].copy(), -normals, repair)
    return mesh


def _declared_vertices(path):
    """The vertex count a PLY header or an OBJ file states (None for other formats or a header that is unclear)."""
    suffix = path.suffix.lower()
    try:
        if suffix == ".ply":
            with open(path, "rb") as fh:
                for raw in fh:
                    line = raw.decode("latin-1").strip()
                    if line.startswith("element vertex"):
                        return int(line.split()[2])
                    if line == "end_header":
                        return None
        elif suffix == ".obj":
            with open(path, "rb") as fh:
                return sum(1 for raw in fh if raw.startswith(b"v ") or raw.startswith(b"v\t"))
    except (OSError, ValueError, IndexError):
        return None
    return None


def _topology(vertices, faces, weld=True):
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=vertices, face_matrix=faces))
    if weld:
        ms.meshing_merge_close_vertices(threshold=pymeshlab.PercentageValue(1e-4))
    return ms, ms.get_topological_measures()


def check_closed(vertices, faces, repaired=False, file=False):
    """Raise :class:`FieldProblem` unless the mesh (coincident vertices welded) is closed and two-manifold."""
    _, topo = _topology(vertices, faces)
    if topo["boundary_edges"] > 0 or not topo["is_mesh_two_manifold"]:
        state = (f"{topo['boundary_edges']} boundary edges, two-manifold={topo['is_mesh_two_manifold']}")
        if repaired:
            raise FieldProblem((), f"is still not closed after repair = \"close-holes\" ({state}; holes of more "
                               f"than {MAX_HOLE_EDGES} edges and non-manifold parts are not repaired)",
                               "repair the mesh in MeshLab or Blender, so inside and outside are defined")
        if topo["boundary_edges"] == 0:          # closed, but edges shared by more than two faces
            raise FieldProblem((), f"is not two-manifold ({state})", "split or remove the non-manifold edges, e.g. "
                               "with MeshLab's 'Repair non Manifold Edges', so inside and outside are defined")
        fix = ("add repair = \"close-holes\" to [mesh], or close the holes in MeshLab" if file else
               "close the holes, e.g. with MeshLab's 'Close Holes'")
        raise FieldProblem((), f"is not closed ({state})", f"{fix}, so inside and outside are defined")


def close_holes(vertices, faces):
    """``repair = "close-holes"``: weld, drop unreferenced vertices, close holes; returns (v, f, what changed)."""
    ms, before = _topology(vertices, faces)
    welded = len(vertices) - ms.current_mesh().vertex_number()
    n0 = ms.current_mesh().vertex_number()
    ms.meshing_remove_unreferenced_vertices()
    unreferenced = n0 - ms.current_mesh().vertex_number()
    f0 = ms.current_mesh().face_number()
    passes, edges = 0, before["boundary_edges"]
    while edges > 0 and passes < _PASSES:
        try:
            ms.meshing_close_holes(maxholesize=MAX_HOLE_EDGES, selfintersection=False)
        except pymeshlab.PyMeshLabException as exc:   # e.g. non-manifold edges: nothing it can close
            reason = " ".join(str(exc).split()).replace("Failed to apply filter: meshing_close_holes ", "")
            raise FieldProblem((), f"is still not closed after repair = \"close-holes\" (MeshLab: {reason})",
                               "repair the mesh in MeshLab or Blender, so inside and outside are defined") from None
        passes += 1
        now = ms.get_topological_measures()["boundary_edges"]
        if now >= edges:                            # no progress: what is left is not a closable hole
            edges = now
            break
        edges = now
    v, f = _from_meshset(ms)
    after = ms.get_topological_measures()
    return v, f, {"method": "close-holes", "tool": f"pymeshlab {_version()} meshing_close_holes("
                  f"maxholesize={MAX_HOLE_EDGES}, selfintersection=False)", "passes": passes,
                  "boundary_edges_before": int(before["boundary_edges"]),
                  "holes_before": int(before["number_holes"]), "boundary_edges_after": int(after["boundary_edges"]),
                  "faces_added": int(len(f) - f0), "vertices_welded": int(welded),
                  "unreferenced_vertices_removed": int(unreferenced)}


def _version():
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("pymeshlab")
    except PackageNotFoundError:
        return "?"


def signed_volume(mesh):
    tri = mesh.triangles()
    return float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0)


def resolve_inside(scene_dir, rel, field):
    """Resolve a file named in a scene; refuse folders, missing files and paths that leave the folder."""
    scene_dir = Path(scene_dir).resolve()
    path = (scene_dir / rel).resolve()
    if not path.is_relative_to(scene_dir):
        raise FieldProblem(field, f"path {rel!r} leaves the scene folder", "put the file inside the scene folder")
    if path.is_dir():
        raise FieldProblem(field, f"{rel!r} is a folder, not a file", "name the file inside it")
    if not path.is_file():
        raise FieldProblem(field, f"file {rel!r} does not exist", "check the name or add the file")
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
