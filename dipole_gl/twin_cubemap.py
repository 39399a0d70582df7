"""NumPy twin of the cubemap gather (the thesis draft's real-time directional dipole, Ch. 4), pass by pass.

.. list-table::
   :header-rows: 1

   * - function
     - GL pass
     - thesis
     - what
   * - :func:`raycast`
     - ``rsm.vert/frag`` (light buffer), ``rsm.vert`` + ``cubemap_face.frag`` (faces)
     - Ch. 4.1, Steps 1 and 2
     - the first surface point along each texel centre's ray (perspective from a light, or
       orthographic from a face): position, normal, coverage, window depth; ray against every
       triangle (Moeller-Trumbore), the vertex normals interpolated
   * - :func:`closest_point`
     - ``cubemap_gather.comp`` (its first lookup)
     - Ch. 4.1, Fig. 4.3, Sec. 4.3.1
     - the light-buffer texel of the point moved by ``eps_g``, and the depth of the point closest to the light
   * - :func:`gather`
     - ``cubemap_gather.comp``
     - Ch. 4.1, Step 2 (the sum for ``C^f``), Sec. 4.3.1
     - ``C^f(x_o)`` at given face texels from the light buffers, averaged over the frames' rotations
   * - :func:`combine`
     - ``cubemap_combine.comp``
     - Ch. 4.1, Step 3, Secs. 4.3.2-4.3.3
     - the average over the faces that see the intruded point, times the exit Fresnel

Textures are arrays in GL's layout: ``[row, column]`` with row 0 at the bottom (as read back
without flipping), the six faces (or the lights' buffers) side by side along the columns.
Everything runs in float64; a texel index is ``floor(uv N)`` as in the shaders, so a lookup whose
``uv N`` lies within float32 rounding of a texel edge can pick the neighbouring texel in GL
(:func:`gather` and :func:`combine` report such points as ``ambiguous``, and :func:`gather` bounds
what a disc sample's neighbouring texel would change as ``slack``).
"""

from __future__ import annotations

import numpy as np

from sslpv_gl.optics import fresnel_transmittance

from . import kernels
from .cubemap_geometry import disc, rotations
from .twin import exit_coefficients

__all__ = ["raycast", "closest_point", "gather", "combine", "light_axis", "EDGE", "EDGE_SAMPLE"]

#: A lookup with ``uv N`` within this many texels of a texel edge is ambiguous between float32 and float64
#: (the disc's centre, a face texel in the combination): such a point is left out of a comparison.
EDGE = 1e-4
#: The same for a disc sample (its angle goes through GLSL's sin and cos): its neighbouring texel's
#: contribution is evaluated too, and the difference allowed (``slack``).
EDGE_SAMPLE = 1e-3


def light_axis(light_pos, centre):
    """The light's unit view axis (:func:`sslpv_gl.rsm.light_view` aims it at the bounding sphere's centre)."""
    a = np.asarray(centre, np.float64) - np.asarray(light_pos, np.float64)
    return a / np.linalg.norm(a)


