"""Carr, Hall & Hart 2003's multiresolution meshed atlas (MMA, their Sec. 2.3 and 4.2.1), built on the host.

:func:`build` turns a mesh into an :class:`Atlas` of ``size x size`` texels (``size`` a power of two):

1. **Binary face clustering** (:func:`cluster_tree`). The root is the whole mesh; each node is split
   into two neighbouring clusters, each face set measured by :func:`topology` (components through shared
   edges, Euler characteristic ``V - E + F``, boundary loops; a disc is one component with ``V - E + F = 1``).
   A connected cluster's faces are ordered breadth-first from a peripheral face (every prefix connected); of
   the :data:`SPLIT_TRIES` cut points nearest ``ceil(n/2)`` (never giving a child more faces than its
   rectangle's texels), the first where both halves are discs is taken. Failing that, the same cuts of two
   more orders: a region grown from the peripheral face, next always the face with the fewest neighbours left
   untaken (:func:`_grow`: a face hemmed in, or a tooth of the rim, is taken at once rather than cut off), and,
   for a cluster that is not a disc, one grown from a shortest strip of faces between two of its boundary
   loops (an annulus halved across the strip gives two discs). Failing those, the first cut where the
   breadth-first remainder is connected, else the
   remainder's smaller pieces join the grown half when the texels allow, else the balanced split is kept
   with the remainder in pieces. A disconnected cluster is split into whole components. Leaves are single
   triangles: ``2T - 1`` nodes.
2. **Packing** (:func:`pack`). The root owns the whole square; a node's rectangle (square or 2:1) is
   halved for its two children (a square across x into two 2:1 rectangles, a 2:1 rectangle across its
   long side into two squares). The face clusters at even depth are therefore the squares of a
   quadtree, so a texel of MIP level ``m`` covers exactly one cluster's ``2^m x 2^m`` block and the
   MIP-map averages over clusters (Sec. 2.3).
3. **Per-triangle texels** (:func:`texel_geometry`). A leaf triangle fills its ``w x h`` rectangle as
   the right triangle on three of its corners (``v0`` lower-left, ``v1`` lower-right, ``v2``
   upper-left). A texel whose centre lies inside the closed texture triangle (the rasterisation rule,
   edges included) is a surface patch, of area ``A_tri / (its inside texels)``, at the surface point of
   its centre (a one-texel rectangle: the centroid); the other texels of the rectangle are the gutter:
   area 0, at the nearest point of the long edge, so that bilinear interpolation across that edge reads
   values of the same triangle. Pass 3 clamps its lookup to the rectangle's texel centres (half a texel
   inside its border: the half-texel gutter), so a bilinear lookup reads texels of its own triangle only.

Limits
------
* A leaf's rectangle takes its whole triangle; the upper half of each rectangle is gutter, so about
  half the texels are patches (the MMA pairs triangles instead).
* Disc clusters are preferred, not guaranteed. ``Atlas.not_disc`` counts the connected clusters that are not
  discs, ``Atlas.disconnected`` the others. A closed mesh is never a disc (``V - E + F = 2 - 2g``), so the
  root is always counted; and a closed mesh of genus ``g >= 1`` (a torus) cannot be halved into two discs:
  for halves ``A``, ``B``, ``chi(M) = chi(A) + chi(B) - chi(A n B)``, and with ``A`` a disc ``A n B`` is its
  one boundary loop (``chi = 0``), so two discs give ``chi(M) = 2``, a sphere. At least one child of a
  torus's root is therefore not a disc. Deeper down, where a rectangle's texels leave only cut points that
  split a small cluster into pieces, a cluster is disconnected.
* Refused (one line, :class:`harness.errors.InputError`): more triangles than texels, a mesh with an
  edge shared by more than two triangles (non-manifold), a clustering whose subtrees outgrow their
  rectangles (fix: a larger ``--atlas-size``).
"""

from __future__ import annotations

import heapq
from collections import deque
from dataclasses import dataclass

import numpy as np

from harness.errors import InputError

__all__ = ["Atlas", "Topology", "build", "cluster_tree", "pack", "texel_geometry", "face_adjacency", "topology",
           "welded_faces", "SPLIT_TRIES"]

#: Cut points tried in each order (nearest the middle first) for two discs, then for a connected remainder.
SPLIT_TRIES = 16


