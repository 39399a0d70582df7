"""The ``diffusion`` mapping in a bounded domain: lattice problems and their diffusion solutions.

``docs/diffusion_mapping.md`` matches the lattice to diffusion
theory in an unbounded medium (its Eq. (14)-(21)). Here the same lattice is run in
bounded objects with the ``extrapolated`` boundary of :mod:`sslpv_gl.boundary`
(the medium continues ``z_b = 2 A(eta) D`` beyond the surface, then sink cells),
and compared with the diffusion equation under the matching Dirichlet condition
``phi = 0`` at the extrapolated surface (Eq. (B3)).

Equations (cited as "Eq. (Dn)")
-------------------------------
(D1) Slab ``0 <= z <= d``, plane source of unit power per area at depth ``z0``,
     ``phi = 0`` at ``z = -z_b`` and ``z = d + z_b``; with ``L = d + 2 z_b``,
     ``u = z + z_b``: ``phi(u) = sinh(s u<) sinh(s (L - u>)) / (D s sinh(s L))``,
     ``s = sigma_tr``. The flux through the extrapolated surfaces, ``D |phi'|``, is
     ``R = sinh(s (L - u0)) / sinh(s L)`` (source side) and
     ``T = sinh(s u0) / sinh(s L)`` (far side); ``(L - u0)/L`` and ``u0/L`` when
     ``s = 0``.
(D2) Sphere of radius ``a``, point source of power ``P`` at its centre, ``phi = 0``
     at ``a' = a + z_b``: ``phi(r) = P sinh(s (a' - r)) / (4 pi D r sinh(s a'))``;
     the power leaving through ``r = a'`` is ``P s a' / sinh(s a')`` (``P`` when
     ``s = 0``).
(D2') The same sphere with the point source at ``r0`` from the centre (a sphere lit
     from one side: the dipole's source one reduced mean free path below the lit
     pole). Expanding ``exp(-s R) / (4 pi R)`` in Legendre polynomials of the angle
     ``gamma`` from the source's axis (modified spherical Bessel ``i_l``, ``k_l``) and
     adding the homogeneous solution that vanishes at ``a'``, the Wronskian
     ``i_l k_l' - i_l' k_l = -pi / (2 x^2)`` leaves the outgoing flux density
     ``J(mu) = P / (4 pi a'^2) sum_l (2 l + 1) P_l(mu) i_l(s r0) / i_l(s a')``,
     ``mu = cos gamma``; its integral over ``mu < 0`` is the power leaving through the
     far hemisphere, ``(P / 2) sum_l (2 l + 1) rho_l int_{-1}^0 P_l``.
(D3) The lattice's slab is the laterally uniform solution of the twin's transfer
     rule (``docs/conventions.md``): with every cell of a plane equal, the four
     lateral sources of a destination hold the destination's own coefficients, so
     ``c'_i = sum_{s=+-x} M_s A_{i,j} e_j S_j c_j + sum_{s=+-y,+-z} M_s A_{i,i} e_i S_i c_i``
     (``j = i + o_s``, ``A`` the two-half attenuation, ``e`` emit, ``S = diag(1, k1, k1, k1)``).
     :func:`slab_operator` builds it; ``tests/test_diffusion_bounded.py`` checks it
     against :func:`sslpv_gl.twin.propagate` on a 3D grid.
(D4) Where a sink puts the zero of the lattice's fluence. A half-infinite chain
     (Eq. (D3)) of the ``diffusion`` lattice ends in a *partial sink*: a cell that holds
     the medium and passes on ``emit = f`` of what it receives, with sinks beyond it.
     Between that end and a plane source deep inside, the lattice's fluence is
     ``A sinh(k (z - z0))`` (``k`` its decay per cell, measured on the chain); ``z0``
     solves ``phi(z1) / phi(z2) = sinh(k (z1 - z0)) / sinh(k (z2 - z0))`` for two cells
     ``z1 < z2`` past the end's transients. :func:`partial_sink_offsets` tabulates the
     zero's distance beyond the partial cell's centre, ``o(f)``: about ``-0.07`` cells
     at ``f = 0`` (a plain sink: the zero lies just inside its centre) to ``+0.93`` at
     ``f = 1`` (the cell is medium; the zero moves one cell out), independent of the
     medium to 0.01 cells for ``sigma_tr dx`` from 0.05 to 0.35 (the test). The
     ``extrapolated`` layer (:func:`sslpv_gl.boundary.outside_masks`) inverts it to
     put the zero at ``z_b`` to a fraction of a cell.

(D5) At the extrapolated boundary (``phi = 0`` at ``z_b = 2 A D`` past the surface, the
     profile linear near it) Fick's law gives the exitance ``J = D phi(0) / z_b =
     phi(0) / (2 A)``: the light a render should read as Lambertian ``J / pi``, twice
     (for ``A = 1``) the isotropic part ``phi / (4 pi)`` that Eq. (21) reads.
     :func:`slab_lattice` reports it in the two cells that straddle the far surface.

The lattice's fluxes are read from its sinks: a sink cell keeps what enters it and
passes nothing on, so its accumulated ``c00`` (from step 1, ``skip = 0``) is the
total flux that crossed into it, in the same ``c00`` units as the source. A partial
sink (Eq. (D4)) removes ``1 - emit`` of what it receives.

Limits
------
* Isotropic (``c00``) sources, as the dipole's "source at one transport mean free
  path" model of normal illumination; the render's injection lobe in the surface
  cell is studied separately (:func:`slab_lattice` with ``lobe=True``).
* Index-matched (``eta = 1``, ``A = 1``) unless ``eta`` is given.
"""

