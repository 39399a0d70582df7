"""The atlas gather's links (Carr, Hall & Hart 2003, Sec. 4.1 and 4.2.1), precomputed on the host.

Every texel ``b`` of the atlas (:mod:`dipole_gl.atlas`) is a receiving patch ``P_b``; a *node* is a
texel ``(u, v)`` of MIP level ``l``, the face cluster of the ``2^l x 2^l`` base texels below it. A link
``(u, v, l, G)`` adds ``G`` times the level-``l`` texel of the MIP-mapped radiosity map (pass 1) to
``b``'s scattered irradiance (pass 2, Eq. 9: ``B_b = sum_c F_bc E_c``).

The throughput factor of Eq. (10), with the receiver taken at its texel's point ``x_b``:
``F_bc = int_{P_c} R_d(|x_b - x|) dx``, as the sum over the cluster's base texels ``t`` of
``a_t R_d(|x_b - x_t|)`` (the midpoint rule of the atlas's patches), ``b``'s own patch as the disc of
the same area around ``x_b``, ``int_0^r R_d 2 pi r' dr'``, ``pi r^2 = a_b`` (Eq. K8 of
``docs/dipole_rivals.md``). :func:`throughput` sums it exactly (``P^2`` kernel evaluations, every level
at once); the links use :class:`Estimate`, the same sum with a node farther than :data:`FAR_RATIO` times
its radius taken as one point ``A_c R_d(|x_b - p_c|)`` at its centroid (within 0.3 % of the exact sum
on ``apple_sphere`` at 128^2, ``tests/test_dipole_atlas.py``). The
MIP texel holds the mean of ``E a`` over its block (pass 1 stores the flux ``E a`` per texel), i.e.
``sum_c E a / 4^l``, and ``E_c = sum_c E a / A_c``, so the stored factor is ``G = F_bc 4^l / A_c``.
``R_d`` uses the material at ``x_b`` (the exit point, as the other gathers) and is kept per colour (the
paper's scalar factor is a storage saving; it allows colour factors "at a cost of space").

* **non-adaptive** (``link_level = l``): links from every texel to every level-``l`` node of nonzero
  area: the same node set for every texel;
* **adaptive** (``links = L``): per texel, a priority queue on throughput (its mean over colours)
  starts at the root; the node at the top that has children is replaced by its children (those of
  nonzero area) while the queue stays within ``L`` entries. A base texel cannot be refined; the
  queue's nodes are the links.

The one approximation of a link is Sec. 4.1's clustering: the irradiance taken uniform over the
cluster (its mean ``E_c``). With every texel linked at level 0 the gather is the midpoint rule over the
atlas's patches.

Limits: the far-node estimate errs low where ``R_d`` is convex across a node (about 0.2 % of the
throughput at ``FAR_RATIO = 8``); the standard dipole only (the directional dipole depends on the light's direction, which a precomputed factor cannot hold).
A table over :data:`MAX_LINK_BYTES` is refused with the setting that fits (:func:`check_table`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from harness.errors import InputError

from . import kernels

#: A node is far from a receiver (one point at its centroid) beyond this many times its radius.
FAR_RATIO = 8.0

__all__ = ["Blocks", "Estimate", "FAR_RATIO", "Links", "blocks", "adaptive", "non_adaptive", "rd_disc", "throughput", "check_table", "encode", "decode",
           "LINK_BYTES", "MAX_LINK_BYTES"]

#: Bytes per link on the GPU: the node (one int) and the factor (rgb + pad).
LINK_BYTES = 20
#: The largest link table built (host and GPU).
MAX_LINK_BYTES = 256 * 1024 * 1024


@dataclass
class Blocks:
    """Per MIP level ``l``, of each node: the patch area ``A`` (n, n) summed over its base texels, their
    area-weighted centroid ``p`` (n, n, 3) and a radius (n, n) that bounds their distance from ``p``."""
    area: list
    centroid: list
    radius: list


@dataclass
class Links:
    node: np.ndarray        # (P, L) int32: encoded (level, u, v), -1 for an empty slot
    g: np.ndarray           # (P, L, 3) float64: the factor G
    count: np.ndarray       # (P,) links used per texel
    adaptive: bool

    @property
    def slots(self):
        return self.node.shape[1]


def encode(level, u, v):
    return (np.asarray(level, np.int64) << 24) | (np.asarray(v, np.int64) << 12) | np.asarray(u, np.int64)


def decode(code):
    code = np.asarray(code, np.int64)
    return code >> 24, code & 0xFFF, (code >> 12) & 0xFFF


def blocks(atlas):
    """The nodes' areas, centroids and radii at every level."""
    a, p = atlas.area, atlas.position
    out = Blocks([a], [p], [np.zeros_like(a)])
    while a.shape[0] > 1:
        n = a.shape[0] // 2
        pa = (p * a[..., None]).reshape(n, 2, n, 2, 3).sum(axis=(1, 3))
        a_up = a.reshape(n, 2, n, 2).sum(axis=(1, 3))
        with np.errstate(invalid="ignore", divide="ignore"):
            p_up = np.where(a_up[..., None] > 0, pa / a_up[..., None], 0.0)
        child = np.linalg.norm(p.reshape(n, 2, n, 2, 3) - p_up[:, None, :, None], axis=-1) \
            + out.radius[-1].reshape(n, 2, n, 2)
        rad = np.where(a.reshape(n, 2, n, 2) > 0, child, 0.0).max(axis=(1, 3))
        a, p = a_up, p_up
        out.area.append(a)
        out.centroid.append(p)
        out.radius.append(rad)
    return out


