r"""Chandrasekhar's H-function for isotropic scattering, and what it gives for a half-space.

Transport theory's exact answers for the setting of :mod:`harness.reference.random_walk`
(a homogeneous, index-matched half-space, isotropic scattering of albedo ``omega``), the
anchors against which the walk and the dipole kernels are judged:

* :func:`h_function`: ``H(mu)``, from its nonlinear integral equation in the second form
  (Chandrasekhar, *Radiative Transfer*, 1950, Ch. V, Eq. (H2) below), iterated to a fixed point
  on Gauss-Legendre nodes in ``t`` with ``mu' = t^2`` (``H`` has a ``mu ln mu`` term at 0), then
  evaluated at any ``mu`` by the same equation (Nyström interpolation):

      (H2)  1 / H(mu) = sqrt(1 - omega) + omega/2 int_0^1 mu' H(mu') / (mu + mu') dmu'

  which follows from the first form ``H(mu) = 1 + omega/2 mu H(mu) int_0^1 H(mu') / (mu + mu') dmu'``
  and the moment ``int_0^1 H dmu = 2 (1 - sqrt(1 - omega)) / omega`` (Ch. V, Sec. 39). The
  fixed point converges linearly, at a rate that tends to 1 as ``omega -> 1``: ``omega`` is limited
  to [0, 1) (at 0.999 a few hundred iterations; the conservative case is left out).
* :func:`plane_albedo`: the fraction of a collimated beam's power, incident at cosine ``mu_0``,
  that the half-space returns through its surface, all orders of scattering (Ch. VI):

      (A)   A(mu_0) = 1 - H(mu_0) sqrt(1 - omega)

  For a pencil beam of unit power this is the total diffuse reflectance (superposition: the
  medium is invariant under translations along the surface).
* :func:`single_scattering_albedo`: the order-1 part of the same, for any phase function
  (here Henyey-Greenstein): with ``mu`` the exit cosine,

      (S)   A_1(mu_0) = omega int_{upward} p(cos Theta) mu / (mu + mu_0) dw

  (the first collision at depth ``z`` has density ``sigma_t e^(-sigma_t z / mu_0) / mu_0``, the
  scattered photon leaves with probability ``e^(-sigma_t z / mu)``; the integral over ``z`` gives
  ``mu / (mu + mu_0)``). By 2D Gauss-Legendre quadrature over the upward hemisphere.
* :func:`single_scattering_exitance`: where the order-1 light leaves, per unit area, for a pencil
  beam of unit power entering at the origin along ``b = (sin theta, 0, -cos theta)``; at the exit
  point ``e = (x, y, 0)``, with ``c = s b`` the collision point and ``v = e - c``:

      (S_r) R_1(x, y) = omega int_0^inf sigma_t e^(-sigma_t s) p(v.b / |v|) (s cos theta / |v|) / |v|^2
                        e^(-sigma_t |v|) ds

  (collision density, the scattered intensity ``omega p`` toward ``e``, the solid angle per unit
  area of the surface seen from ``c``, the way out). Gauss-Legendre in ``u = 1 - e^(-sigma_t s)``.

Limits: isotropic scattering for (H2) and (A) (the H-function of an anisotropic phase function
is a different equation); index-matched boundary; no internal reflection.
"""

from __future__ import annotations

import numpy as np

__all__ = ["h_function", "plane_albedo", "single_scattering_albedo", "single_scattering_exitance", "henyey_greenstein"]


def _nodes(n):
    """Nodes and weights on [0, 1] for ``mu' = t^2``, ``dmu' = 2 t dt`` (resolves ``mu ln mu`` at 0)."""
    x, w = np.polynomial.legendre.leggauss(n)
    t, wt = 0.5 * (x + 1.0), 0.5 * w
    return t * t, 2.0 * t * wt


def _check_albedo(albedo, upper_open=False):
    if not (0.0 <= albedo < 1.0 if upper_open else 0.0 <= albedo <= 1.0):
        raise ValueError(f"albedo {albedo}: must lie in [0, {'1)' if upper_open else '1]'}")