from __future__ import annotations

import functools

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from . import boundary, diffusion
from .sh import SOURCE_OFFSETS, clamped_cosine_coeffs, hemisphere_radiance, propagation_matrices, scatter_factors

__all__ = ["slab_diffusion", "sphere_diffusion", "sphere_side_diffusion", "slab_operator", "slab_lattice", "sphere_lattice",
           "partial_sink_offsets", "chain_zero"]


def _coefficients(sigma_t, albedo, g):
    sigma_a, sigma_tp, sigma_tr = diffusion.diffusion_coefficients(sigma_t, albedo, g)
    return float(sigma_a), float(sigma_tp), float(sigma_tr), 1.0 / (3.0 * float(sigma_tp))


def slab_diffusion(sigma_t, albedo, g, d, z0, zb):
    """Eq. (D1) -> ``(R, T)``: the fractions of a plane source at depth ``z0`` leaving each side."""
    _, _, s, _ = _coefficients(sigma_t, albedo, g)
    L, u0 = d + 2.0 * zb, z0 + zb
    if s == 0.0:
        return (L - u0) / L, u0 / L
    return float(np.sinh(s * (L - u0)) / np.sinh(s * L)), float(np.sinh(s * u0) / np.sinh(s * L))


def sphere_diffusion(sigma_t, albedo, g, a, zb, r=None):
    """Eq. (D2) for ``P = 1`` -> ``(escape, phi(r))``; ``phi`` is None without ``r``."""
    _, _, s, D = _coefficients(sigma_t, albedo, g)
    ap = a + zb
    esc = 1.0 if s == 0.0 else float(s * ap / np.sinh(s * ap))
    if r is None:
        return esc, None
    r = np.asarray(r, dtype=np.float64)
    phi = (ap - r) / (4 * np.pi * D * r * ap) if s == 0.0 else np.sinh(s * (ap - r)) / (
        4 * np.pi * D * r * np.sinh(s * ap))
    return esc, phi


