"""Two-band real spherical harmonics for SSLPV (Borlum et al., HPG 2011).

The intensity of every LPV cell is stored as four coefficients per colour in
the order of the paper's Sec. 4::

    c = (c00, c1-1, c10, c11)        y00  = 1/sqrt(4 pi)
                                     y1-1 = sqrt(3/(4 pi)) * y
                                     y10  = sqrt(3/(4 pi)) * z
                                     y11  = sqrt(3/(4 pi)) * x

Functions
---------

.. list-table::
   :header-rows: 1

   * - function
     - paper
     - meaning
   * - ``sh_basis(dirs)``
     - Sec. 4
     - ``(..., 4)`` basis values at (not necessarily unit) directions
   * - ``clamped_cosine_coeffs(direction)``
     - Eq. 1, authors' answer
     - projection of ``max(0, w_t . w)``: zonal ``(sqrt(pi)/2, sqrt(pi/3))``
       rotated to ``direction``
   * - ``face_sh_integrals(source, axis, sign)``
     - Sec. 4
     - ``int_{dOmega_f,s} y_lm(w) dw`` over one face of a unit cell, by
       Gauss-Legendre quadrature over the face with Jacobian ``cos / r^2``
   * - ``propagation_matrices()``
     - Sec. 4
     - ``(6, 4, 4)``: ``sum'_f M_{f,d<-s}`` for sources at
       ``+x, -x, +y, -y, +z, -z`` of the destination, applied to the SOURCE
       cell's coefficients
   * - ``scatter_factors(sigma_s_prime, g)``
     - Eq. 3
     - per-band ``(k0, k1)``, ``k_l = (1 - s') + s' g^l``
   * - ``apply_scattering(c, sigma_s_prime, g)``
     - Eq. 3
     - ``c`` with band 1 multiplied by ``k1``
   * - ``rotate_to_normal_c10(c, n)``
     - Eq. 6, Sec. 4
     - ``c10`` in the frame whose z axis is ``n``
   * - ``hemisphere_radiance(c, n, area)``
     - Eq. 5 / 7, Sec. 4
     - area-light radiance ``(2/A)(c00/sqrt(4 pi) + 1/2 sqrt(3/(4 pi)) c10^(n))``

Limits
------
* Two bands only (``l_max = 1``), as the paper's implementation.
* The propagation matrices assume cubic cells (the LPV grid of the paper);
  they do not depend on the cell size.
* The matrices are computed, not typed in: the paper prints them to three
  decimals, and the numbers computed here agree with every printed digit
  (``tests/test_sh.py`` checks ``atol=5e-4``).

Only NumPy is imported, so ``import sslpv_gl`` stays light.
"""

from __future__ import annotations

import functools

import numpy as np

__all__ = [
    "SH_Y00",
    "SH_Y1",
    "SOURCE_OFFSETS",
    "sh_basis",
    "clamped_cosine_coeffs",
    "face_sh_integrals",
    "propagation_matrices",
    "AXIAL_PATTERN",
    "axial_mask",
    "check_axial",
    "neighbour_slices",
    "scatter_factors",
    "apply_scattering",
    "rotate_to_normal_c10",
    "hemisphere_radiance",
]

SH_Y00 = 1.0 / np.sqrt(4.0 * np.pi)        # y00
SH_Y1 = np.sqrt(3.0 / (4.0 * np.pi))       # band-1 factor

#: Clamped-cosine zonal coefficients (authors' answer, ``003_...``):
#: ``int y00 max(0,cos) = sqrt(pi)/2`` and ``int y10 max(0,cos) = sqrt(pi/3)``.
CLAMPED_COSINE_ZONAL = (np.sqrt(np.pi) / 2.0, np.sqrt(np.pi / 3.0))

