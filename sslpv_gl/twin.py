"""NumPy twin of the SSLPV pipeline (Borlum et al., HPG 2011, Sec. 3-4).

An independent, vectorised float64 implementation of injection,
propagation and shading, written from the paper and ``docs/conventions.md``
only, so that the GL renderer can be checked against it cell by cell.

Stages
------

.. list-table::
   :header-rows: 1

   * - function
     - paper
     - parameters (defaults)
   * - ``inject(texels, light_pos, bbox_min, bbox_max, N, eta=1.0, offset=0.0, depth=None)``
     - Sec. 3.1, Eq. 1
     - ``texels`` (M, 10) RSM of ONE light; ``offset`` moves the virtual
       point light ``offset`` scene units inwards along ``-n_p`` (0 = paper)
   * - ``propagate(c0, sigma_lpv, sigma_s_prime, g, dx, steps, skip=2, matrices=None, emit=None)``
     - Sec. 3.2, Eq. 3, Sec. 4
     - transfer rule of ``docs/conventions.md``; accumulate steps ``k > skip``;
       ``emit`` (0/1 per cell) makes sink cells (``sslpv_gl.boundary``)
   * - ``shade_points(accum, bbox_min, bbox_max, points, normals, lookup="cell", eta=1.0, view_dirs=None, eta2=False, radiance_scale=None, shade_depth=0.0)``
     - Sec. 3.3, Eq. 4-7
     - ``"cell"`` or ``"trilinear"`` coefficient lookup; ``eta2`` adds the
       ``1/eta^2`` radiance factor (not in the paper); ``shade_depth`` reads
       the grid that many cells inwards (``sslpv_gl.shade`` Eq. (S1); not in the paper)

Grids are ``(N, N, N, 3, 4)`` indexed ``[z, y, x, colour, coeff]`` with the
coefficient order ``(c00, c1-1, c10, c11)``.

Limits
------
* Several lights: call :func:`inject` once per light (each with its own RSM
  and position) and sum the grids; everything after injection is linear.
* Cubic cells are assumed for the area ``A = dx^2`` of Eq. 5 (x width used).
* Texels whose normal faces away from the light (interpolated normals at a
  silhouette) are treated, here and in ``inject.vert``, as light arriving
  from INSIDE the medium: refracted with ``1/eta`` (the lobe then points out
  of the surface) and weighted by the Fresnel transmittance for that side,
  which is 0 beyond the critical angle ``asin(1/eta)`` (total internal
  reflection) but NOT in general (e.g. ``T = 0.969`` for ``eta = 1.4`` at
  ``cos = 0.9``); for ``eta == 1`` they pass unchanged with ``T = 1``.
* ``eta2=True`` in :func:`shade_points` divides the subsurface radiance by
  ``eta^2`` (radiance leaving a medium of index ``eta``, as Mitsuba does);
  the paper's Eq. 4 omits it, so the default is ``False``.
"""

from __future__ import annotations

import numpy as np

from . import reflect
from .optics import fresnel_transmittance, refract
from .sh import SOURCE_OFFSETS, clamped_cosine_coeffs, hemisphere_radiance, neighbour_slices, propagation_matrices, scatter_factors

__all__ = ["inject", "propagate", "shade_points", "cell_index", "sample_trilinear"]


def _grid_geometry(bbox_min, bbox_max, N):
    bmin = np.asarray(bbox_min, dtype=np.float64)
    bmax = np.asarray(bbox_max, dtype=np.float64)
    return bmin, (bmax - bmin) / int(N)


def cell_index(points, bbox_min, bbox_max, N):
    """Integer ``(x, y, z)`` index of the cell containing each point, clamped to the grid."""
    bmin, dx = _grid_geometry(bbox_min, bbox_max, N)
    idx = np.floor((np.asarray(points, dtype=np.float64) - bmin) / dx).astype(np.int64)
    return np.clip(idx, 0, int(N) - 1)


# ------------------------------------------------------------------ injection

