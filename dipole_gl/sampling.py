"""The dense gather's sampling: surface samples for the far field, a polar quadrature for the near field.

The kernel is split by the window ``w(r) = 1 - smoothstep(0, rho, r)`` (``smoothstep(t) =
3t^2 - 2t^3``), ``rho = NEAR_RADIUS * h``: the far field ``(1 - w) K`` is smooth on the scale
of ``h`` and is summed over the surface samples below; the near field ``w K``, where both
kernels peak (the directional dipole's real source sits at ``d_r >= D mu_0``, a spike of width
``D mu_0`` at grazing light), is integrated per exit point on its tangent plane with its own
irradiance, by :func:`radial_nodes` (Gauss-Legendre panels that shrink geometrically towards
``r = 0``) times :data:`N_PHI` equally spaced angles. Both approximations of the near field
(a flat surface, constant irradiance within ``rho``) vanish with ``h``.

Triangle ``(a, b, c)`` with longest edge ``e`` is split into ``m^2`` congruent
sub-triangles, ``m = ceil(e / h)`` with ``h = spacing * l'`` (``l'`` the smallest reduced
mean free path, :mod:`dipole_gl.medium`), so no sub-triangle edge exceeds ``h``. One
sample sits at each sub-triangle's centroid with the sub-triangle's area as its weight
(the midpoint rule), and the vertex normals interpolated there. The samples cover the
whole closed surface, lit or not; the irradiance pass gives the unlit ones zero.
"""

from __future__ import annotations

import math

import numpy as np

from harness.errors import InputError

__all__ = ["surface_samples", "MAX_SAMPLES", "subdivision_barycentrics", "radial_nodes", "window", "NEAR_RADIUS",
           "N_PHI", "MAX_FRAME_PAIRS"]

#: A dense gather with more samples than this is refused (the fix: a larger ``--spacing``).
MAX_SAMPLES = 2_000_000
#: A dense gather that would evaluate more (pixel, sample) pairs per frame than this is refused.
MAX_FRAME_PAIRS = 2_000_000_000
#: The near-field radius, in sample spacings ``h``.
NEAR_RADIUS = 3.0
#: Angles of the near-field quadrature (the trapezoid rule, exact for trigonometric polynomials of degree < 16).
N_PHI = 16


def radial_nodes(ratio=0.25, panels=7, order=6):
    """``(t, w)`` on ``[0, 1]``: ``order``-point Gauss-Legendre on the panels ``[0, q^P], [q^P, q^(P-1)], ..., [q, 1]``.

    With ``q = 0.25``, ``P = 7`` and 6 nodes (48 in all) the smallest panel is ``6e-5 rho`` wide:
    the near-field peaks (width ``z_r`` or ``D mu_0``) are resolved for ``rho`` from ``0.3 z_r`` to
    ``100 z_r`` (the standard dipole's near field within 4e-6 of its closed form, Eq. K8).
    """
    x, wts = np.polynomial.legendre.leggauss(int(order))
    edges = [0.0] + [ratio ** k for k in range(panels, 0, -1)] + [1.0]
    t, w = [], []
    for a, b in zip(edges[:-1], edges[1:]):
        t.append(a + (b - a) * (x + 1.0) / 2.0)
        w.append((b - a) / 2.0 * wts)
    return np.concatenate(t), np.concatenate(w)


def window(r, rho):
    """``w(r) = 1 - smoothstep(0, rho, r)`` (GLSL's ``smoothstep``): 1 at 0, 0 from ``rho`` on."""
    t = np.clip(np.asarray(r, dtype=np.float64) / rho, 0.0, 1.0)
    return 1.0 - t * t * (3.0 - 2.0 * t)


def subdivision_barycentrics(m):
    """Barycentric ``(u, v)`` of the centroids of the ``m^2`` sub-triangles -> (m^2, 2)."""
    pts = []
    for i in range(m):
        for j in range(m - i):
            pts.append(((i + 1.0 / 3.0) / m, (j + 1.0 / 3.0) / m))            # upright
            if i + j <= m - 2:
                pts.append(((i + 2.0 / 3.0) / m, (j + 2.0 / 3.0) / m))        # inverted
    return np.asarray(pts, dtype=np.float64)


def surface_samples(mesh, h):
    """``(positions (S,3), normals (S,3), areas (S,))`` float64 of the dense gather at spacing ``h``."""
    v = np.asarray(mesh.vertices, dtype=np.float64)
    f = np.asarray(mesh.faces, dtype=np.int64)
    nv = np.asarray(mesh.normals, dtype=np.float64)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    edges = np.stack([np.linalg.norm(b - a, axis=1), np.linalg.norm(c - b, axis=1), np.linalg.norm(a - c, axis=1)])
    m = np.maximum(np.ceil(edges.max(axis=0) / h), 1).astype(np.int64)
    total = int(np.sum(m * m))
    if total > MAX_SAMPLES:
        raise InputError("--spacing", "spacing", f"the dense gather would need {total:,} surface samples "
                         f"(more than {MAX_SAMPLES:,})", "raise --spacing")
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    pos, nrm, wts = [], [], []
    for mm in np.unique(m):
        sel = np.nonzero(m == mm)[0]
        uv = subdivision_barycentrics(int(mm))                            # (k, 2)
        u, w = uv[:, 0][None, :, None], uv[:, 1][None, :, None]
        pa, pb, pc = a[sel][:, None], b[sel][:, None], c[sel][:, None]
        pos.append((pa + u * (pb - pa) + w * (pc - pa)).reshape(-1, 3))
        na, nb, nc = nv[f[sel, 0]][:, None], nv[f[sel, 1]][:, None], nv[f[sel, 2]][:, None]
        n = (1.0 - u - w) * na + u * nb + w * nc
        nrm.append((n / np.linalg.norm(n, axis=-1, keepdims=True)).reshape(-1, 3))
        wts.append(np.repeat(area[sel] / (mm * mm), len(uv)))
    return np.concatenate(pos), np.concatenate(nrm), np.concatenate(wts)


def sample_count(mesh, h):
    """The number of samples :func:`surface_samples` would make (without making them)."""
    v = np.asarray(mesh.vertices, dtype=np.float64)
    f = np.asarray(mesh.faces, dtype=np.int64)
    tri = v[f]
    e = np.linalg.norm(tri - np.roll(tri, -1, axis=1), axis=2).max(axis=1)
    return int(np.sum(np.maximum(np.ceil(e / h), 1) ** 2)) if math.isfinite(h) else len(f)