def sphere_side_diffusion(sigma_t, albedo, g, a, zb, r0, lmax=160):
    """Eq. (D2') for ``P = 1`` -> ``(escape, escape_far)``: all power leaving, and through the far hemisphere."""
    from scipy.special import eval_legendre, spherical_in

    _, _, s, _ = _coefficients(sigma_t, albedo, g)
    ap = a + zb
    x, w = np.polynomial.legendre.leggauss(200)
    mu, w = 0.5 * (x - 1.0), 0.5 * w                 # nodes on [-1, 0]
    total = far = 0.0
    for ell in range(lmax + 1):
        den = spherical_in(ell, s * ap)
        if den == 0.0 or not np.isfinite(den):       # i_l underflows: the series has converged long before
            break
        rho = spherical_in(ell, s * r0) / den
        if ell == 0:
            total = rho
        far += 0.5 * (2 * ell + 1) * rho * float(np.sum(w * eval_legendre(ell, mu)))
    return float(total), float(far)


def slab_operator(sigma_lpv, k1, emit, dx):
    """Eq. (D3): one laterally uniform step as a sparse ``(4 n, 4 n)`` matrix (cells along x).

    ``sigma_lpv``, ``k1``, ``emit``: ``(n,)`` arrays along the slab normal; nothing
    enters from beyond either end (the twin's zero outside the grid).
    """
    sig, k1, em = (np.asarray(v, dtype=np.float64) for v in (sigma_lpv, k1, emit))
    n = sig.size
    mats = propagation_matrices()
    rows, cols, vals = [], [], []
    for s, off in enumerate(SOURCE_OFFSETS):
        shift = int(off[0])                          # lateral sources (shift 0): the cell itself
        for i in range(n):
            j = i + shift
            if not 0 <= j < n:
                continue
            f = np.exp(-0.5 * (sig[i] + sig[j]) * dx) * em[j]
            block = mats[s] * f * np.array([1.0, k1[j], k1[j], k1[j]])[None, :]   # M_s S_j
            r, c = np.nonzero(block)
            rows.append(4 * i + r)
            cols.append(4 * j + c)
            vals.append(block[r, c])
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(4 * n, 4 * n))


def _steady(P, P1, c0):
    """``sum_{k>=1} c_k`` with ``c_1 = P1 c0`` and ``c_{k+1} = P c_k`` (skip = 0): ``(I - P)^-1 P1 c0``."""
    n = P.shape[0]
    return spla.spsolve((sp.identity(n, format="csc") - P).tocsc(), P1 @ c0)


def chain_zero(emit_end, kappa=0.1, medium_end=True, cells=160):
    """Eq. (D4): the zero of the lattice's fluence beyond a chain's end cell, in cells from its centre.

    The chain (Eq. (D3)) holds the ``diffusion`` lattice of a medium with ``sigma_tr dx =
    kappa`` (``sigma_t' dx = 1``); cell 20 is the end (medium when ``medium_end``, else
    vacuum) passing on ``emit_end`` of what it receives, cells below it are sinks, and a
    plane ``c00`` source sits 100 cells further in. Positive: the zero lies outside the
    end cell's centre.
    """
    from scipy.optimize import brentq

    b, src, n = 20, 120, int(cells)
    m = diffusion.diffusion_mapping(1.0, 1.0 - kappa * kappa / 3.0, 0.0, 1.0)
    keep = np.zeros(n)
    keep[b + 1:] = 1.0
    keep[b] = 1.0 if medium_end else 0.0
    emit = np.ones(n)
    emit[:b] = 0.0
    emit[b] = float(emit_end)
    sig = np.where(keep > 0, float(m["sigma_lpv"]), 0.0)
    k1 = scatter_factors(keep, float(m["g"]))[..., 1]
    c0 = np.zeros(4 * n)
    c0[4 * src] = 1.0
    phi = _steady(slab_operator(sig, k1, emit, 1.0), slab_operator(sig, k1, np.ones(n), 1.0), c0).reshape(n, 4)[:, 0]
    k = float(np.log(phi[b + 80] / phi[b + 79]))       # the decay per cell, far from both ends
    z1, z2 = b + 6, b + 6 + max(int(np.ceil(0.7 / k)), 4)
    ratio = phi[z1] / phi[z2]
    z0 = brentq(lambda z: np.sinh(k * (z1 - z)) / np.sinh(k * (z2 - z)) - ratio, b - 10.0, z1 - 1e-6)
    return float(b - z0)


