"""NumPy twin of the dipole rivals' GL passes: the same algorithm, in float64, for the tests.

.. list-table::
   :header-rows: 1

   * - function
     - GL pass
     - what
   * - :func:`irradiance`
     - ``irradiance.comp``
     - per light and surface point: transmitted flux ``T(w_i) I cos / d^2 V dA`` (the
       visibility ``V`` is an input: the GL pass's shadow-map answer, read back)
   * - :func:`dense_gather`
     - ``gather_dense.comp``
     - radiance at exit points: ``T(w_o)/pi sum R_d Phi`` (dipole) or ``T(w_o) sum S_d Phi`` (dirpole)
   * - :func:`vertex_gather`
     - ``gather_vertex.comp``
     - per scattering vertex over its precomputed neighbourhood (:mod:`dipole_gl.vertex`)
   * - :func:`display`
     - ``display.comp``
     - barycentric transfer to the display mesh's vertices
"""

from __future__ import annotations

import numpy as np

from sslpv_gl.optics import fresnel_transmittance

from . import kernels
from .medium import lookup
from .sampling import N_PHI, NEAR_RADIUS, radial_nodes, window

__all__ = ["irradiance", "dense_gather", "vertex_gather", "display", "exit_coefficients"]


def irradiance(positions, normals, areas, lights, eta, visibility):
    """``(flux (L, S, 3), w_i (L, S, 3))``: transmitted flux per light and point, direction to the light.

    ``visibility`` (L, S) in [0, 1]; points facing away from a light get zero.
    """
    p = np.asarray(positions, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float64)
    flux, dirs = [], []
    for light, vis in zip(lights, visibility):
        to = np.asarray(light.position, dtype=np.float64) - p
        d2 = np.sum(to * to, axis=-1)
        wi = to / np.sqrt(d2)[:, None]
        cos = np.sum(wi * n, axis=-1)
        lit = cos > 0.0
        t = fresnel_transmittance(np.where(lit, cos, 1.0), eta)
        e = np.where(lit, cos * t * np.asarray(vis, dtype=np.float64) / d2 * np.asarray(areas, np.float64), 0.0)
        flux.append(e[:, None] * np.asarray(light.intensity, dtype=np.float64)[None])
        dirs.append(wi)
    return np.stack(flux), np.stack(dirs)


def exit_coefficients(mat, points, normals, eta):
    """The kernel coefficients at exit points (the material there, :mod:`dipole_gl.medium`) -> dict (P, 3)."""
    # the GL lookup runs in float32
    sp, sa, st = lookup(mat, np.asarray(points, np.float32).astype(np.float64),
                        np.asarray(normals, np.float32).astype(np.float64))
    return kernels.material(sp, sa, eta, sigma_t=st)


def _pair_kernel(kernel, xi, ni, wi, xo, no, m):
    """(P, S, 3) kernel between every exit point (P) and sample (S); ``m`` entries (P, 1, 3)."""
    if kernel == "dipole":
        r = np.linalg.norm(xo[:, None, :] - xi[None, :, :], axis=-1)
        return kernels.rd_dipole(r[..., None], m) / np.pi
    P, S = len(xo), len(xi)
    b = lambda a, first: np.broadcast_to(a[:, None] if first else a[None], (P, S, 3))  # noqa: E731
    return kernels.dirpole_sd(b(xi, False), b(ni, False), b(wi, False), b(xo, True), b(no, True), m)


def _sliced(m, sel):
    return {k: (v[sel][:, None] if isinstance(v, np.ndarray) and v.ndim == 2 else v) for k, v in m.items()}


def dense_gather(kernel, exit_pos, exit_nrm, cam_pos, samples, flux, dirs, mat, eta, spacing, lights, exit_vis,
                 chunk=32):
    """Radiance (P, 3) at exit points of the dense gather over ``samples = (positions, normals)``.

    ``flux``/``dirs`` from :func:`irradiance`; ``spacing`` the samples' spacing ``h`` (the
    near-field radius is ``NEAR_RADIUS h``); ``exit_vis`` (P, L) the lights' visibility at
    the exit points. The exit Fresnel transmittance uses the direction to ``cam_pos``.
    """
    xo = np.asarray(exit_pos, dtype=np.float64)
    no = np.asarray(exit_nrm, dtype=np.float64)
    xi, ni = (np.asarray(a, dtype=np.float64) for a in samples)
    m = exit_coefficients(mat, xo, no, eta)
    rho = NEAR_RADIUS * spacing
    out = np.zeros((len(xo), 3))
    total = flux.sum(axis=0)
    for s in range(0, len(xo), chunk):
        sel = slice(s, s + chunk)
        ms = _sliced(m, sel)
        far = 1.0 - window(np.linalg.norm(xo[sel, None, :] - xi[None], axis=-1), rho)[..., None]     # (p, S, 1)
        if kernel == "dipole":
            out[sel] = np.einsum("psc,sc->pc", far * _pair_kernel(kernel, xi, ni, None, xo[sel], no[sel], ms), total)
        else:
            for fl, wi in zip(flux, dirs):
                lit = np.any(fl > 0.0, axis=1)             # as the GL pass: unlit points are skipped
                out[sel] += np.einsum("psc,sc->pc", far[:, lit] * _pair_kernel(kernel, xi[lit], ni[lit], wi[lit],
                                                                               xo[sel], no[sel], ms), fl[lit])
    out += near_field(kernel, xo, no, m, rho, lights, exit_vis, eta)
    wo = np.asarray(cam_pos, dtype=np.float64) - xo
    cos_o = np.sum(wo * no, axis=-1) / np.linalg.norm(wo, axis=-1)
    return out * fresnel_transmittance(np.clip(cos_o, 0.0, 1.0), eta)[:, None]