def rd_disc(radius, m):
    """Eq. (K8): ``int_0^radius R_d(r) 2 pi r dr = alpha'/2 sum_z (e^(-sigma_tr z) - z e^(-sigma_tr d)/d)``,
    ``d = sqrt(radius^2 + z^2)``, for the real and the virtual source."""
    r = np.asarray(radius, np.float64)
    s = m["sigma_tr"]
    out = 0.0
    for z in (m["z_r"], m["z_v"]):
        d = np.sqrt(r * r + z * z)
        out = out + np.exp(-s * z) - z * np.exp(-s * d) / d
    return 0.5 * m["alpha_prime"] * out


def _coeffs(m, sel):
    return {k: (v[sel] if isinstance(v, np.ndarray) and v.ndim == 2 else v) for k, v in m.items()}


def throughput(atlas, m, rows):
    """Eq. (10) from receivers ``rows`` (flat texel indices) to every node of every level -> list over levels of
    ``F`` (len(rows), n, n, 3): sums over the node's base texels of ``a_t R_d(|x_b - x_t|)``, the receiver's own
    texel as the disc of its area (Eq. K8)."""
    P, N = atlas.texels, atlas.size
    x, a = atlas.position.reshape(P, 3), atlas.area.reshape(P)
    mb = {k: (v[:, None] if isinstance(v, np.ndarray) else v) for k, v in _coeffs(m, rows).items()}
    r = np.linalg.norm(x[rows, None] - x[None], axis=-1)
    f = kernels.rd_dipole(r[..., None], mb) * a[None, :, None]
    own = rd_disc(np.sqrt(a[rows] / np.pi)[:, None], _coeffs(m, rows))
    f[np.arange(len(rows)), rows] = np.where(a[rows, None] > 0, own, 0.0)
    f = f.reshape(len(rows), N, N, 3)
    out = [f]
    while f.shape[1] > 1:
        n = f.shape[1] // 2
        f = f.reshape(len(rows), n, 2, n, 2, 3).sum(axis=(2, 4))
        out.append(f)
    return out


