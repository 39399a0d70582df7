"""The hierarchical gather's octree of irradiance samples (Jensen & Buhler 2002, Sec. 3), host side, NumPy.

Jensen & Buhler ("A rapid hierarchical rendering technique for translucent materials", SIGGRAPH
2002) compute the irradiance at surface samples, store them in an octree whose nodes hold the
total irradiance times area, the total area and the irradiance-weighted mean position, and
evaluate the BSSRDF per exit point by a descent that uses a node's aggregate when the solid
angle it subtends, ``dOmega = A_node / |x_o - p_node|^2``, is below ``epsilon`` (Sec. 3.2).

Structure (:func:`build`, once per scene and spacing; deterministic): the samples of
:func:`dipole_gl.sampling.surface_samples` are sorted by their Morton code (positions
quantised by ``floor`` to ``2^21`` cells per axis of the samples' bounding cube; ties by
index), so that every octree cell holds a contiguous range ``[first, end)`` of the sorted
samples. A node is a cell whose samples fall into at least two of its eight children (cells
with one occupied child are collapsed into it: every internal node splits), or a single sample
(a leaf; samples that share a finest cell are leaves of that cell's node). Nodes are stored
in depth-first order, a parent before its children, each with ``skip``, the index of the first
node after its subtree: a stackless traversal goes to ``i + 1`` to refine and to ``skip[i]`` to
accept (or to leave a leaf). With the adjacent samples' common prefix ``d_i`` (in octal digits)
of the sorted codes, the internal nodes at depth ``k`` are the maximal runs of ``d >= k`` that
contain a ``d == k`` (Karras 2012's observation for radix trees, taken per octal digit).

Aggregates (:func:`aggregate`, per frame, from the irradiance pass's flux; float64 sums by
prefix sums over the sorted samples) of an internal node, with ``w_s`` the sample's flux
summed over colours and lights:

* ``area`` = sum of the samples' areas (``A_node``, lit or not);
* ``centroid`` = ``sum w_s x_s / sum w_s`` (the irradiance-weighted position ``P_v``), and the
  weight ``W = sum w_s``: a node with ``W = 0`` is unlit and adds nothing;
* ``total`` = ``sum_s sum_l Phi_{s,l}`` (rgb): the standard dipole's ``E A`` of the node;
* for the directional dipole, per light: ``flux_l = sum_s Phi_{s,l}`` and the flux-weighted mean
  direction to the light ``w_l = normalize(sum_s |Phi_{s,l}| w_{s,l})``, and per node the
  flux-weighted mean normal ``n = normalize(sum_s w_s n_s)``; the kernel refracts ``w_l`` at ``n``
  (a direction that does not refract, light from behind the mean normal at grazing incidence,
  adds nothing).

Approximations and limits: an accepted node is one source at its centroid. For the standard
dipole that is Jensen & Buhler's own approximation (``R_d`` depends only on the distance). For
the directional dipole, which also depends on the source's normal (the modified tangent plane)
and on the light's direction, the node's mean normal and mean direction to the light stand for its
samples': exact for a flat node under a distant light, wrong where a node spans a fold or an
edge (its mean normal is then short and is renormalised) or two lights light different parts of
it (one centroid for all lights). All of this vanishes as ``epsilon -> 0``: at ``epsilon = 0``
every lit node is refined to its leaves, which are the samples themselves, and the gather is the
dense gather's far field exactly (up to the order of the float sums). The Morton quantisation
limits the depth to 21 levels below the bounding cube; deeper coincident samples are leaves of
one node.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Octree", "Aggregates", "build", "aggregate", "to_lights", "MORTON_BITS", "morton_codes"]

#: Quantisation bits per axis (3 x 21 = 63 bits of Morton code).
MORTON_BITS = 21


@dataclass(frozen=True, eq=False)
class Octree:
    positions: np.ndarray    # (S, 3) float64, the samples in Morton order
    normals: np.ndarray      # (S, 3)
    areas: np.ndarray        # (S,)
    order: np.ndarray        # (S,) index of each sorted sample in the samples as given
    first: np.ndarray        # (N,) int64: the node's samples are [first, end) (sorted order); DFS order
    end: np.ndarray          # (N,)
    skip: np.ndarray         # (N,) the first node after the subtree
    internal: np.ndarray     # (N,) index into the internal nodes' aggregates, -1 for a leaf
    depth: np.ndarray        # (N,) octree depth of the node's cell (leaves: MORTON_BITS)
    cell: np.ndarray         # (N, 4) float64: the cell's centre xyz and half size

    @property
    def nodes(self):
        return len(self.first)

    @property
    def internal_count(self):
        return int((self.internal >= 0).sum())


@dataclass(frozen=True, eq=False)
class Aggregates:
    area: np.ndarray         # (K,) float64
    weight: np.ndarray       # (K,) W = sum of the samples' flux over colours and lights
    centroid: np.ndarray     # (K, 3) irradiance-weighted mean position
    normal: np.ndarray       # (K, 3) flux-weighted mean normal (unit)
    total: np.ndarray        # (K, 3) flux summed over lights
    flux: np.ndarray         # (L, K, 3) flux per light
    to_light: np.ndarray     # (L, K, 3) flux-weighted mean direction to each light (unit)


def _spread(v):
    """Insert two zero bits between each of the low 21 bits of ``v`` (uint64)."""
    v = v & np.uint64(0x1FFFFF)
    for shift, mask in ((32, 0x1F00000000FFFF), (16, 0x1F0000FF0000FF), (8, 0x100F00F00F00F00F),
                        (4, 0x10C30C30C30C30C3), (2, 0x1249249249249249)):
        v = (v | (v << np.uint64(shift))) & np.uint64(mask)
    return v


def morton_codes(positions):
    """``(codes (S,) uint64, q (S, 3) int64 cells, lo (3,), size)``: x in the top bit of each octal digit."""
    p = np.asarray(positions, dtype=np.float64)
    lo = p.min(axis=0)
    size = float((p.max(axis=0) - lo).max()) * (1.0 + 1e-9)
    size = size if size > 0.0 else 1.0
    n = 1 << MORTON_BITS
    q = np.clip(np.floor((p - lo) / size * n), 0, n - 1).astype(np.int64)
    u = q.astype(np.uint64)
    codes = (_spread(u[:, 0]) << np.uint64(2)) | (_spread(u[:, 1]) << np.uint64(1)) | _spread(u[:, 2])
    return codes, q, lo, size


def _bit_length(x):
    """Bit length of each uint64 (0 for 0), exactly."""
    x = x.copy()
    n = np.zeros(len(x), np.int64)
    for b in (32, 16, 8, 4, 2, 1):
        big = (x >> np.uint64(b)) != 0
        n[big] += b
        x[big] >>= np.uint64(b)
    return n + (x != 0)


def build(positions, normals, areas):
    """The :class:`Octree` of the samples (see the module docstring)."""
    positions = np.asarray(positions, np.float64)
    S = len(positions)
    codes, q, lo, size = morton_codes(positions)
    order = np.argsort(codes, kind="stable")
    c, q = codes[order], q[order]
    # d[i]: octal digits shared by samples i and i + 1 (21 for one finest cell)
    d = (3 * MORTON_BITS - _bit_length(c[:-1] ^ c[1:])) // 3
    firsts, ends, depths = [np.arange(S)], [np.arange(S) + 1], [np.full(S, MORTON_BITS)]
    if S > 1:
        eq_cum = np.zeros(S, np.int64)
        for k in range(MORTON_BITS + 1):
            ge = np.concatenate([[False], d >= k, [False]])
            starts = np.nonzero(ge[1:] & ~ge[:-1])[0]              # first pair of each run
            stops = np.nonzero(ge[:-1] & ~ge[1:])[0]               # one past its last pair
            if not len(starts):
                break
            eq_cum[1:] = np.cumsum(d == k)
            real = eq_cum[stops] - eq_cum[starts] > 0             # the cell splits at this depth
            firsts.append(starts[real])
            ends.append(stops[real] + 1)
            depths.append(np.full(int(real.sum()), k))
    first, end, depth = (np.concatenate(a) for a in (firsts, ends, depths))
    dfs = np.lexsort((-end, first))                               # parent (same first, larger end) first
    first, end, depth = first[dfs], end[dfs], depth[dfs]
    skip = np.searchsorted(first, end, side="left")
    is_internal = end - first > 1
    internal = np.where(is_internal, np.cumsum(is_internal) - 1, -1)
    cell_size = size / (2.0 ** depth)
    cell_idx = q[first] >> (MORTON_BITS - depth)[:, None]
    centre = lo + (cell_idx + 0.5) * cell_size[:, None]
    cell = np.concatenate([centre, 0.5 * cell_size[:, None]], axis=1)
    return Octree(positions[order], np.asarray(normals, np.float64)[order], np.asarray(areas, np.float64)[order],
                  order, first, end, skip, internal, depth, cell)


def _range_sums(values, first, end):
    """Sum of ``values[first:end]`` per range (prefix sums, float64)."""
    v = np.asarray(values, np.float64)
    cs = np.concatenate([np.zeros((1,) + v.shape[1:]), np.cumsum(v, axis=0)])
    return cs[end] - cs[first]


def _unit(v):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.where(n > 0.0, v / np.where(n > 0.0, n, 1.0), 0.0)


def to_lights(tree, lights):
    """``(L, S, 3)``: the unit direction from each sorted sample to each light."""
    out = [np.asarray(light.position, np.float64) - tree.positions for light in lights]
    return np.stack([_unit(v) for v in out]) if out else np.zeros((0, len(tree.positions), 3))


def aggregate(tree, flux, to_light):
    """:class:`Aggregates` of the internal nodes from the flux ``(L, S, 3+)`` of the sorted samples (the
    irradiance pass's buffer; extra components ignored) and their directions to the lights ``(L, S, 3)``."""
    flux = np.asarray(flux, np.float64)[..., :3]
    to_light = np.asarray(to_light, np.float64)[..., :3]
    sel = tree.internal >= 0
    a, b = tree.first[sel], tree.end[sel]
    per_light = flux.sum(axis=2)                                   # (L, S)
    w = per_light.sum(axis=0)                                      # (S,)
    weight = _range_sums(w, a, b)
    lit = weight > 0.0
    centroid = _range_sums(w[:, None] * tree.positions, a, b) / np.where(lit, weight, 1.0)[:, None]
    centroid = np.where(lit[:, None], centroid, tree.cell[sel, :3])
    normal = _unit(_range_sums(w[:, None] * tree.normals, a, b))
    fl = np.stack([_range_sums(f, a, b) for f in flux]) if len(flux) else np.zeros((0, len(a), 3))
    dirs = np.stack([_unit(_range_sums(np.abs(pl)[:, None] * wd, a, b)) for pl, wd in zip(per_light, to_light)]) \
        if len(flux) else np.zeros((0, len(a), 3))
    return Aggregates(_range_sums(tree.areas, a, b), weight, centroid, normal, fl.sum(axis=0), fl, dirs)
