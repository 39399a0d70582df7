"""How far a rasterised texel's surface point may lie from the ray cast through the texel's centre.

A G-buffer texel (an RSM's or a cube face's position and normal) interpolates the triangle's vertex
attributes at the barycentric coordinates of the texel's centre. OpenGL keeps window coordinates to
``GL_SUBPIXEL_BITS`` bits of sub-pixel precision (an implementation-dependent value, at least 4), so the
rasteriser may compute those from vertices snapped to that grid. Snapping to the nearest grid point
moves each vertex by at most half a grid step along each axis, so the barycentrics are those of a point
at most ``sqrt(2) / 2 * 2**-bits`` pixels from the centre on the unsnapped triangle; with truncation
instead of rounding, ``sqrt(2) * 2**-bits``, the bound used here (:func:`subpixel_bound`). The
interpolated position lies on the triangle's plane, that far from the centre's hit measured through the
texel's footprint on the plane; the interpolated normal is the mesh's normal at that position, not at
the hit.

So the checks are, per texel (:func:`split_offset`):

* the distance of the GL position from the hit triangle's plane, against the float32 rounding of one
  interpolation (a few 1e-6 of the mesh's size);
* the position's offset from the hit within the plane, in texels (solved in the footprint spanned by
  where the neighbouring texel centres' rays meet the plane), against :func:`subpixel_bound`.

A texel centre shifted by a fraction of a texel (a half-texel convention wrong, a projection off) moves
the in-plane offset by that fraction, far above the bound (``glsl_rsm_subtexel_shift`` in
``tests/mutations/catalogue.py`` plants 1/64 of a texel).

Measured with :func:`split_offset` on the suite's sphere and torus RSMs (64^2 injection map, 256^2 shadow
map): in-plane offsets of at most 3.3e-4 texels on llvmpipe and 2.5e-3 on an NVIDIA H200 (driver
580.159.04, GL_SUBPIXEL_BITS 8, bound 5.5e-3); off-plane at most 4e-6 of the mesh's size on both.

Limits: the footprint is the linearisation at the hit, valid for offsets far below a texel; at grazing
incidence a texel's footprint is long, so the same texel offset is a longer distance; a texel whose
centre's ray hits another triangle than the one the rasteriser chose (an edge, a silhouette) is not
covered: callers pass the hit triangle their ray caster found.
"""

import numpy as np

#: The fewest sub-pixel bits OpenGL allows (SUBPIXEL_BITS among the implementation-dependent values, minimum 4).
MIN_SUBPIXEL_BITS = 4


def subpixel_bound(ctx):
    """The largest in-plane offset, in texels, that snapping to the context's sub-pixel grid explains."""
    bits = int(ctx.info.get("GL_SUBPIXEL_BITS") or MIN_SUBPIXEL_BITS)
    return float(np.sqrt(2.0) * 2.0 ** -bits)


def plane_hits(origins, dirs, point, normal):
    """Where rays (origins broadcast to dirs) meet the planes through ``point`` with ``normal`` (row-wise)."""
    origins = np.broadcast_to(np.asarray(origins, np.float64), dirs.shape)
    s = np.einsum("ij,ij->i", point - origins, normal) / np.einsum("ij,ij->i", dirs, normal)
    return origins + s[:, None] * dirs


def split_offset(pos, hit, normal, right_hit, up_hit):
    """``(off_plane, texels)`` of GL positions ``pos`` against the hits of their texel centres.

    ``normal``: the hit triangle's unit normal; ``right_hit``/``up_hit``: where the rays through the next
    texel centres along the two texel axes meet that plane (:func:`plane_hits`). ``off_plane`` is the
    distance of ``pos`` from the plane; ``texels`` the length, in texels, of its offset within the plane.
    """
    delta = np.asarray(pos, np.float64) - hit
    off_plane = np.abs(np.einsum("ij,ij->i", delta, normal))
    J = np.stack([right_hit - hit, up_hit - hit], axis=-1)                      # (n, 3, 2): one texel each way
    JtJ = np.einsum("nki,nkj->nij", J, J)
    uv = np.linalg.solve(JtJ, np.einsum("nki,nk->ni", J, delta)[..., None])[..., 0]
    return off_plane, np.linalg.norm(uv, axis=1)


def interpolated_normals(mesh, face, point):
    """The mesh's vertex normals interpolated at ``point`` (on face ``face``'s plane), normalised: barycentrics
    from the normal equations of ``point - a = v (b - a) + w (c - a)``."""
    tri = np.asarray(mesh.vertices, np.float64)[mesh.faces[face]]
    e1, e2, d = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], np.asarray(point, np.float64) - tri[:, 0]
    d11, d12, d22 = (np.einsum("ij,ij->i", a, b) for a, b in ((e1, e1), (e1, e2), (e2, e2)))
    p1, p2 = np.einsum("ij,ij->i", d, e1), np.einsum("ij,ij->i", d, e2)
    den = d11 * d22 - d12 * d12
    v, w = (d22 * p1 - d12 * p2) / den, (d11 * p2 - d12 * p1) / den
    bary = np.stack([1 - v - w, v, w], axis=1)
    n = np.einsum("ij,ijk->ik", bary, np.asarray(mesh.normals, np.float64)[mesh.faces[face]])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def face_normals(mesh, face):
    """Unit geometric normals of faces ``face``."""
    tri = np.asarray(mesh.vertices, np.float64)[mesh.faces[face]]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    return n / np.linalg.norm(n, axis=1, keepdims=True)