def inject(texels, light_pos, bbox_min, bbox_max, N, eta=1.0, offset=0.0, depth=None):
    """Inject one light's RSM texels into an SH grid (Sec. 3.1) -> (N,N,N,3,4) float64.

    For each valid texel ``p``: ``w_i = normalize(x_p - light_pos)``,
    ``w_t = refract(w_i, n_p, eta)``, ``T = fresnel_transmittance(-w_i.n_p, eta)``
    and Eq. 1, ``I_p(w) = (1/pi) T Phi_p max(0, w_t.w)``, whose SH
    coefficients are ``(1/pi) T Phi_p clamped_cosine_coeffs(w_t)``. The lobe
    is added to the cell that contains ``x_p - offset * n_p`` (clamped into
    the grid); all texels of a cell sum to one point light at its centre.
    ``depth`` (an extension): None, or an (N,N,N) grid ``[z, y, x]`` of further
    inward moves (:func:`sslpv_gl.inject.depth_offsets`, Eq. (J1)), read in the
    cell that contains ``x_p`` and added to ``offset``.
    """
    tex = np.asarray(texels, dtype=np.float64).reshape(-1, 10)
    N = int(N)
    grid = np.zeros((N, N, N, 3, 4), dtype=np.float64)
    tex = tex[tex[:, 9] > 0.5]
    if tex.shape[0] == 0:
        return grid
    x_p, n_p, phi = tex[:, 0:3], tex[:, 3:6], tex[:, 6:9]
    n_p = n_p / np.linalg.norm(n_p, axis=-1, keepdims=True)
    w_i = x_p - np.asarray(light_pos, dtype=np.float64)
    w_i /= np.linalg.norm(w_i, axis=-1, keepdims=True)

    cos_i = -np.sum(w_i * n_p, axis=-1)              # > 0: light arrives from outside
    w_t = refract(w_i, n_p, eta)
    T = fresnel_transmittance(cos_i, eta)
    tir = ~np.isfinite(w_t).all(axis=-1)
    w_t[tir] = w_i[tir]                              # T = 0 there; any direction will do
    T = np.where(tir, 0.0, T)

    lobe = clamped_cosine_coeffs(w_t) / np.pi        # Eq. 1 per unit flux
    coeffs = (T[:, None] * phi)[:, :, None] * lobe[:, None, :]   # (M, 3, 4)

    off = np.full(x_p.shape[0], float(offset))
    if depth is not None:
        hi, hj, hk = cell_index(x_p, bbox_min, bbox_max, N).T
        off = off + np.asarray(depth, dtype=np.float64)[hk, hj, hi]
    pos = x_p - off[:, None] * n_p
    i, j, k = cell_index(pos, bbox_min, bbox_max, N).T
    np.add.at(grid, (k, j, i), coeffs)
    return grid


# ---------------------------------------------------------------- propagation

def _shift_from(a, offset):
    """``out[d] = a[d + offset]`` with zeros where ``d + offset`` leaves the grid.

    ``a`` is indexed ``[z, y, x, ...]``; ``offset`` is ``(ox, oy, oz)``.
    """
    out = np.zeros_like(a)
    dst, src = neighbour_slices(offset)
    out[dst] = a[src]
    return out