#: Position of the source cell relative to the destination, in (x, y, z),
#: in the order of :func:`propagation_matrices`.
SOURCE_OFFSETS = np.array(
    [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=np.int64
)


def sh_basis(dirs):
    """Real SH basis ``(y00, y1-1, y10, y11)`` at ``dirs`` (..., 3) -> (..., 4).

    ``dirs`` is normalised here (a zero vector gives NaN in band 1).
    """
    d = np.asarray(dirs, dtype=np.float64)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    out = np.empty(d.shape[:-1] + (4,), dtype=np.float64)
    out[..., 0] = SH_Y00
    # coefficient order (c00, c1-1, c10, c11) ~ (1, y, z, x), paper Sec. 4
    out[..., 1] = SH_Y1 * d[..., 1]
    out[..., 2] = SH_Y1 * d[..., 2]
    out[..., 3] = SH_Y1 * d[..., 0]
    return out


def clamped_cosine_coeffs(direction):
    """SH projection of ``max(0, direction . w)`` -> (..., 4).

    Eq. 1's lobe shape. The zonal coefficients ``sqrt(pi)/2`` and
    ``sqrt(pi/3)`` of the lobe about z (authors' answer) are rotated to
    ``direction`` (normalised here): a band-1 zonal coefficient about a unit
    vector ``d`` becomes ``(d_y, d_z, d_x)`` times itself in our order.
    """
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    z0, z1 = CLAMPED_COSINE_ZONAL
    out = np.empty(d.shape[:-1] + (4,), dtype=np.float64)
    out[..., 0] = z0
    out[..., 1] = z1 * d[..., 1]
    out[..., 2] = z1 * d[..., 2]
    out[..., 3] = z1 * d[..., 0]
    return out


def face_sh_integrals(source, axis, sign, n_quad=48):
    """``int_{dOmega} y_lm(w) dw`` over one face of the unit destination cell.

    The destination cell is the unit cube centred at the origin; the face is
    the square ``x[axis] = sign/2``, the other two coordinates in
    ``[-1/2, 1/2]``. ``dOmega`` is its solid angle seen from the point
    ``source`` (the source cell's centre, Sec. 4), counted positive whatever
    side the face is seen from, as the paper does for every face.

    Tensor Gauss-Legendre quadrature over the square with the solid-angle
    Jacobian ``|cos theta| / r^2``; the integrand is smooth because the
    source centre lies at least 1/2 away from every face plane used. With the
    default 48x48 nodes the result is converged to ~1e-13.

    Returns (4,) float64.
    """
    src = np.asarray(source, dtype=np.float64)
    t, w = np.polynomial.legendre.leggauss(int(n_quad))
    t, w = 0.5 * t, 0.5 * w                 # [-1, 1] -> [-1/2, 1/2]
    u, v = np.meshgrid(t, t, indexing="ij")
    weights = np.outer(w, w)
    others = [a for a in range(3) if a != axis]
    pts = np.empty(u.shape + (3,))
    pts[..., axis] = 0.5 * sign
    pts[..., others[0]] = u
    pts[..., others[1]] = v
    r = pts - src
    dist = np.linalg.norm(r, axis=-1)
    d_omega = weights * np.abs(r[..., axis]) / dist**3   # dA cos/r^2, cos = |r_axis|/r
    return np.einsum("ij,ijk->k", d_omega, sh_basis(r))


@functools.lru_cache(maxsize=4)
def _propagation_matrices(n_quad):
    mats = np.zeros((6, 4, 4), dtype=np.float64)
    for s, offset in enumerate(SOURCE_OFFSETS):
        for axis in range(3):
            for sign in (1, -1):
                normal = np.zeros(3)
                normal[axis] = sign
                # primed sum: skip the destination face that borders the source
                if np.array_equal(normal, offset):
                    continue
                # n_f is the destination face's outward normal: the reprojected
                # lobe points from the destination centre through face f
                emit = clamped_cosine_coeffs(normal)             # int_2pi (n_f.w) y_lm
                gather = face_sh_integrals(offset, axis, sign, n_quad)
                mats[s] += np.outer(emit, gather) / np.pi
    mats.setflags(write=False)
    return mats


def propagation_matrices(n_quad=48):
    """Propagation matrices ``sum'_f M_{f,d<-s}`` (Sec. 4) -> float64 (6, 4, 4).

    Index ``s`` is the source position relative to the destination:
    ``+x, -x, +y, -y, +z, -z`` (:data:`SOURCE_OFFSETS`). The matrix multiplies
    the SOURCE cell's coefficients::

        [M]_{lm,l'm'} = sum'_f (1/pi) [int_2pi (n_f . w) y_lm(w) dw]
                                      [int_{dOmega_f,s} y_l'm'(w) dw]

    summing over the destination's five faces other than the one it shares
    with the source. Computed once per ``n_quad`` (cached); a fresh copy is
    returned so callers may modify it.
    """
    return _propagation_matrices(int(n_quad)).copy()


#: Per source offset (:data:`SOURCE_OFFSETS`): the index of the band-1 coefficient along the
#: offset's axis, then the two transverse ones, in the order ``(c00, c1-1, c10, c11) ~ (1, y, z, x)``.
AXIAL_PATTERN = ((3, 1, 2), (3, 1, 2), (1, 2, 3), (1, 2, 3), (2, 1, 3), (2, 1, 3))


def axial_mask():
    """(6, 4, 4) bool: the entries of each propagation matrix that symmetry allows to be non-zero.

    A source on the destination's axis ``a`` sees the five receiving faces symmetrically about
    that axis, so band 0 and the band-1 coefficient along ``a`` mix (a 2x2 block), and each
    transverse band-1 coefficient maps to itself only (mirror symmetry across the axis makes
    every other entry's integrand odd). ``propagate.comp`` multiplies by these six entries only.
    """
    mask = np.zeros((6, 4, 4), dtype=bool)
    for s, (a, t1, t2) in enumerate(AXIAL_PATTERN):
        mask[s][np.ix_((0, a), (0, a))] = True
        mask[s, t1, t1] = mask[s, t2, t2] = True
    return mask


def check_axial(M, rtol=1e-12):
    """Raise ValueError unless every entry of ``M`` outside :func:`axial_mask` is below ``rtol`` max|M|.

    Guards ``propagate.comp``, which skips those entries: matrices with another structure
    (another quadrature, another basis order) must not be used with it silently.
    """
    M = np.asarray(M, dtype=np.float64)
    off = np.abs(np.where(axial_mask(), 0.0, M))
    worst = tuple(int(i) for i in np.unravel_index(int(np.argmax(off)), off.shape))
    if off[worst] > rtol * np.abs(M).max():
        raise ValueError(f"propagation matrix {worst[0]} has entry {worst[1:]} = {M[worst]:.3g}, outside the axial "
                         f"pattern that propagate.comp assumes (sslpv_gl.sh.AXIAL_PATTERN)")


def neighbour_slices(offset):
    """``(destination, source)`` slices of a ``[z, y, x]`` array for sources at ``d + offset``.

    ``a[src]`` lines up with ``out[dst]`` for every destination whose neighbour
    ``d + offset`` lies in the grid (``offset`` is ``(ox, oy, oz)``, one of
    :data:`SOURCE_OFFSETS`); the twin's gather and the steady solver's sparse
    operator both index their neighbours through it.
    """
    src = [slice(None)] * 3
    dst = [slice(None)] * 3
    for axis_xyz, o in enumerate(offset):
        ax = 2 - axis_xyz                            # array axis of x, y, z
        if o > 0:
            src[ax], dst[ax] = slice(o, None), slice(None, -o)
        elif o < 0:
            src[ax], dst[ax] = slice(None, o), slice(-o, None)
    return tuple(dst), tuple(src)


def scatter_factors(sigma_s_prime, g):
    """Eq. 3 per-band factors -> (..., 2) = ``(k0, k1)``.

    ``k_l = (1 - s') + s' g^l``; the HG multipole moments are ``p_l = g^l``
    (Sec. 3.2.2), so ``k0 = 1``: scattering never changes the flux.
    """
    sp = np.asarray(sigma_s_prime, dtype=np.float64)
    g = np.asarray(g, dtype=np.float64)
    sp, g = np.broadcast_arrays(sp, g)
    k1 = (1.0 - sp) + sp * g
    return np.stack([np.ones_like(k1), k1], axis=-1)


def apply_scattering(c, sigma_s_prime, g):
    """Eq. 3 applied to coefficients ``c`` (..., 4); ``sigma_s_prime``, ``g`` (...)."""
    c = np.asarray(c, dtype=np.float64)
    k = scatter_factors(sigma_s_prime, g)
    out = c.copy()
    out[..., 1:] *= k[..., 1:2]
    return out


def rotate_to_normal_c10(c, n):
    """``c10`` expressed in the frame whose z axis is the unit normal ``n``.

    Eq. 6 with the explicit rotation of Sec. 4:
    ``c10^(n) = sin(a) sin(b) c1-1 + cos(b) c10 + cos(a) sin(b) c11``, i.e.
    ``n_y c1-1 + n_z c10 + n_x c11``. ``c`` (..., 4), ``n`` (..., 3) -> (...).
    """
    c = np.asarray(c, dtype=np.float64)
    n = np.asarray(n, dtype=np.float64)
    return n[..., 1] * c[..., 1] + n[..., 2] * c[..., 2] + n[..., 0] * c[..., 3]


def hemisphere_radiance(c, n, area):
    """Area-light radiance of a cell's point light towards normal ``n`` (Eq. 5/7).

    ``L_i = (1/(A pi)) int_{n.w>0} I(w) dw
          = (2/A) (c00/sqrt(4 pi) + 1/2 sqrt(3/(4 pi)) c10^(n))``,
    the two-band form of Sec. 4 without the Fresnel factor ``T`` of Eq. 4.
    ``c`` (..., 4), ``n`` (..., 3) unit, ``area`` scalar or (...) -> (...).
    """
    c = np.asarray(c, dtype=np.float64)
    c10n = rotate_to_normal_c10(c, n)
    return (2.0 / np.asarray(area, dtype=np.float64)) * (
        SH_Y00 * c[..., 0] + 0.5 * SH_Y1 * c10n
    )
