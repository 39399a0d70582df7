"""NumPy twin of the hierarchical gather (``gather_tree.comp``): the same decisions, by another route.

The GL pass walks the octree sequentially (refine: next node; accept or leave a leaf: ``skip``).
Here the nodes that walk visits are found at once, per exit point (:func:`visited_nodes`): each
internal node's decision (refine or not) is computed for every node, and a node is visited unless
it lies strictly inside the subtree ``(j, skip_j)`` of an internal node ``j`` that is not refined;
the union of those subtrees is marked by a difference array. A node not refined blocks its whole
subtree whether or not it is itself visited, so the union is the same. The decisions use the same
float32 arithmetic as the shader on the float32 values it reads (the cell, the centroid, the area,
``epsilon`` and ``rho``), so that both make the same choice at a node on the boundary.

Then (:func:`tree_gather`) the visited leaves add the dense far field's terms
(:func:`dipole_gl.twin.dense_gather`: window ``1 - w(r)``, kernel, flux), the accepted internal
nodes their aggregate at the centroid (:mod:`dipole_gl.octree`), and the near field and the exit
Fresnel transmittance are the dense gather's (:func:`dipole_gl.twin.near_field`). Float64 throughout.
"""

from __future__ import annotations

import numpy as np

from sslpv_gl.optics import fresnel_transmittance

from . import kernels, twin
from .sampling import NEAR_RADIUS, window

__all__ = ["visited_nodes", "tree_gather"]

F32 = np.float32


def visited_nodes(tree, agg, xo, epsilon, rho):
    """``(leaf samples, accepted internal nodes k, visits)`` of the descent for one exit point ``xo``."""
    N = tree.nodes
    internal = tree.internal >= 0
    k = tree.internal[internal]
    x = np.asarray(xo, F32)
    cell = tree.cell[internal].astype(F32)
    dq = np.maximum(np.abs(x - cell[:, :3]) - cell[:, 3:], F32(0))
    near = np.sum(dq * dq, axis=1, dtype=F32) < F32(rho) * F32(rho)
    dp = agg.centroid[k].astype(F32) - x
    crit = agg.area[k].astype(F32) > F32(epsilon) * np.sum(dp * dp, axis=1, dtype=F32)
    lit = agg.weight[k].astype(F32) > F32(0)
    stop = np.zeros(N, bool)
    stop[internal] = ~(lit & (near | crit))                    # unlit, or used whole
    j = np.nonzero(stop)[0]
    diff = np.zeros(N + 1, np.int64)
    np.add.at(diff, j + 1, 1)
    np.add.at(diff, tree.skip[j], -1)
    visited = np.cumsum(diff)[:N] == 0
    lit_all = np.zeros(N, bool)
    lit_all[internal] = lit
    accepted = visited & stop & lit_all
    leaves = visited & ~internal
    return tree.first[leaves], tree.internal[accepted], int(visited.sum())


def tree_gather(kernel, tree, agg, exit_pos, exit_nrm, cam_pos, flux, dirs, mat, eta, spacing, lights, exit_vis,
                epsilon):
    """``(radiance (P, 3), visits (P,))`` at exit points: the hierarchical gather over ``tree``.

    ``flux``/``dirs`` (L, S, 3) of the tree's (sorted) samples from :func:`dipole_gl.twin.irradiance`,
    ``agg`` their :func:`dipole_gl.octree.aggregate`; other arguments as :func:`dipole_gl.twin.dense_gather`.
    """
    xo = np.asarray(exit_pos, np.float64)
    no = np.asarray(exit_nrm, np.float64)
    m = twin.exit_coefficients(mat, xo, no, eta)
    rho = NEAR_RADIUS * spacing
    total = flux.sum(axis=0)
    out = np.zeros((len(xo), 3))
    visits = np.zeros(len(xo), np.int64)
    for p in range(len(xo)):
        leaves, nodes, visits[p] = visited_nodes(tree, agg, xo[p], epsilon, rho)
        mp = twin._sliced(m, slice(p, p + 1))
        xi, ni = tree.positions[leaves], tree.normals[leaves]
        far = 1.0 - window(np.linalg.norm(xo[p] - xi, axis=-1), rho)[:, None]
        c, cn = agg.centroid[nodes], agg.normal[nodes]
        if kernel == "dipole":
            out[p] += np.sum(far * twin._pair_kernel(kernel, xi, ni, None, xo[p:p + 1], no[p:p + 1], mp)[0]
                             * total[leaves], axis=0)
            out[p] += np.sum(twin._pair_kernel(kernel, c, cn, None, xo[p:p + 1], no[p:p + 1], mp)[0]
                             * agg.total[nodes], axis=0)
            continue
        for li in range(len(flux)):
            lit = np.any(flux[li, leaves] > 0.0, axis=1)       # as the dense gather
            out[p] += np.sum(far[lit] * twin._pair_kernel(kernel, xi[lit], ni[lit], dirs[li, leaves][lit],
                                                          xo[p:p + 1], no[p:p + 1], mp)[0] * flux[li, leaves][lit],
                             axis=0)
            sel = np.any(agg.flux[li, nodes] != 0.0, axis=1)
            sd = kernels.dirpole_sd(c[sel], cn[sel], agg.to_light[li, nodes][sel], np.broadcast_to(xo[p], c[sel].shape),
                                    np.broadcast_to(no[p], c[sel].shape), {a: (v[0] if isinstance(v, np.ndarray)
                                                                             and v.ndim == 3 else v)
                                                                         for a, v in mp.items()})
            out[p] += np.sum(np.nan_to_num(sd, nan=0.0) * agg.flux[li, nodes][sel], axis=0)   # NaN: no refraction
    out += twin.near_field(kernel, xo, no, m, rho, lights, exit_vis, eta)
    wo = np.asarray(cam_pos, np.float64) - xo
    cos_o = np.sum(wo * no, axis=-1) / np.linalg.norm(wo, axis=-1)
    return out * fresnel_transmittance(np.clip(cos_o, 0.0, 1.0), eta)[:, None], visits