@dataclass
class Atlas:
    size: int                      # texels per side (a power of two)
    levels: int                    # MIP levels, log2(size) + 1
    position: np.ndarray           # (size, size, 3) float64: the texel's surface point, [y, x]
    normal: np.ndarray             # (size, size, 3) interpolated vertex normal (unit)
    area: np.ndarray               # (size, size) patch area (0 in the gutter)
    face: np.ndarray               # (size, size) int: the leaf triangle owning the texel
    rects: np.ndarray              # (2T - 1, 4) int: x0, y0, w, h of every node of the tree
    children: np.ndarray           # (2T - 1, 2) int, -1 for a leaf
    leaf_face: np.ndarray          # (2T - 1,) int, -1 for an internal node
    uv: np.ndarray                 # (T, 3, 2) float32: texture coordinates of each triangle's corners, in [0, 1]
    face_rect: np.ndarray          # (T, 4) float32: x0, y0, w, h of each triangle's rectangle (texels)
    disconnected: int              # clusters that are not connected in the face adjacency
    not_disc: int                  # connected clusters that are not discs (V - E + F != 1), the root included

    @property
    def texels(self):
        return self.size * self.size


def welded_faces(mesh):
    """The faces' corners as vertex indices welded by position (equal up to ``1e-7`` of the mesh's extent) -> (T, 3)."""
    v = np.asarray(mesh.vertices, np.float64)
    scale = max(float(np.ptp(v, axis=0).max()), 1e-30)
    _, weld = np.unique(np.round(v / (scale * 1e-7)).astype(np.int64), axis=0, return_inverse=True)
    return weld.reshape(-1)[np.asarray(mesh.faces)]


@dataclass(frozen=True)
class Topology:
    """A face set's topology: ``components`` (through shared edges), ``euler`` (``V - E + F`` of the set's own
    vertices, edges and faces) and ``boundary_loops`` (connected pieces of the edges that only one of its faces has)."""

    components: int
    euler: int
    boundary_loops: int

    @property
    def disc(self):
        """One component with ``V - E + F = 1``: a disc (simply connected, one boundary loop)."""
        return self.components == 1 and self.euler == 1


