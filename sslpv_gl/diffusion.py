"""The ``diffusion`` mapping: a physical medium to the lattice material whose steady state matches diffusion theory.

Equation numbers refer to ``docs/diffusion_mapping.md``, which derives everything
here from the lattice's own constants (:mod:`sslpv_gl.lattice`). Per cell, diffusion
theory (Eq. (14)) gives ``sigma_tr``; the mapping picks the LPV loss that puts the
lattice Green's function's pole at ``kappa = sigma_tr dx`` (Eq. (15)-(16)), the band-1
factor ``k1`` (Eq. (17), default :data:`~sslpv_gl.lattice.DIFFUSION_K1` = -1, the most
isotropic lattice), and the scales that turn the accumulated ``c00`` into fluence
(Eq. (18)) and shaded radiance (Eq. (21)).

Functions
---------

.. list-table::
   :header-rows: 1

   * - function
     - docs equation
     - meaning
   * - ``diffusion_coefficients(sigma_t, albedo, g)``
     - (14)
     - ``sigma_a, D, sigma_tr`` of diffusion theory
   * - ``diffusion_mapping(sigma_t, albedo, g, dx, k1)``
     - (15)-(21)
     - per-cell ``sigma_lpv, sigma_s_prime, g, fluence_scale, radiance_scale``
   * - ``radiance_scale(sigma_t, albedo, g, dx, k1)``
     - (21)
     - factor on ``sh.hemisphere_radiance`` (A = dx^2) of the accumulation grid

Limits
------
* Homogeneous, unbounded lattice; the mapping is applied cell by cell in a
  heterogeneous medium (local approximation).
* Cubic cells (the propagation matrices assume them).
* ``sigma_a = 0`` has an infinite diffusion length: the mapping gives
  ``sigma_lpv = 0`` there (the lattice then loses nothing, as the physics)
  and a radiance scale from the limit ``kappa -> 0`` (Eq. (19)).
"""

from __future__ import annotations

import numpy as np

from harness.errors import InputError

from .lattice import DIFFUSION_K1, constants, d_lpv, survival

__all__ = ["diffusion_coefficients", "diffusion_mapping", "fluence_scale", "radiance_scale"]


def diffusion_coefficients(sigma_t, albedo, g):
    """Diffusion theory (Eq. (14)) -> ``(sigma_a, sigma_t_prime, sigma_tr)``, float64 arrays.

    ``sigma_a = sigma_t (1 - albedo)``, ``sigma_t' = sigma_a + sigma_s (1 - g)``,
    ``D = 1 / (3 sigma_t')`` and ``sigma_tr = sqrt(sigma_a / D) = sqrt(3 sigma_a sigma_t')``.
    ``sigma_t'`` is returned instead of ``D`` so that vacuum (``sigma_t' = 0``,
    ``D`` infinite) stays finite.
    """
    st = np.asarray(sigma_t, dtype=np.float64)
    a = np.asarray(albedo, dtype=np.float64)
    gg = np.asarray(g, dtype=np.float64)
    sigma_a = st * (1.0 - a)
    sigma_tp = sigma_a + st * a * (1.0 - gg)
    sigma_tr = np.sqrt(np.maximum(3.0 * sigma_a * sigma_tp, 0.0))
    return sigma_a, sigma_tp, sigma_tr


def _check_k1(k1):
    if not (isinstance(k1, (int, float, np.floating)) and -1.0 <= float(k1) <= 1.0):
        raise InputError("diffusion mapping", "k1", f"must be a number in [-1, 1], got {k1!r}",
                         "use the default DIFFUSION_K1 = -1 or a value in [-1, 1]")
    return float(k1)