def _chunk(atlas):
    return max(1, int(2e7 // (atlas.texels * 3)))


class Estimate:
    """Eq. (10)'s ``F_bc`` for receivers ``rows``, Barnes-Hut style: a node far from ``x_b``
    (``|x_b - p_c| > FAR_RATIO r_c``) is ``A_c R_d(|x_b - p_c|)``, a near one the sum of its children's estimates, a base texel
    ``a_t R_d(|x_b - x_t|)`` (``b``'s own: the disc, Eq. K8). ``get`` answers any node; the near ones
    (with their children) are summed once, bottom-up, others are taken as far."""

    def __init__(self, atlas, blk, m, rows):
        self.blk, self.rows, self.N = blk, np.asarray(rows), atlas.size
        self.x = atlas.position.reshape(-1, 3)[self.rows]
        self.a = atlas.area.reshape(-1)[self.rows]
        self.m = _coeffs(m, self.rows)
        self.known = {}                               # level -> (sorted keys, values (K, 3))
        top = atlas.levels - 1
        near = np.arange(len(self.rows)), np.zeros(len(self.rows), np.int64), np.zeros(len(self.rows), np.int64)
        tiers = []                                    # per level from the top: (rows, v, u, is_near)
        is_near = self._near(top, *near)
        tiers.append((top, *near, is_near))
        for lv in range(top, 0, -1):
            r, v, u, nr = tiers[-1][1:]
            r, v, u = r[nr], v[nr], u[nr]
            cr = np.repeat(r, 4)
            cv = (2 * v[:, None] + np.array([0, 0, 1, 1])).reshape(-1)
            cu = (2 * u[:, None] + np.array([0, 1, 0, 1])).reshape(-1)
            keep = blk.area[lv - 1][cv, cu] > 0
            cr, cv, cu = cr[keep], cv[keep], cu[keep]
            tiers.append((lv - 1, cr, cv, cu, self._near(lv - 1, cr, cv, cu)))
        below = None                                  # (keys, values) of the level below
        for lv, r, v, u, nr in reversed(tiers):
            val = self._point(lv, r, v, u)
            if below is not None and nr.any():
                n_below = self.N >> (lv - 1)
                parent = below[0] // (n_below * n_below) * (self.N >> lv) ** 2 \
                    + (below[0] % (n_below * n_below) // n_below // 2) * (self.N >> lv) \
                    + below[0] % n_below // 2
                key = self._key(lv, r, v, u)
                order = np.argsort(parent, kind="stable")
                up, start = np.unique(parent[order], return_index=True)
                tot = np.add.reduceat(below[1][order], start, axis=0)
                pos = np.searchsorted(up, key[nr])
                hit = (pos < len(up)) & (up[np.minimum(pos, len(up) - 1)] == key[nr])
                part = np.zeros((nr.sum(), 3))
                part[hit] = tot[pos[hit]]
                val[nr] = part
            key = self._key(lv, r, v, u)
            order = np.argsort(key)
            self.known[lv] = (key[order], val[order])
            below = (key, val)

    def _key(self, lv, r, v, u):
        n = self.N >> lv
        return (np.asarray(r, np.int64) * n + v) * n + u

    def _near(self, lv, r, v, u):
        if lv == 0:
            return np.zeros(len(r), bool)
        rad = self.blk.radius[lv][v, u]
        d = np.linalg.norm(self.x[r] - self.blk.centroid[lv][v, u], axis=-1)
        return d <= FAR_RATIO * rad

    def _point(self, lv, r, v, u):
        """``A_c R_d(|x_b - p_c|)`` (level 0: the texel, or the disc for the receiver's own)."""
        A = self.blk.area[lv][v, u]
        d = np.linalg.norm(self.x[r] - self.blk.centroid[lv][v, u], axis=-1)
        mr = _coeffs(self.m, r)
        f = kernels.rd_dipole(d[:, None], mr) * A[:, None]
        if lv == 0:
            own = (v * self.N + u) == self.rows[r]
            if own.any():
                f[own] = rd_disc(np.sqrt(self.a[r[own]] / np.pi)[:, None], _coeffs(mr, own))
        return f

    def get(self, lv, r, v, u):
        """``F`` (M, 3) from local receivers ``r`` to the nodes ``(lv, u, v)``."""
        r, v, u = (np.asarray(x, np.int64).reshape(-1) for x in (r, v, u))
        out = self._point(lv, r, v, u)
        keys, vals = self.known.get(lv, (np.zeros(0, np.int64), np.zeros((0, 3))))
        k = self._key(lv, r, v, u)
        pos = np.searchsorted(keys, k)
        hit = (pos < len(keys)) & (keys[np.minimum(pos, max(len(keys) - 1, 0))] == k) if len(keys) else \
            np.zeros(len(k), bool)
        out[hit] = vals[pos[hit]]
        return out


def _g(F, blk, level, u, v):
    """``G = F 4^l / A_c`` (0 for a node of no area)."""
    level = np.broadcast_to(level, np.shape(u))
    A = np.zeros(np.shape(u))
    for lv in np.unique(level):
        sel = level == lv
        A[sel] = blk.area[lv][v[sel], u[sel]]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(A[..., None] > 0, F * (4.0 ** level / A)[..., None], 0.0)


def non_adaptive(atlas, blk, m, level):
    """Links from every texel to every node of ``level`` with nonzero area (the paper's non-adaptive scheme)."""
    vv, uu = np.nonzero(blk.area[level] > 0)
    K, P = len(uu), atlas.texels
    node = np.broadcast_to(encode(level, uu, vv).astype(np.int32), (P, K)).copy()
    g = np.zeros((P, K, 3))
    step = _chunk(atlas)
    for s in range(0, P, step):
        rows = np.arange(s, min(s + step, P))
        est = Estimate(atlas, blk, m, rows)
        R = len(rows)
        F = est.get(level, np.repeat(np.arange(R), K), np.tile(vv, R), np.tile(uu, R)).reshape(R, K, 3)
        g[rows] = _g(F, blk, np.full(K, level), uu, vv)
    return Links(node, g, np.full(P, K), False)


def adaptive(atlas, blk, m, L):
    """Per texel, the top-down priority queue of Sec. 4.2.1 grown to at most ``L`` links."""
    P = atlas.texels
    node = np.full((P, L), -1, np.int32)
    g = np.zeros((P, L, 3))
    count = np.zeros(P, np.int64)
    step = _chunk(atlas)
    for s in range(0, P, step):
        rows = np.arange(s, min(s + step, P))
        node[rows], g[rows], count[rows] = _queue(atlas, blk, Estimate(atlas, blk, m, rows), len(rows), L)
    return Links(node, g, count, True)


def _queue(atlas, blk, est, R, L):
    """The priority queues of ``R`` receivers, their throughput from ``est`` (:class:`Estimate`)."""
    top = atlas.levels - 1
    rows = np.arange(R)
    lev = np.full((R, L), -1, np.int64)
    uu = np.zeros((R, L), np.int64)
    vv = np.zeros((R, L), np.int64)
    pri = np.full((R, L), -np.inf)
    lev[:, 0] = top
    pri[:, 0] = est.get(top, rows, np.zeros(R), np.zeros(R)).mean(axis=-1)
    count = np.ones(R, np.int64)
    active = np.ones(R, bool)
    while True:
        cand = np.where(lev > 0, pri, -np.inf)
        j = np.argmax(cand, axis=1)
        has = cand[rows, j] > -np.inf
        kl = np.maximum(lev[rows, j] - 1, 0)
        ku = 2 * uu[rows, j][:, None] + np.array([0, 1, 0, 1])
        kv = 2 * vv[rows, j][:, None] + np.array([0, 0, 1, 1])
        kvalid = np.zeros(ku.shape, bool)
        kpri = np.zeros(ku.shape)
        for lv in np.unique(kl[has]):
            sel = np.nonzero(has & (kl == lv))[0]
            kvalid[sel] = blk.area[lv][kv[sel], ku[sel]] > 0
            kpri[sel] = est.get(lv, np.repeat(sel, 4), kv[sel], ku[sel]).reshape(-1, 4, 3).mean(axis=-1)
        nk = kvalid.sum(axis=1)
        ok = active & has & (count - 1 + nk <= L)
        active &= ok
        if not ok.any():
            break
        rank = np.cumsum(kvalid, axis=1) - 1
        slot = np.where(rank == 0, j[:, None], count[:, None] + rank - 1)
        take = ok[:, None] & kvalid
        r, sl = np.broadcast_to(rows[:, None], ku.shape)[take], slot[take]
        lev[r, sl] = np.broadcast_to(kl[:, None], ku.shape)[take]
        uu[r, sl], vv[r, sl], pri[r, sl] = ku[take], kv[take], kpri[take]
        count = np.where(ok, count + nk - 1, count)
    used = lev >= 0
    lv = np.maximum(lev, 0)
    Fl = np.zeros((R, L, 3))
    for level in np.unique(lv[used]):
        sel = used & (lv == level)
        Fl[sel] = est.get(level, np.nonzero(sel)[0], vv[sel], uu[sel])
    g = np.where(used[..., None], _g(Fl, blk, lv, uu, vv), 0.0)
    return np.where(used, encode(lv, uu, vv), -1).astype(np.int32), g, count


def check_table(atlas_size, links, link_level, limit):
    """Refuse a link table over ``min(MAX_LINK_BYTES, limit)`` bytes, naming the setting that fits."""
    P = atlas_size * atlas_size
    budget = min(MAX_LINK_BYTES, int(limit))
    if link_level is None:
        need = P * links * LINK_BYTES
        if need > budget:
            fit = budget // (P * LINK_BYTES)
            raise InputError("--links", "links", f"{links} links per texel of a {atlas_size} x {atlas_size} atlas "
                             f"need a table of {need:,} bytes, over the {budget:,} that fit",
                             f"use --links {fit} or less, or a smaller --atlas-size")
        return need
    K = (atlas_size >> link_level) ** 2
    need = P * K * LINK_BYTES
    if need > budget:
        lo = next(lv for lv in range(link_level, 13) if P * (atlas_size >> lv) ** 2 * LINK_BYTES <= budget)
        raise InputError("--link-level", "link_level", f"level {link_level} links every texel of a {atlas_size} x "
                         f"{atlas_size} atlas to up to {K:,} nodes: a table of {need:,} bytes, over the {budget:,} that fit",
                         f"use --link-level {lo} or more, or a smaller --atlas-size")
    return need