def topology(faces, tri):
    """The :class:`Topology` of the faces ``faces`` of a mesh whose welded corners are ``tri`` (:func:`welded_faces`).

    Counted from the set alone (labels over its shared and boundary edges), not from :func:`face_adjacency`."""
    t = np.asarray(tri)[np.asarray(faces, np.int64)]
    n = len(t)
    if n == 0:
        return Topology(0, 0, 0)
    e = np.sort(np.stack([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]], axis=1).reshape(-1, 2), axis=1)
    keys, inv, counts = np.unique(e, axis=0, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    euler = len(np.unique(t)) - len(keys) + n

    def pieces(a, b, m):                    # connected pieces of a graph: labels lowered to a fixed point
        lab = np.arange(m)
        while True:
            old = lab.copy()
            np.minimum.at(lab, a, lab[b])
            np.minimum.at(lab, b, lab[a])
            lab = lab[lab]
            if np.array_equal(lab, old):
                return len(np.unique(lab))

    owner = np.repeat(np.arange(n), 3)
    order = np.argsort(inv, kind="stable")
    same = np.nonzero(inv[order][1:] == inv[order][:-1])[0]       # the two faces of an inner edge
    components = pieces(owner[order[same]], owner[order[same + 1]], n)
    rim = keys[counts == 1]
    if len(rim) == 0:
        return Topology(int(components), int(euler), 0)
    ids, rv = np.unique(rim, return_inverse=True)
    rv = rv.reshape(-1, 2)
    return Topology(int(components), int(euler), int(pieces(rv[:, 0], rv[:, 1], len(ids))))


def face_adjacency(mesh):
    """Faces sharing an edge, with the vertices welded by position -> list of neighbour lists.

    An edge with more than two faces is refused (non-manifold)."""
    f = welded_faces(mesh)
    T = len(f)
    e = np.sort(np.stack([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]], axis=1).reshape(-1, 2), axis=1)
    owner = np.repeat(np.arange(T), 3)
    keys, inv, counts = np.unique(e, axis=0, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    if np.any(counts > 2):
        k = int(np.argmax(counts))
        raise InputError("mesh", "faces", f"the mesh is non-manifold: edge {tuple(int(x) for x in keys[k])} is "
                         f"shared by {int(counts[k])} triangles (the atlas's face clustering needs at most two)",
                         "repair the mesh (split the edge or remove the extra triangles)")
    order = np.argsort(inv, kind="stable")
    same = np.nonzero(inv[order][1:] == inv[order][:-1])[0]          # the two instances of a shared edge
    nb = [[] for _ in range(T)]
    for a, b in zip(owner[order[same]], owner[order[same + 1]]):
        if a != b:
            nb[a].append(int(b))
            nb[b].append(int(a))
    return nb


def _bfs(start, inside, nb):
    seen = {start}
    out = [start]
    q = deque([start])
    while q:
        a = q.popleft()
        for b in nb[a]:
            if b in inside and b not in seen:
                seen.add(b)
                out.append(b)
                q.append(b)
    return out


def _grow(sources, inside, nb):
    """All of ``inside`` in the order a region grows from ``sources``: next the face with the fewest neighbours in
    ``inside`` not yet taken (a face hemmed in, or a tooth of the cluster's rim, comes first), then the earliest
    reached. Every prefix is connected, and the front leaves fewer faces cut off behind than a breadth-first one."""
    taken = set(sources)
    out = list(sources)
    free, heap, seq = {}, [], 0                 # free: a reached face's neighbours in inside not yet taken

    def reach(a):
        nonlocal seq
        for b in nb[a]:
            if b in inside and b not in taken:
                free[b] = free.get(b, sum(1 for c in nb[b] if c in inside)) - 1
                heapq.heappush(heap, (free[b], seq, b))
                seq += 1

    for a in out:
        reach(a)
    while heap:
        c, _, a = heapq.heappop(heap)
        if a in taken or c != free[a]:            # taken already, or a stale entry
            continue
        taken.add(a)
        out.append(a)
        reach(a)
    return out


def _components(faces, nb):
    left = set(faces)
    comps = []
    while left:
        c = _bfs(next(iter(left)), left, nb)
        comps.append(c)
        left.difference_update(c)
    return sorted(comps, key=len, reverse=True)


def _face_edges(mesh, with_ends=False):
    """``(welded corners (T, 3), each face's edge ids (T, 3))``, and each edge's two vertices (E, 2) ``with_ends``."""
    tri = welded_faces(mesh)
    ev, fe = np.unique(np.sort(np.stack([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]], axis=1), axis=2).reshape(-1, 2),
                       axis=0, return_inverse=True)
    fe = fe.reshape(len(tri), 3)
    return (tri, fe, ev) if with_ends else (tri, fe)


@dataclass(frozen=True)
class _Edges:
    tri: list                      # (T, 3) welded corners of each face
    fe: list                       # (T, 3) each face's edges, as edge ids
    ev: list                       # (E, 2) each edge's two welded vertices


def _across(faces, nb, g):
    """The order of a connected, non-disc ``faces`` grown (:func:`_grow`) from a shortest strip of faces between two
    of its boundary loops (halving an annulus across its strip gives two discs), or ``None`` with fewer than two
    loops."""
    inside = set(faces)
    uses = {}
    for f in faces:
        for e in g.fe[f]:
            uses[e] = uses.get(e, 0) + 1
    rim = [e for e, c in uses.items() if c == 1]
    parent = {}

    def root(a):
        while parent.setdefault(a, a) != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for e in rim:                               # boundary loops: the rim's edges joined at shared vertices
        a, b = root(g.ev[e][0]), root(g.ev[e][1])
        parent[a] = b
    loop = {e: root(g.ev[e][0]) for e in rim}
    if len(set(loop.values())) < 2:
        return None
    first = next(iter(loop.values()))
    touch = {f: {loop[e] for e in g.fe[f] if e in loop} for f in faces}
    sources = [f for f in faces if first in touch[f]]
    back = dict.fromkeys(sources)
    q = deque(sources)
    while q:
        a = q.popleft()
        if touch[a] - {first}:                  # reached another loop: the strip back to the first
            strip = [a]
            while back[strip[-1]] is not None:
                strip.append(back[strip[-1]])
            break
        for b in nb[a]:
            if b in inside and b not in back:
                back[b] = a
                q.append(b)
    return _grow(strip[::-1], inside, nb)