def diffusion_mapping(sigma_t, albedo, g, dx, k1=DIFFUSION_K1, matrices=None):
    """Physical medium -> LPV material matching diffusion theory (Eq. (15)-(21)) -> dict of float64.

    Per cell (arrays broadcast together), with ``kappa = sigma_tr dx``
    (Eq. (15)) and ``D_lpv = D_lpv(k1)`` (Eq. (9)):

    * ``sigma_lpv = max(0, ln a + ln(1 + D_lpv kappa^2)) / dx`` (Eq. (16)),
      so the steady-state lattice diffusion length ``sqrt(lambda0 D_lpv /
      (1 - lambda0))`` cells equals ``1 / sigma_tr`` (Eq. (11), (15));
    * ``sigma_s_prime = 1`` and ``g = k1``: Eq. 3's band-1 factor is then
      exactly ``k1`` (Eq. (17)); the returned ``g`` is the LATTICE's, the
      medium's ``g`` has entered through ``sigma_t'``;
    * ``fluence_scale = sqrt(4 pi) lambda0 D_lpv / (D dx)`` turns the
      accumulated ``c00`` into fluence (W per unit area) (Eq. (18));
    * ``radiance_scale = lambda0 D_lpv dx / (2 D)``, the factor on
      ``sh.hemisphere_radiance(c_accum, n, dx^2)`` (Eq. (21)).

    Also returned: ``kappa``, ``lambda0`` (the survival actually run,
    Eq. (5)), ``d_lpv``. ``sigma_a = 0`` gives ``sigma_lpv = 0`` (infinite
    diffusion length, nothing to match) with the finite scales of Eq. (19);
    vacuum (``sigma_t = 0``) gives zero scales.
    """
    k1 = _check_k1(k1)
    dx = float(dx)
    c = constants(matrices)
    _, sigma_tp, sigma_tr = diffusion_coefficients(sigma_t, albedo, g)
    kappa = sigma_tr * dx
    D = float(d_lpv(k1, matrices))
    # Eq. (16): the loss that puts the pole of 1/(1 - lambda(q)) at q = i kappa;
    # clamp at 0 where the geometric survival a already loses more (a < 1)
    sigma_dx = np.maximum(np.log(c.a) + np.log1p(D * kappa * kappa), 0.0)
    lam0 = survival(sigma_dx, matrices)
    # Eq. (18) with 1/D = 3 sigma_t' (finite in vacuum)
    fluence = np.sqrt(4.0 * np.pi) * lam0 * D * 3.0 * sigma_tp / dx
    radiance = 1.5 * lam0 * D * sigma_tp * dx           # Eq. (21) = fluence dx^2 / (2 sqrt(4 pi))
    shape = np.broadcast(np.asarray(sigma_t), np.asarray(albedo), np.asarray(g)).shape
    return {
        "sigma_lpv": np.broadcast_to(sigma_dx / dx, shape).copy(),
        "sigma_s_prime": np.ones(shape),
        "g": np.full(shape, k1),
        "fluence_scale": np.broadcast_to(fluence, shape).copy(),
        "radiance_scale": np.broadcast_to(radiance, shape).copy(),
        "kappa": np.broadcast_to(kappa, shape).copy(),
        "lambda0": np.broadcast_to(lam0, shape).copy(),
        "d_lpv": D,
    }


def fluence_scale(sigma_t, albedo, g, dx, k1=DIFFUSION_K1):
    """Fluence per unit accumulated ``c00`` under the ``diffusion`` mapping (Eq. (18))."""
    return diffusion_mapping(sigma_t, albedo, g, dx, k1)["fluence_scale"]


def radiance_scale(sigma_t, albedo, g, dx, k1=DIFFUSION_K1):
    """Factor on ``sh.hemisphere_radiance`` (``A = dx^2``) under the ``diffusion`` mapping (Eq. (21)).

    Multiply the shaded subsurface radiance of a point by the value of the
    cell whose coefficients it reads (equivalently: multiply the
    accumulation grid cell by cell before shading; shading is linear in
    ``c``). Then its isotropic part is diffusion theory's ``phi / (4 pi)``.
    """
    return diffusion_mapping(sigma_t, albedo, g, dx, k1)["radiance_scale"]