@functools.lru_cache(maxsize=1)
def partial_sink_offsets(points=41):
    """Eq. (D4) tabulated -> ``(emit, offset)``, two increasing float64 arrays of ``points`` values.

    ``offset`` is :func:`chain_zero` of a medium end cell at each ``emit`` (denser near 1,
    where it changes fastest), at ``sigma_tr dx = 0.1``.
    """
    u = np.linspace(0.0, 1.0, int(points))
    f = 1.0 - (1.0 - u) ** 2
    off = np.array([chain_zero(e) for e in f])
    return f, off


def slab_lattice(sigma_t, albedo, g, N, depth_mfp=1.0, pad=None, eta=1.0, lobe=False, outside="extrapolated",
                 lobe_depth_mfp=None):
    """The ``diffusion`` lattice's slab of ``N`` cells -> dict of lattice and diffusion R, T.

    The slab is ``N`` cells thick (``dx = d / N`` for ``d = 1``; lengths scale out of
    the comparison through ``sigma_t``), padded on each side by the ``extrapolated``
    layer and sink cells. The source is a plane of ``c00`` in the cell whose centre is
    nearest ``depth_mfp / sigma_t'`` below the lit face (Eq. (D1) uses that centre's
    depth), or with ``lobe=True`` the render's injection: Eq. 1's clamped-cosine lobe
    pointing into the slab, in the first inside cell (or ``lobe_depth_mfp / sigma_t'``
    deep: ``inject_offset``). ``outside`` is the boundary mode (``extrapolated`` or
    ``absorb``). Returns ``R``, ``T`` (lattice: flux into the sinks on each side over
    the injected flux), ``R_diff``, ``T_diff`` (Eq. (D1), the source at ``z0``), ``z0``,
    ``zb``, ``dx``, ``kappa`` (``sigma_tr dx``), ``T_render``: the far side's exitant
    radiance as the render reads it, ``pi L A / P`` (``P`` the injected power per cell,
    ``L`` Eq. 5-7 times the cell's radiance scale: Eq. (21) in medium cells, 1 in sinks),
    in the last inside cell (``T_render_in``) and the first outside cell
    (``T_render_out``; ``T_render_out_R`` with Eq. (21)'s scale in a sink too, as before
    the sink fix), ``T_exitance_in`` / ``T_exitance_out``: the same cells' fluence read as
    diffusion theory's exitance at the boundary, ``J A / P`` with ``J = phi / (2 A(eta))``
    (Eq. (D5); 0 in a sink), and the arrays ``accum`` and ``pad``.
    """
    d = 1.0
    dx = d / int(N)
    zb = float(boundary.extrapolation_distance(sigma_t, albedo, g, eta))
    pad = int(np.ceil(zb / dx)) + 3 if pad is None else int(pad)
    n = int(N) + 2 * pad
    inside = np.zeros((1, 1, n), dtype=bool)
    inside[..., pad:pad + int(N)] = True
    keep, emit = boundary.outside_masks(inside, outside, np.full(3, zb / dx), partial_sink_offsets())
    keep, emit = keep[0, 0, :, 0], emit[0, 0, :, 0]
    m = diffusion.diffusion_mapping(sigma_t, albedo, g, dx)
    sig = np.where(keep > 0, float(m["sigma_lpv"]), 0.0)
    k1 = scatter_factors(np.where(keep > 0, 1.0, 0.0), float(m["g"]))[..., 1]
    P = slab_operator(sig, k1, emit, dx)
    P1 = slab_operator(sig, k1, np.ones(n), dx)      # step 1 sends the injected light on from every cell
    _, sigma_tp, _, _ = _coefficients(sigma_t, albedo, g)
    c0 = np.zeros(4 * n)
    if lobe:
        depth = 0 if lobe_depth_mfp is None else int(np.floor(lobe_depth_mfp / sigma_tp / dx))
        i0 = pad + int(np.clip(depth, 0, int(N) - 1))
        c0[4 * i0:4 * i0 + 4] = clamped_cosine_coeffs(np.array([1.0, 0.0, 0.0])) / np.pi
        z0 = 1.0 / sigma_tp                          # the dipole's source depth, for the diffusion column
    else:
        i0 = pad + int(np.clip(np.floor(depth_mfp / sigma_tp / dx), 0, int(N) - 1))
        c0[4 * i0] = 1.0
        z0 = (i0 - pad + 0.5) * dx
    acc = _steady(P, P1, c0).reshape(n, 4)
    removed = acc[:, 0] * (1.0 - emit)             # what the sinks and partial sinks kept (Eq. (D4))
    left, right = np.arange(n) < pad, np.arange(n) >= pad + int(N)
    R_d, T_d = slab_diffusion(sigma_t, albedo, g, d, z0, zb)
    power = np.sqrt(4.0 * np.pi) * c0[4 * i0]        # per cell (P = sqrt(4 pi) c00)
    n_out = np.array([1.0, 0.0, 0.0])

    def exitance(i):
        # Eq. (D5): diffusion theory's exitance at the extrapolated boundary, J = phi / (2 A), from the cell's fluence
        phi = float(m["fluence_scale"]) * acc[i, 0]
        return float(phi / (2.0 * boundary.a_of_eta(eta)) * dx * dx / power) if keep[i] > 0 else 0.0

    def read(i, sink_scale=1.0):
        scale = float(m["radiance_scale"]) if keep[i] > 0 else sink_scale
        return float(np.pi * scale * hemisphere_radiance(acc[i], n_out, dx * dx) * dx * dx / power)

    return {"R": removed[left].sum() / c0[4 * i0], "T": removed[right].sum() / c0[4 * i0],
            "R_diff": R_d, "T_diff": T_d, "z0": z0, "zb": zb, "dx": dx, "kappa": float(m["kappa"]),
            "T_render_in": read(pad + int(N) - 1), "T_render_out": read(pad + int(N)),
            "T_exitance_in": exitance(pad + int(N) - 1), "T_exitance_out": exitance(pad + int(N)),
            "T_render_out_R": read(pad + int(N), float(m["radiance_scale"])), "accum": acc, "pad": pad}