def _prefix_euler(order, tri, fe):
    """``V - E + F`` of every prefix ``order[:c]``, ``c = 0..n``, adding one face at a time."""
    verts, edges = set(), set()
    out = [0]
    for f in order:
        nv = sum(1 for v in tri[f] if v not in verts)
        ne = sum(1 for e in fe[f] if e not in edges)
        verts.update(tri[f])
        edges.update(fe[f])
        out.append(out[-1] + nv - ne + 1)
    return out


def _suffix_components(order, nb):
    """Components (through shared edges) of every suffix ``order[c:]``, ``c = 0..n``: a union-find fed backwards."""
    parent = {}

    def root(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    out = [0]
    for f in reversed(order):
        parent[f] = f
        count = out[-1] + 1
        for g in nb[f]:
            if g in parent:
                ra, rb = root(f), root(g)
                if ra != rb:
                    parent[ra] = rb
                    count -= 1
        out.append(count)
    return out[::-1]


def _scan(order, nb, g):
    """``(order, chi of each prefix, chi of each suffix, components of each suffix)``, indexed by the cut."""
    return (order, _prefix_euler(order, g.tri, g.fe), _prefix_euler(order[::-1], g.tri, g.fe)[::-1],
            _suffix_components(order, nb))


def _split(faces, nb, cap, g):
    """Two neighbouring halves of ``faces``, neither over ``cap`` faces (see the module docstring)."""
    inside = set(faces)
    n = len(faces)
    comps = _components(faces, nb)
    k = (n + 1) // 2
    if len(comps) > 1:                          # a disconnected cluster: whole components, largest first
        a, b = [], []
        for c in comps:
            (a if len(a) <= len(b) else b).extend(c)
        if max(len(a), len(b)) <= cap:
            return a, b
        faces = [f for c in comps for f in c]
        return faces[:k], faces[k:]
    far = _bfs(faces[0], inside, nb)[-1]        # a peripheral face
    cuts = sorted(range(max(n - cap, 1), min(cap, n - 1) + 1), key=lambda c: (abs(c - k), c))[:SPLIT_TRIES]
    scans = [_scan(_bfs(far, inside, nb), nb, g)]
    for more in range(3):                       # both halves discs
        o, pre, suf, parts = scans[-1]
        for cut in cuts:
            if parts[cut] == 1 and pre[cut] == 1 and suf[cut] == 1:
                return o[:cut], o[cut:]
        if more == 0:                           # grown by most taken neighbours
            scans.append(_scan(_grow([far], inside, nb), nb, g))
        elif more == 1 and pre[n] != 1:         # a non-disc cluster: grown from a strip between two loops
            across = _across(faces, nb, g)
            if across is None:
                break
            scans.append(_scan(across, nb, g))
        else:
            break
    for o, pre, suf, parts in scans:            # both halves connected
        for cut in cuts:
            if parts[cut] == 1:
                return o[:cut], o[cut:]
    order = _bfs(far, inside, nb)
    a, rest = order[:k], order[k:]
    comps = _components(rest, nb)
    merged = a + [f for c in comps[1:] for f in c]
    if len(merged) <= cap:
        return merged, comps[0]
    return a, rest                              # balance first: the remainder stays in pieces


def cluster_tree(mesh, size):
    """The binary face clustering for a ``size x size`` atlas -> ``(children (2T-1, 2), leaf_face (2T-1,),
    members)``; node 0 is the root, ``members[j]`` lists the faces of node ``j``. A node at depth ``d`` owns
    ``size^2 / 2^d`` texels (:func:`pack`), so no split gives a child more faces than that."""
    nb = face_adjacency(mesh)
    tri, fe, ev = _face_edges(mesh, True)
    T = len(tri)
    mesh_edges = _Edges(tri.tolist(), fe.tolist(), ev.tolist())
    children, leaf, members = [], [], []

    def add(faces):
        members.append(faces)
        children.append([-1, -1])
        leaf.append(faces[0] if len(faces) == 1 else -1)
        return len(members) - 1

    stack = [(add(list(range(T))), 0)]
    while stack:
        j, depth = stack.pop()
        if len(members[j]) == 1:
            continue
        a, b = _split(members[j], nb, (size * size) >> (depth + 1), mesh_edges)
        ca, cb = add(a), add(b)
        children[j] = [ca, cb]
        stack += [(cb, depth + 1), (ca, depth + 1)]
    return np.array(children, np.int64), np.array(leaf, np.int64), members


def pack(size, children, members):
    """Every node's rectangle ``(x0, y0, w, h)``: the root the whole square, each node halved for its children.

    Refuses a subtree with more faces than its rectangle's texels."""
    rects = np.zeros((len(children), 4), np.int64)
    rects[0] = (0, 0, size, size)
    for j in range(len(children)):                # children always come after their parent
        x0, y0, w, h = rects[j]
        if len(members[j]) > w * h:
            raise InputError("--atlas-size", "atlas_size", f"the face clustering puts {len(members[j]):,} triangles "
                             f"into a {w} x {h} texel region of the {size} x {size} atlas",
                             f"raise --atlas-size to {2 * size} or more")
        a, b = children[j]
        if a < 0:
            continue
        if w == h:                                # a square into two 2:1 rectangles
            rects[a], rects[b] = (x0, y0, w // 2, h), (x0 + w // 2, y0, w // 2, h)
        else:                                     # a 2:1 rectangle (h = 2 w) into two squares
            rects[a], rects[b] = (x0, y0, w, h // 2), (x0, y0 + h // 2, w, h // 2)
    return rects


def texel_geometry(mesh, size, rects, leaf_face):
    """Per texel: surface point, normal, patch area and owning face; per face: its corners' uv and its
    rectangle (module docstring)."""
    V, F, N = np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces), np.asarray(mesh.normals, np.float64)
    T = len(F)
    pos = np.zeros((size, size, 3))
    nrm = np.zeros((size, size, 3))
    area = np.zeros((size, size))
    face = np.full((size, size), -1, np.int64)
    uv = np.zeros((T, 3, 2), np.float32)
    face_rect = np.zeros((T, 4), np.float32)
    tri = V[F]
    tri_area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    for j in np.nonzero(leaf_face >= 0)[0]:
        f = int(leaf_face[j])
        x0, y0, w, h = (int(v) for v in rects[j])
        i, k = np.meshgrid(np.arange(w), np.arange(h))
        s, t = (i + 0.5) / w, (k + 0.5) / h              # texel centres in the rectangle, [0, 1]^2
        inside = s + t <= 1.0 + 1e-12                    # the closed texture triangle (rasterisation rule)
        tot = np.where(inside, 1.0, s + t)
        s, t = s / tot, t / tot                          # the gutter: nearest point of the long edge
        b = np.stack([1.0 - s - t, s, t], axis=-1)
        if w * h == 1:                                   # one texel: the triangle's centroid
            b = np.full((1, 1, 3), 1.0 / 3.0)
        pos[y0:y0 + h, x0:x0 + w] = b @ tri[f]
        n = b @ N[F[f]]
        nrm[y0:y0 + h, x0:x0 + w] = n / np.linalg.norm(n, axis=-1, keepdims=True)
        area[y0:y0 + h, x0:x0 + w] = np.where(inside, tri_area[f] / inside.sum(), 0.0)
        face[y0:y0 + h, x0:x0 + w] = f
        uv[f] = np.array([[x0, y0], [x0 + w, y0], [x0, y0 + h]]) / size
        face_rect[f] = (x0, y0, w, h)
    return pos, nrm, area, face, uv, face_rect


def build(mesh, size):
    """The atlas of ``mesh`` at ``size x size`` texels (module docstring)."""
    T = len(mesh.faces)
    if T > size * size:
        raise InputError("--atlas-size", "atlas_size", f"the mesh has {T:,} triangles, more than the "
                         f"{size * size:,} texels of a {size} x {size} atlas (each triangle needs one)",
                         f"raise --atlas-size to {1 << int(np.ceil(np.log2(np.sqrt(T))))} or more")
    children, leaf, members = cluster_tree(mesh, size)
    rects = pack(size, children, members)
    pos, nrm, area, face, uv, face_rect = texel_geometry(mesh, size, rects, leaf)
    nb = face_adjacency(mesh)
    tri, fe = _face_edges(mesh)
    disconnected = not_disc = 0
    for m in members:
        if len(m) > 1:
            if len(_components(m, nb)) > 1:
                disconnected += 1
            elif len(np.unique(tri[m])) - len(np.unique(fe[m])) + len(m) != 1:   # V - E + F
                not_disc += 1
    return Atlas(size, int(np.log2(size)) + 1, pos, nrm, area, face, rects, children, leaf, uv, face_rect,
                 disconnected, not_disc)