def near_field(kernel, xo, no, m, rho, lights, vis, eta):
    """The near field ``int w K dA`` on each exit point's tangent plane times its irradiance -> (P, 3).

    The quadrature of :mod:`dipole_gl.sampling` (radial panels times ``N_PHI`` angles);
    ``vis`` (P, L) is the lights' visibility at the exit points (the GL G-buffer's).
    """
    t, w = radial_nodes()
    r = rho * t
    wr = w * window(r, rho) * r                          # weights of int_0^rho ... r dr (times rho below)
    out = np.zeros((len(xo), 3))
    per_light, dirs = irradiance(xo, no, np.ones(len(xo)), lights, eta, np.asarray(vis, np.float64).T)
    if kernel == "dipole":
        k = kernels.rd_dipole(r[None, :, None], {a: (v[:, None] if isinstance(v, np.ndarray) and v.ndim == 2 else v)
                                                for a, v in m.items()})              # (P, R, 3)
        ring = rho * np.sum(wr[None, :, None] * 2.0 * np.pi * k, axis=1)
        return ring * per_light.sum(axis=0) / np.pi
    t1 = np.where(np.abs(no[:, :1]) < 0.9, np.cross(no, [1.0, 0.0, 0.0]), np.cross(no, [0.0, 1.0, 0.0]))
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(no, t1)
    phi = 2.0 * np.pi * np.arange(N_PHI) / N_PHI
    for p in range(len(xo)):
        u = r[:, None, None] * (np.cos(phi)[None, :, None] * t1[p] + np.sin(phi)[None, :, None] * t2[p])   # (R, F, 3)
        xi = xo[p] + u
        mp = {a: (v[p] if isinstance(v, np.ndarray) and v.ndim == 2 else v) for a, v in m.items()}
        for li, e in enumerate(per_light):
            if not np.any(e[p] > 0.0):
                continue
            sd = kernels.dirpole_sd(xi, np.broadcast_to(no[p], xi.shape), np.broadcast_to(dirs[li, p], xi.shape),
                                    np.broadcast_to(xo[p], xi.shape), np.broadcast_to(no[p], xi.shape), mp)
            out[p] += rho * np.sum(wr[:, None, None] * sd * (2.0 * np.pi / N_PHI), axis=(0, 1)) * e[p]
    return out


def vertex_gather(kernel, pre, flux, dirs, mat, eta, vertices=None):
    """``B`` (V, 3) per scattering vertex: the neighbourhood sum (the exit Fresnel is applied per pixel).

    ``pre`` is :class:`dipole_gl.vertex.VertexPrecomp`; dipole: ``sum_j w_oj Phi_j`` with the
    precomputed ``w_oj = R_d(r_oj) / pi``; dirpole: ``sum_j sum_l S_d(x_j, w_l; x_o) Phi_jl``.
    ``vertices`` (indices) restricts it to those exit vertices: then ``(len(vertices), 3)``.
    """
    V = len(pre.positions)
    out = np.zeros((V, 3))
    total = flux.sum(axis=0)
    m = exit_coefficients(mat, pre.positions, pre.normals, eta)
    for o in (range(V) if vertices is None else vertices):
        lo, hi = pre.offsets[o], pre.offsets[o + 1]
        j = pre.neighbours[lo:hi]
        if kernel == "dipole":
            out[o] = np.sum(pre.factors[lo:hi] * total[j], axis=0)
        else:
            mo = _sliced(m, slice(o, o + 1))
            for fl, wi in zip(flux, dirs):
                jl = j[np.any(fl[j] > 0.0, axis=1)]          # lit neighbours only, as the GL pass
                k = _pair_kernel(kernel, pre.positions[jl], pre.normals[jl], wi[jl], pre.positions[o:o + 1],
                                 pre.normals[o:o + 1], mo)[0]
                out[o] += np.sum(k * fl[jl], axis=0)
    return out if vertices is None else out[np.asarray(vertices)]


def display(pre, b):
    """``B`` at the display mesh's vertices: barycentric weights of the closest scattering triangle."""
    return np.einsum("dk,dkc->dc", pre.display_weights, np.asarray(b, dtype=np.float64)[pre.display_index])