def sphere_lattice(media, N, rtol=1e-9, depth_mfp=None, pole="face"):
    """A sphere ``N`` cells across with a ``c00`` point source in its centre cell -> dict.

    ``media``: three ``(sigma_t, albedo, g)``, one per colour, in units of the sphere's
    radius ``a = 1`` (``dx = 2 / N``). ``depth_mfp``: the source sits instead in the cell
    next to the +x axis nearest ``depth_mfp / sigma_t'`` below the surface (per colour), and
    the result also holds ``escape_far`` / ``escape_far_diff`` (Eq. (D2'), ``r0`` that
    cell's centre, the series' axis through it; the far hemisphere is the sinks on the
    other side of the plane through the centre normal to that axis, half of those on it).
    The centred source needs an odd-sized grid, whose centre is a cell centre; its
    poles then lie ON the centres of the first outside cells, half a cell beyond where a
    mask of cell centres can put a surface (averaged over the sphere the two agree). For
    the source below a pole, ``pole="face"`` (the default) uses an even-sized grid, as
    renders do (the grid's corners on the bounding box), whose poles lie on cell faces;
    ``pole="centre"`` keeps the odd grid and the source on the axis. Grids are padded by
    the ``extrapolated`` layer and sinks; the steady state is
    :func:`sslpv_gl.steady.steady_state` with ``skip = 0``. Returns per colour
    ``escape`` (flux removed by the sinks and partial sinks over the source),
    ``escape_diff`` (Eq. (D2)), the fluence ratio ``phi_lattice / phi_diff`` at every
    inside cell with ``3 <= r/dx <= (a/dx) - 3`` (``ratio``, ``r_cells``), ``kappa`` and ``zb``.
    """
    from .steady import steady_state

    a = 1.0
    dx = 2.0 * a / int(N)
    media = [tuple(float(v) for v in m) for m in media]
    st, al, gg = (np.array(v) for v in zip(*media))
    zb = boundary.extrapolation_distance(st, al, gg, 1.0)
    pad = int(np.ceil(zb.max() / dx)) + 3
    half = int(N) // 2 + pad
    if pole not in ("face", "centre"):
        raise ValueError(f"pole must be 'face' or 'centre', not {pole!r}")
    even = depth_mfp is not None and pole == "face"
    n = 2 * half if even else 2 * half + 1
    idx = np.arange(n) - half + (0.5 if even else 0.0)     # cell centres, in cells from the sphere's centre
    r = np.sqrt(idx[:, None, None] ** 2 + idx[None, :, None] ** 2 + idx[None, None, :] ** 2) * dx
    inside = r < a
    keep, emit = boundary.outside_masks(inside, "extrapolated", zb / dx, partial_sink_offsets())
    m = diffusion.diffusion_mapping(st, al, gg, dx)
    sig = np.where(keep > 0, m["sigma_lpv"], 0.0)
    spr = np.where(keep > 0, 1.0, 0.0)
    c0 = np.zeros((n, n, n, 3, 4))
    src = [(half, half, half)] * 3                   # [z, y, x]
    if depth_mfp is not None:
        sigma_tp = np.array([_coefficients(*med)[1] for med in media])
        x = a - depth_mfp / sigma_tp                 # the source's distance from the centre, along +x
        src = [(half, half, int(np.argmin(np.abs(idx * dx - xc)))) for xc in x]
    for col in range(3):
        c0[src[col] + (col, 0)] = 1.0
    acc, info = steady_state(c0, sig, spr, m["g"], dx, skip=0, emit=emit, rtol=rtol, check_spectrum=False)
    out = []
    sel = inside & (r >= 3 * dx - 1e-9) & (r <= a - 3 * dx + 1e-9)
    for col, med in enumerate(media):
        removed = acc[..., col, 0] * (1.0 - emit[..., col])   # sinks and partial sinks (Eq. (D4))
        row = {"escape": float(removed.sum()), "kappa": float(m["kappa"][col]), "zb": float(zb[col])}
        if depth_mfp is None:
            esc_d, phi_d = sphere_diffusion(*med, a, float(zb[col]), r[sel])
            phi = m["fluence_scale"][col] * acc[..., col, 0][sel]     # Eq. (18); P = sqrt(4 pi) c00 = sqrt(4 pi)
            row |= {"escape_diff": esc_d, "ratio": phi / (np.sqrt(4 * np.pi) * phi_d), "r_cells": r[sel] / dx}
        else:
            p = idx[list(src[col])] * dx             # the source cell's centre [z, y, x]
            r0 = float(np.linalg.norm(p))
            along = (idx[:, None, None] * p[0] + idx[None, :, None] * p[1] + idx[None, None, :] * p[2]) * dx
            weight = np.where(along < -1e-12, 1.0, np.where(along <= 1e-12, 0.5, 0.0))
            row["escape_far"] = float((removed * weight).sum())
            row["escape_diff"], row["escape_far_diff"] = sphere_side_diffusion(*med, a, float(zb[col]), r0)
            row["ratio"] = None                      # Eq. (D2)'s fluence is for the centred source
            row["r0"] = r0
        out.append(row)
    return out, info