def h_function(mu, albedo, nodes=200, tol=1e-14, max_iterations=10_000):
    """Chandrasekhar's ``H(mu)`` for isotropic scattering of single-scattering albedo ``albedo``, Eq. (H2).

    ``mu`` (any shape) in [0, 1]. The fixed-point iteration starts from ``H = 1`` and stops when
    no node changes by more than ``tol``; it raises if that takes over ``max_iterations``.
    """
    _check_albedo(albedo, upper_open=True)
    mu = np.asarray(mu, dtype=np.float64)
    if np.any((mu < 0) | (mu > 1)):
        raise ValueError("mu: cosines in [0, 1]")
    m, w = _nodes(nodes)
    root = np.sqrt(1.0 - albedo)
    kernel = 0.5 * albedo * w * m / (m[:, None] + m[None, :])      # [i, j]: mu_j w_j / (mu_i + mu_j)
    h = np.ones_like(m)
    for _ in range(max_iterations):
        nxt = 1.0 / (root + kernel @ h)
        if np.max(np.abs(nxt - h)) < tol:
            h = nxt
            break
        h = nxt
    else:
        raise RuntimeError(f"h_function: no fixed point within {max_iterations} iterations (albedo {albedo})")
    flat = mu.reshape(-1)
    integral = (0.5 * albedo * w * m / (flat[:, None] + m[None, :])) @ h
    return (1.0 / (root + integral)).reshape(mu.shape)


def plane_albedo(mu0, albedo, **kwargs):
    """Eq. (A): ``1 - H(mu_0) sqrt(1 - omega)``, all orders, isotropic scattering, index-matched."""
    return 1.0 - h_function(mu0, albedo, **kwargs) * np.sqrt(1.0 - albedo)


def single_scattering_albedo(mu0, albedo, g=0.0, nodes=96):
    """Eq. (S): the order-1 part of the plane albedo, Henyey-Greenstein phase ``g``, incidence cosine ``mu0``.

    The beam travels along ``(sqrt(1 - mu0^2), 0, -mu0)``; the exit direction ``(sin t cos phi,
    sin t sin phi, mu)``; ``cos Theta`` between them. Gauss-Legendre in ``mu`` on [0, 1] and in
    ``phi`` on [0, pi] (symmetric), ``nodes`` each (the HG peak needs more nodes as ``g -> 1``).
    """
    _check_albedo(albedo)
    x, w = np.polynomial.legendre.leggauss(nodes)
    mu, wm = 0.5 * (x + 1.0), 0.5 * w
    phi, wp = 0.5 * np.pi * (x + 1.0), 0.5 * np.pi * w
    st0 = np.sqrt(1.0 - mu0 * mu0)
    sin_t = np.sqrt(1.0 - mu * mu)
    cos_th = st0 * sin_t[:, None] * np.cos(phi)[None, :] - mu0 * mu[:, None]
    p = henyey_greenstein(cos_th, g)
    return float(albedo * 2.0 * np.einsum("ij,i,j,i->", p, wm, wp, mu / (mu + mu0)))


def henyey_greenstein(cos_theta, g):
    """Henyey-Greenstein's phase function (per steradian) of the cosine between the directions of travel."""
    return (1.0 - g * g) / (4.0 * np.pi * (1.0 + g * g - 2.0 * g * cos_theta) ** 1.5)


def single_scattering_exitance(x, y, albedo, g=0.0, theta_deg=0.0, sigma_t=1.0, nodes=64):
    """Eq. (S_r): order-1 exitance per unit area at surface points ``(x, y)`` (any shape), unit beam power.

    Not for points within a fraction of a mean free path of the origin (the integrand peaks at
    ``s -> 0`` there and the fixed rule loses accuracy).
    """
    _check_albedo(albedo)
    x, y = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
    th = np.radians(theta_deg)
    b = np.array([np.sin(th), 0.0, -np.cos(th)])
    xu, wu = np.polynomial.legendre.leggauss(nodes)
    u, wu = 0.5 * (xu + 1.0), 0.5 * wu
    s = -np.log1p(-u) / sigma_t                               # sigma_t e^(-sigma_t s) ds = du
    vx = x[..., None] - s * b[0]
    vy = y[..., None] - s * b[1]
    vz = -s * b[2]                                            # s cos(theta) > 0: up to the surface
    d = np.sqrt(vx * vx + vy * vy + vz * vz)
    cos_scatter = (vx * b[0] + vy * b[1] + vz * b[2]) / d
    integrand = henyey_greenstein(cos_scatter, g) * (vz / d) / (d * d) * np.exp(-sigma_t * d)
    return albedo * np.sum(integrand * wu, axis=-1)