def raycast(mesh, origins, dirs, pairs=2_000_000, faces=False):
    """First hit of each ray on ``mesh`` -> ``(position (R, 3), normal (R, 3), hit (R,), t (R,))``, and with
    ``faces`` the index of the hit triangle (R,) (-1 where the ray misses) after them.

    ``dirs`` unit; the normal interpolates the vertex normals barycentrically and is normalised
    (as ``cubemap_face.frag`` and ``rsm.frag`` do); back faces count (the rasteriser draws both).
    """
    v = np.asarray(mesh.vertices, np.float64)
    nv = np.asarray(mesh.normals, np.float64)
    f = np.asarray(mesh.faces, np.int64)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    e1, e2 = b - a, c - a
    o = np.asarray(origins, np.float64)
    d = np.asarray(dirs, np.float64)
    o = np.broadcast_to(o, d.shape)
    R = len(d)
    best = np.full(R, np.inf)
    tri = np.full(R, -1)
    bu, bv = np.zeros(R), np.zeros(R)
    step = max(1, pairs // len(f))                    # rays per chunk: at most ``pairs`` ray-triangle tests
    for s in range(0, R, step):
        sl = slice(s, min(R, s + step))
        dd, oo = d[sl, None, :], o[sl, None, :]
        p = np.cross(dd, e2[None])
        det = np.sum(e1[None] * p, axis=-1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            tv = oo - a[None]
            u = np.sum(tv * p, axis=-1) * inv
            q = np.cross(tv, e1[None])
            w = np.sum(dd * q, axis=-1) * inv
            t = np.sum(e2[None] * q, axis=-1) * inv
            ok = (np.abs(det) > 1e-14) & (u >= 0) & (w >= 0) & (u + w <= 1) & (t > 0)
        t = np.where(ok, t, np.inf)
        k = np.argmin(t, axis=1)
        tk = t[np.arange(len(k)), k]
        best[sl], tri[sl] = tk, np.where(np.isfinite(tk), k, -1)
        bu[sl], bv[sl] = u[np.arange(len(k)), k], w[np.arange(len(k)), k]
    hit = tri >= 0
    pos = np.where(hit[:, None], o + np.where(hit, best, 0.0)[:, None] * d, 0.0)
    ft = f[np.maximum(tri, 0)]
    n = (1 - bu - bv)[:, None] * nv[ft[:, 0]] + bu[:, None] * nv[ft[:, 1]] + bv[:, None] * nv[ft[:, 2]]
    n = np.where(hit[:, None], n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300), 0.0)
    out = (pos, n, hit, np.where(hit, best, np.inf))
    return out + (tri,) if faces else out


def _edge(x, tol):
    """True where ``x`` (in texels) lies within ``tol`` texels of an integer."""
    return np.abs(x - np.round(x)) < tol


def closest_point(xo, no, light_pos, view, axis, lb_pos, lb_valid, eps_g):
    """The disc's centre for exit points ``xo`` (P, 3) in one light's buffer (``lb_pos`` (S, S, 3), ``lb_valid``):
    ``(uv (P, 2), found (P,), depth (P,), ambiguous (P,))`` (thesis Fig. 4.3, Sec. 4.3.1).

    ``x'_o = x_o - eps_g (n_o - w_l (w_l . n_o))`` (``eps_g`` in texels at ``x_o``'s depth along the light's
    ``axis``) projected with the light's matrix; ``found``: the texel there is covered, and ``depth`` is then
    the depth of the point it holds (``x_o^T``), else ``x_o``'s own.
    """
    S = lb_pos.shape[0]
    L = np.asarray(light_pos, np.float64)
    th = float(view.tan_half)
    wl = L - xo
    wl /= np.linalg.norm(wl, axis=1, keepdims=True)
    depth_o = (xo - L) @ axis
    eps = eps_g * 2.0 * th / S * depth_o
    xs = xo - eps[:, None] * (no - wl * np.sum(wl * no, axis=1, keepdims=True))           # Sec. 4.3.1
    clip = np.concatenate([xs, np.ones((len(xo), 1))], axis=1) @ view.view_proj.T
    uv = clip[:, :2] / clip[:, 3:4] * 0.5 + 0.5
    tc = np.floor(uv * S).astype(np.int64)
    inside = np.all((tc >= 0) & (tc < S), axis=1)
    tcc = np.clip(tc, 0, S - 1)
    found = inside & lb_valid[tcc[:, 1], tcc[:, 0]]
    depth = np.where(found, (lb_pos[tcc[:, 1], tcc[:, 0]] - L) @ axis, depth_o)
    return uv, found, depth, np.any(_edge(uv * S, EDGE), axis=1)


def gather(kernel, exit_pos, exit_nrm, lb_pos, lb_nrm, lb_valid, lights, views, axes, mat, eta, samples, frames,
           disc_radius, eps_g):
    """``(C (P, 3), ambiguous (P,), slack (P, 3))``: the face texels' gathered radiance over ``frames`` rotations.

    ``lb_pos``/``lb_nrm`` (S, S L, 3) and ``lb_valid`` (S, S L) are the light buffers (GL layout,
    light ``l`` in columns ``l S .. (l + 1) S - 1``); ``views`` the lights'
    :class:`sslpv_gl.rsm.LightView`, ``axes`` their unit view axes; ``disc_radius`` in world units,
    ``eps_g`` in light-buffer texels. ``C`` has no exit Fresnel (:func:`combine` applies it).
    ``ambiguous``: the disc's centre lookup lies within :data:`EDGE` of a texel edge (GL may take the
    neighbour, and with it another disc size). ``slack``: for every disc sample within
    :data:`EDGE_SAMPLE` of a texel edge, ``|contribution with the neighbouring texel - contribution|``,
    summed; GL may differ from ``C`` by up to that (float32 against float64 picking the other texel).
    """
    xo = np.asarray(exit_pos, np.float64)
    no = np.asarray(exit_nrm, np.float64)
    P = len(xo)
    S = lb_pos.shape[0]
    m = exit_coefficients(mat, xo, no, eta)
    ms = {k: (v[:, None] if isinstance(v, np.ndarray) and v.ndim == 2 else v) for k, v in m.items()}
    pts = disc(samples)                                           # (k, 2)
    out = np.zeros((P, 3))
    slack = np.zeros((P, 3))
    amb = np.zeros(P, bool)
    for l, (light, view) in enumerate(zip(lights, views)):
        L = np.asarray(light.position, np.float64)
        I = np.asarray(light.intensity, np.float64)
        ax = np.asarray(axes[l], np.float64)
        th = float(view.tan_half)
        wl = L - xo
        wl /= np.linalg.norm(wl, axis=1, keepdims=True)
        uv, ok, depth, edge = closest_point(xo, no, L, view, ax, lb_pos[:, l * S:(l + 1) * S], lb_valid[:, l * S:(l + 1) * S],
                                            eps_g)
        amb |= edge
        r_uv = disc_radius / (2.0 * th * depth)
        plane = np.pi / samples * r_uv**2 * 4.0 * th * th                                # (P,)

        def contribution(uj, tj):
            """(P, k, 3) per-sample ``L S (n.w) F_t dA`` (times I) of the samples at ``uj`` read from texels ``tj``."""
            inb = np.all((uj >= 0.0) & (uj < 1.0), axis=-1) & np.all((tj >= 0) & (tj < S), axis=-1)
            tj = np.clip(tj, 0, S - 1)
            cj = tj[..., 0] + l * S
            valid = inb & lb_valid[tj[..., 1], cj]
            xi = lb_pos[tj[..., 1], cj]
            ni = lb_nrm[tj[..., 1], cj]
            to = L - xi
            d2 = np.maximum(np.sum(to * to, axis=-1), 1e-300)
            wi = to / np.sqrt(d2)[..., None]
            cos_i = np.sum(wi * ni, axis=-1)
            use = valid & (cos_i > 0.0)
            qq = (uj * 2.0 - 1.0) * th
            ct = 1.0 / np.sqrt(1.0 + np.sum(qq * qq, axis=-1))
            dA = plane[:, None] * ct**3 * d2 / np.where(use, cos_i, 1.0)                 # surface area per sample
            e = np.where(use, cos_i / d2 * fresnel_transmittance(np.where(use, cos_i, 1.0), eta) * dA, 0.0)
            if kernel == "dipole":
                k = kernels.rd_dipole(np.linalg.norm(xo[:, None] - xi, axis=-1)[..., None], ms) / np.pi
            else:
                b = lambda a: np.broadcast_to(a[:, None], xi.shape)                        # noqa: E731
                k = kernels.dirpole_sd(np.where(use[..., None], xi, b(xo) - b(no)), np.where(use[..., None], ni, b(no)),
                                       np.where(use[..., None], wi, b(wl)), b(xo), b(no), ms)
            return np.where(use[..., None], k, 0.0) * e[..., None] * I

        for phi in rotations(frames):
            rot = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
            # the shader's angle j GOLDEN_ANGLE + phi: the spiral rotated by phi
            uj = uv[:, None, :] + r_uv[:, None, None] * (pts @ rot.T)[None]              # (P, k, 2)
            f = uj * S
            tj = np.floor(f).astype(np.int64)
            near = _edge(f, EDGE_SAMPLE)
            c0 = contribution(uj, tj)
            out += np.sum(c0, axis=1) / frames
            if near.any():
                alt = tj + np.where(near, np.where(f - tj < 0.5, -1, 1), 0)
                diff = np.abs(contribution(uj, alt) - c0) * np.any(near, axis=-1)[..., None]
                slack += np.sum(diff, axis=1) / frames
    return out, amb, slack


def combine(gpos, gnrm, face_pos_valid, face_z, accum, cube, face_size, eps_c, eps_b, cam_pos, eta):
    """``(L (P, 3), visible faces (P,), ambiguous (P,))`` at the camera's exit points (thesis Step 3).

    ``face_pos_valid`` (N, 6 N) the faces' coverage, ``face_z`` (N, 6 N) their window depth,
    ``accum`` (N, 6 N, 3) the gathered ``C^f``; ``eps_c``/``eps_b`` in world units.
    """
    x = np.asarray(gpos, np.float64)
    n = np.asarray(gnrm, np.float64)
    N = int(face_size)
    xs = x - eps_c * n                                                                   # Sec. 4.3.2
    P = len(x)
    total = np.zeros((P, 3))
    count = np.zeros(P)
    amb = np.zeros(P, bool)
    f_, n_ = cube.far, cube.near
    for f, face in enumerate(cube.faces):
        uv = np.stack([(xs - cube.centre) @ face.right, (xs - cube.centre) @ face.up], axis=1) / (2.0 * cube.half) + 0.5
        t = np.floor(uv * N).astype(np.int64)
        inb = np.all((t >= 0) & (t < N), axis=1)
        tc = np.clip(t, 0, N - 1)
        col = tc[:, 0] + f * N
        cov = inb & face_pos_valid[tc[:, 1], col]
        z = face_z[tc[:, 1], col]
        d_face = 0.5 * (f_ - n_) * (2.0 * z - 1.0 + (f_ + n_) / (f_ - n_))               # Sec. 4.3.3
        d_point = (xs - face.eye) @ face.dir
        vis = cov & (d_point < d_face + eps_b)
        amb |= inb & (np.any(_edge(uv * N, EDGE), axis=1) | (cov & (np.abs(d_point - d_face - eps_b) < 1e-4 * cube.half)))
        total += np.where(vis[:, None], accum[tc[:, 1], col], 0.0)
        count += vis
    wo = np.asarray(cam_pos, np.float64) - x
    cos_o = np.sum(wo * n, axis=1) / np.linalg.norm(wo, axis=1)
    out = np.where(count[:, None] > 0, total / np.maximum(count, 1)[:, None], 0.0)
    return out * fresnel_transmittance(np.clip(cos_o, 0.0, 1.0), eta)[:, None], count, amb