def propagate(c0, sigma_lpv, sigma_s_prime, g, dx, steps, skip=2, matrices=None, emit=None, empty=None,
              r_dr=0.0, inside=None):
    """Propagate and accumulate (Sec. 3.2, Eq. 3, Sec. 4) -> ``(prop, accum)``.

    One step, for every destination ``d`` and each of its six neighbours
    ``s`` (conventions' transfer rule)::

        c_d += M_s @ (exp(-0.5 (sigma_lpv[s] + sigma_lpv[d]) dx) * S(s) c_s)

    with ``S(s) = diag(1, k1, k1, k1)``, ``k1 = (1 - sp[s]) + sp[s] g[s]``
    (Eq. 3 on the SOURCE cell), zero contribution from outside the grid. The
    propagation grid is replaced by the gathered one each step (the paper's
    ping-pong). ``accum`` sums the propagation grid after steps
    ``k = skip+1 .. steps``.

    ``c0`` (N,N,N,3,4); material grids (N,N,N,3); ``dx`` scalar or
    ``(dx, dy, dz)`` (the step along an axis uses that axis' width);
    ``matrices`` defaults to :func:`sslpv_gl.sh.propagation_matrices`.
    ``emit`` (N,N,N,3), default 1: a factor on what each SOURCE cell sends on;
    0 makes a sink that keeps (and accumulates) what it received but passes
    nothing on (``outside = absorb`` / ``extrapolated``, :mod:`sslpv_gl.boundary`),
    from step 2 on: step 1 propagates the injected light from every cell.
    ``empty`` (N,N,N,3), default 0: 1 marks an empty cell (``outside = interior``);
    the transfer from ``s`` to ``d`` is multiplied by ``1 - empty[s] empty[d]``, so
    no light ever moves between two empty cells (at every step, the first included).
    ``r_dr`` with ``inside`` (N,N,N) bool: ``boundary_reflect = rdr``
    (:mod:`sslpv_gl.reflect`, Eq. (R3)): across each surface face (inside source,
    outside or off-grid neighbour) the transfer keeps ``1 - r_dr`` and the source
    receives ``r_dr exp(-sigma_lpv[s] dx) M_{+o} F_o S(s) c_s`` in the same step.
    Returns float64 arrays of ``c0``'s shape.
    """
    c = np.asarray(c0, dtype=np.float64)
    mats = propagation_matrices() if matrices is None else np.asarray(matrices, np.float64)
    sig = np.broadcast_to(np.asarray(sigma_lpv, dtype=np.float64), c.shape[:4])
    sp = np.broadcast_to(np.asarray(sigma_s_prime, dtype=np.float64), c.shape[:4])
    gg = np.broadcast_to(np.asarray(g, dtype=np.float64), c.shape[:4])
    dxs = np.broadcast_to(np.asarray(dx, dtype=np.float64), (3,))

    em = np.broadcast_to(np.asarray(1.0 if emit is None else emit, dtype=np.float64), c.shape[:4])
    emp = None if empty is None else np.broadcast_to(np.asarray(empty, dtype=np.float64), c.shape[:4])

    k1 = scatter_factors(sp, gg)[..., 1]             # Eq. 3, band 1; band 0 unchanged
    # per-direction attenuation and source material do not change between steps
    atten = []
    for offset in SOURCE_OFFSETS:
        axis = int(np.flatnonzero(offset)[0])
        sig_s = _shift_from(sig, offset)
        a = np.exp(-0.5 * (sig_s + sig) * dxs[axis])
        if emp is not None:                          # the link between two empty cells is cut
            a = a * (1.0 - _shift_from(emp, offset) * emp)
        atten.append(a)
    atten = np.stack(atten)                          # (6, N, N, N, 3)
    faces = []                                       # (direction, face mask, self attenuation)
    if r_dr and inside is not None:
        ins = np.asarray(inside, dtype=bool)
        for s, offset in enumerate(SOURCE_OFFSETS):
            axis = int(np.flatnonzero(offset)[0])
            # d outside receives from an inside source s = d + offset: only 1 - R crosses
            cross = _shift_from(ins, offset) & ~ins
            atten[s] *= np.where(cross, 1.0 - r_dr, 1.0)[..., None]
            # d inside with its neighbour d + offset outside: the image at d + offset sends F c_d
            faces.append((s, axis, reflect.surface_faces(ins, offset)[..., None] * np.exp(-sig * dxs[axis]) * r_dr))

    accum = np.zeros_like(c)
    for step in range(1, int(steps) + 1):
        # sinks send nothing on, except in step 1: the injected light has crossed the
        # surface inwards, even where its cell's centre lies outside the mesh
        scattered = c * (1.0 if step == 1 else em[..., None])
        scattered[..., 1:] *= k1[..., None]
        nxt = np.zeros_like(c)
        for s, offset in enumerate(SOURCE_OFFSETS):
            src = _shift_from(scattered, offset)     # zero outside the grid
            nxt += (src @ mats[s].T) * atten[s][..., None]
        for s, axis, w in faces:                     # Eq. (R3): the mirrored lobe re-enters its cell
            nxt += (reflect.mirror(scattered, axis) @ mats[s].T) * w[..., None]
        c = nxt
        if step > skip:
            accum += c
    return c, accum


# ------------------------------------------------------------------ shading

def sample_trilinear(grid, points, bbox_min, bbox_max):
    """Trilinear sample of ``grid`` (N,N,N,...) at ``points`` (P,3) -> (P, ...).

    Voxel-centre convention; the continuous index is clamped to the outermost
    cell centres (GL ``CLAMP_TO_EDGE`` with linear filtering).
    """
    grid = np.asarray(grid, dtype=np.float64)
    N = grid.shape[0]
    bmin, dx = _grid_geometry(bbox_min, bbox_max, N)
    u = (np.asarray(points, dtype=np.float64) - bmin) / dx - 0.5
    u = np.clip(u, 0.0, N - 1)
    i0 = np.minimum(np.floor(u).astype(np.int64), N - 1)
    i1 = np.minimum(i0 + 1, N - 1)
    f = u - i0
    out = 0.0
    for cx in (0, 1):
        ix = i1[:, 0] if cx else i0[:, 0]
        wx = f[:, 0] if cx else 1.0 - f[:, 0]
        for cy in (0, 1):
            iy = i1[:, 1] if cy else i0[:, 1]
            wy = f[:, 1] if cy else 1.0 - f[:, 1]
            for cz in (0, 1):
                iz = i1[:, 2] if cz else i0[:, 2]
                wz = f[:, 2] if cz else 1.0 - f[:, 2]
                w = (wx * wy * wz).reshape((-1,) + (1,) * (grid.ndim - 3))
                out = out + w * grid[iz, iy, ix]
    return out


def shade_points(accum, bbox_min, bbox_max, points, normals, lookup="cell", eta=1.0,
                 view_dirs=None, eta2=False, radiance_scale=None, shade_depth=0.0):
    """Subsurface radiance leaving surface points (Sec. 3.3) -> (P, 3) float64.

    Eq. 4 with the area-light estimate of Eq. 5-7 in the two-band form of
    Sec. 4: ``L_o = T (2/A) (c00/sqrt(4 pi) + 1/2 sqrt(3/(4 pi)) c10^(n))``,
    ``A = dx^2``. ``T`` is the Fresnel transmittance for the view direction
    (``view_dirs``: unit vectors from the point TOWARDS the camera); it is 1
    when ``eta == 1``, where ``view_dirs`` may be omitted. ``lookup="cell"``
    uses the coefficients of the cell containing the point, ``"trilinear"``
    interpolates them (:func:`sample_trilinear`). ``eta2=True`` divides the
    result by ``eta^2`` (radiance compression leaving a medium of index
    ``eta``, which Mitsuba applies and the paper's Eq. 4 does not; no effect
    when ``eta == 1``). ``radiance_scale`` (N,N,N,3), default 1, multiplies
    each cell's coefficients before the lookup (``docs/diffusion_mapping.md``
    Eq. (21); a calibrated global factor), as ``scale.comp`` does.
    ``shade_depth`` (cells) reads the grid at ``x - shade_depth dx n`` instead of
    at ``x`` (:mod:`sslpv_gl.shade` Eq. (S1); 0 = the paper).
    """
    accum = np.asarray(accum, dtype=np.float64)
    if radiance_scale is not None:
        accum = accum * np.asarray(radiance_scale, dtype=np.float64)[..., None]
    N = accum.shape[0]
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    nrm = nrm / np.linalg.norm(nrm, axis=-1, keepdims=True)
    _, dx = _grid_geometry(bbox_min, bbox_max, N)
    pts = pts - float(shade_depth) * dx[0] * nrm         # Eq. (S1)
    if lookup == "cell":
        i, j, k = cell_index(pts, bbox_min, bbox_max, N).T
        c = accum[k, j, i]                           # (P, 3, 4)
    elif lookup == "trilinear":
        c = sample_trilinear(accum, pts, bbox_min, bbox_max)
    else:
        raise ValueError(f"unknown lookup '{lookup}'; use 'cell' or 'trilinear'")

    radiance = hemisphere_radiance(c, nrm[:, None, :], dx[0] ** 2)

    if eta == 1.0:
        T = np.ones(pts.shape[0])
    else:
        if view_dirs is None:
            raise ValueError("view_dirs is required when eta != 1 (Fresnel factor of Eq. 4)")
        v = np.asarray(view_dirs, dtype=np.float64).reshape(-1, 3)
        v = v / np.linalg.norm(v, axis=-1, keepdims=True)
        # Fresnel transmittance is the same both ways across the interface, so
        # T(w_i -> w_o) is T for light entering along -w_o from outside
        cos_o = np.clip(np.sum(v * nrm, axis=-1), 0.0, 1.0)
        T = fresnel_transmittance(cos_o, eta)
        if eta2:
            T = T / (float(eta) * float(eta))
    return T[:, None] * radiance
