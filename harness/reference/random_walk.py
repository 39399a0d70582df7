r"""A pencil beam in an index-matched half-space: an analog Monte Carlo random walk in plain NumPy.

An independent route to what the dipole kernels (:mod:`dipole_gl.kernels`) model: the light a
narrow beam of unit power returns through the surface of a homogeneous, semi-infinite medium,
in total and as the exitance ``R(x, y)`` per unit area around the point of entry. Nothing here
uses diffusion theory, Mitsuba or the kernels.

.. list-table::
   :header-rows: 1

   * - Parameter of :func:`walk`
     - Meaning
   * - ``albedo``
     - single-scattering albedo ``omega = sigma_s / sigma_t``, in (0, 1)
   * - ``g``
     - Henyey-Greenstein asymmetry, in (-1, 1) (:func:`sample_hg`)
   * - ``theta_deg``
     - angle of incidence from the normal, in [0, 90) (index-matched: no refraction)
   * - ``sigma_t``
     - extinction (the unit of length is ``1/sigma_t``); default 1
   * - ``n_photons``, ``seed``
     - photons, and the seed of :class:`numpy.random.SeedSequence` (reproducible: the same
       seed, photons and ``batch`` give the same result bit for bit)
   * - ``r_edges``, ``n_sectors``
     - the exitance's bins: annuli around the point of entry, each split into ``n_sectors``
       equal sectors, sector 0 centred on the beam's horizontal direction of travel
       (:data:`FORWARD`; sector ``n_sectors / 2``, :attr:`Walk.backward`, against it)
   * - ``max_orders``
     - scattering events after which a photon still inside is given up (counted in
       :attr:`Walk.unfinished`, a bound on the bias); default 100,000

The walk (the scheme of Wang, Jacques & Zheng's MCML, 1995, reduced to one index-matched layer, with
analog absorption in place of MCML's implicit capture and roulette):

* **Geometry.** The medium fills ``z < 0``; the surface ``z = 0`` is index-matched (the outside
  has the medium's refractive index), so nothing is reflected or refracted there: a photon that
  crosses it has left. The beam enters at the origin travelling along
  ``(sin theta, 0, -cos theta)``.
* **Free flights** ``s = -ln(u) / sigma_t``. A flight that crosses ``z = 0`` leaves at the
  crossing point, where its exit is tallied (``x, y`` and the number of scattering events so
  far, its *order*).
* **Analog absorption.** At a collision the photon is absorbed with probability ``1 - omega``,
  else scattered: each photon carries weight 1 and leaves or is absorbed whole. A tally is the
  fraction of photons, a binomial proportion ``p`` with standard error ``sqrt(p (1 - p) / N)``.
  (Implicit capture would lower the variance a little at low albedo; analog absorption keeps
  every estimate an unweighted count, which is what the standard errors assume.)
* **Scattering** by Henyey-Greenstein's phase function about the direction of travel
  (:func:`sample_hg`, inverted CDF; the frame of Duff et al. 2017).

Results (:class:`Walk`): the total diffuse reflectance, single (order 1) and multiple
(order >= 2) apart, each with its standard error; the exitance per unit area and per unit
beam power in each annulus and sector, per order class, with its standard error. The
unscattered beam never returns (it travels downward), so order 0 is empty.

Limits: homogeneous, index-matched, semi-infinite; a pencil beam (the response to any other
illumination follows by superposition); exitance, not radiance (the exit directions are not
tallied); a bin's value is the mean over its area (compare a model's mean over the same area,
:func:`bin_mean`, not its value at the centre).
"""

from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["Walk", "walk", "sample_hg", "bin_mean", "FORWARD", "SINGLE", "MULTIPLE"]

#: Sector index of the beam's horizontal direction of travel (+x).
FORWARD = 0
#: Order classes of the tallies.
SINGLE, MULTIPLE = 0, 1


def sample_hg(g, u):
    """Cosine between the old and new directions of travel, Henyey-Greenstein, from uniform ``u``.

    ``cos = (1 + g^2 - ((1 - g^2) / (1 - g + 2 g u))^2) / (2 g)``, the inverse of the phase
    function's CDF (``u = 0`` gives -1, ``u = 1`` gives +1); ``1 - 2 u`` at ``g = 0``.
    """
    if abs(g) < 1e-6:
        return 1.0 - 2.0 * u
    s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u)
    return np.clip((1.0 + g * g - s * s) / (2.0 * g), -1.0, 1.0)


def _turn(x, y, z, cos_t, phi):
    """Directions at angle ``acos(cos_t)`` and azimuth ``phi`` about the unit vectors ``(x, y, z)``."""
    sin_t = np.sqrt(np.maximum(1.0 - cos_t * cos_t, 0.0))
    sign = np.where(z >= 0.0, 1.0, -1.0)               # Duff et al. 2017: a frame without branches
    a = -1.0 / (sign + z)
    b = x * y * a
    cp, sp = sin_t * np.cos(phi), sin_t * np.sin(phi)
    return (cp * (1.0 + sign * x * x * a) + sp * b + cos_t * x,
            cp * (sign * b) + sp * (sign + y * y * a) + cos_t * y,
            -cp * sign * x - sp * y + cos_t * z)


@dataclasses.dataclass(frozen=True)
class Walk:
    """The tallies of one :func:`walk`; every estimate comes with its standard error."""

    albedo: float
    g: float
    theta_deg: float
    sigma_t: float
    n_photons: int
    seed: int
    r_edges: np.ndarray            # (B + 1,) annuli's edges
    n_sectors: int
    counts: np.ndarray             # (2, n_sectors, B): exits per order class (SINGLE, MULTIPLE), sector, annulus
    left: np.ndarray               # (2,): every exit per order class, inside the bins or not
    unfinished: int                # photons still inside after max_orders scattering events

    @property
    def backward(self):
        """Sector index against the beam's horizontal direction of travel (-x)."""
        return self.n_sectors // 2

    def _p(self, k):
        p = np.asarray(k, dtype=np.float64) / self.n_photons
        return p, np.sqrt(p * (1.0 - p) / self.n_photons)

    def _orders(self, orders):
        try:
            return {"all": [SINGLE, MULTIPLE], "single": [SINGLE], "multiple": [MULTIPLE]}[orders]
        except KeyError:
            raise ValueError(f"orders {orders!r}: one of 'all', 'single', 'multiple'") from None

    def reflectance(self, orders="all"):
        """``(value, se)``: the fraction of the beam's power that leaves through the surface."""
        return self._p(self.left[self._orders(orders)].sum())

    def exitance(self, orders="all", sector=None):
        """``(value, se)`` per annulus: exitance per unit area and unit beam power, the mean over the bin.

        ``sector=None``: the whole annulus; an index: that sector alone (area ``annulus / n_sectors``).
        """
        c = self.counts[self._orders(orders)].sum(axis=0)
        area = np.pi * np.diff(self.r_edges ** 2)
        if sector is None:
            c = c.sum(axis=0)
        else:
            c = c[int(sector) % self.n_sectors]
            area = area / self.n_sectors
        p, se = self._p(c)
        return p / area, se / area

    def sector_edges(self, sector):
        """The azimuths ``(phi_0, phi_1)`` of a sector (radians, forward = 0)."""
        w = 2.0 * np.pi / self.n_sectors
        return (sector - 0.5) * w, (sector + 0.5) * w


def _check(albedo, g, theta_deg, sigma_t, n_photons, r_edges, n_sectors):
    if not 0.0 < albedo < 1.0:
        raise ValueError(f"albedo {albedo}: must lie in (0, 1) (at 1 the walk may never end)")
    if not -1.0 < g < 1.0:
        raise ValueError(f"g {g}: must lie in (-1, 1)")
    if not 0.0 <= theta_deg < 90.0:
        raise ValueError(f"theta_deg {theta_deg}: must lie in [0, 90)")
    if not sigma_t > 0.0:
        raise ValueError(f"sigma_t {sigma_t}: must be > 0")
    if int(n_photons) < 1:
        raise ValueError(f"n_photons {n_photons}: must be >= 1")
    if r_edges.ndim != 1 or len(r_edges) < 2 or r_edges[0] < 0 or np.any(np.diff(r_edges) <= 0):
        raise ValueError("r_edges: an increasing sequence of at least two distances >= 0")
    if int(n_sectors) < 1 or int(n_sectors) % 2:
        raise ValueError(f"n_sectors {n_sectors}: an even number >= 2")


def walk(albedo, g=0.0, theta_deg=0.0, n_photons=100_000, seed=0, sigma_t=1.0, r_edges=None, n_sectors=4,
         max_orders=100_000, batch=1 << 20):
    """Trace ``n_photons`` photons of a pencil beam into the half-space ``z < 0`` -> :class:`Walk`.

    ``r_edges`` defaults to 40 annuli of width ``0.5 / sigma_t``. Photons run in batches of
    ``batch``, each batch with its own stream spawned from ``seed``.
    """
    r_edges = np.asarray(np.arange(41) * 0.5 / sigma_t if r_edges is None else r_edges, dtype=np.float64)
    _check(albedo, g, theta_deg, sigma_t, n_photons, r_edges, n_sectors)
    n_photons, n_sectors, nb = int(n_photons), int(n_sectors), len(r_edges) - 1
    th = np.radians(theta_deg)
    d0 = np.array([np.sin(th), 0.0, -np.cos(th)])
    counts = np.zeros(2 * n_sectors * nb, dtype=np.int64)
    left = np.zeros(2, dtype=np.int64)
    unfinished = 0
    sizes = [min(batch, n_photons - lo) for lo in range(0, n_photons, batch)]
    for size, ss in zip(sizes, np.random.SeedSequence(seed).spawn(len(sizes))):
        rng = np.random.default_rng(ss)
        x, y, order, alive = _batch(rng, size, d0, albedo, g, sigma_t, max_orders)
        unfinished += alive
        cls = np.minimum(order, 2) - 1                  # order 1 -> SINGLE, >= 2 -> MULTIPLE
        left += np.bincount(cls, minlength=2)
        r = np.hypot(x, y)
        sec = np.floor((np.arctan2(y, x) / (2.0 * np.pi) * n_sectors + 0.5)).astype(np.int64) % n_sectors
        rb = np.searchsorted(r_edges, r, side="right") - 1
        ok = (rb >= 0) & (rb < nb)
        counts += np.bincount((cls[ok] * n_sectors + sec[ok]) * nb + rb[ok], minlength=counts.size)
    return Walk(float(albedo), float(g), float(theta_deg), float(sigma_t), n_photons, int(seed), r_edges, n_sectors,
                counts.reshape(2, n_sectors, nb), left, int(unfinished))


def _batch(rng, n, d0, albedo, g, sigma_t, max_orders):
    """One batch: exit points ``x, y``, their orders, and how many photons were given up."""
    px, py, pz = np.zeros(n), np.zeros(n), np.zeros(n)           # positions
    dx, dy, dz = (np.full(n, c) for c in d0)                     # directions of travel
    order = np.zeros(n, dtype=np.int64)                          # scattering events so far
    xs, ys, os_ = [], [], []
    for _ in range(max_orders + 1):
        if len(px) == 0:
            break
        # --- free flight; a crossing of z = 0 leaves at the crossing point
        s = rng.standard_exponential(len(px)) / sigma_t
        out = pz + s * dz > 0.0
        if out.any():
            t = -pz[out] / dz[out]
            xs.append(px[out] + t * dx[out])
            ys.append(py[out] + t * dy[out])
            os_.append(order[out])
        # --- collision: absorbed with probability 1 - albedo (analog), else scattered
        keep = np.flatnonzero(~out & (rng.random(len(px)) < albedo))
        s = s[keep]
        dx, dy, dz = dx[keep], dy[keep], dz[keep]
        px, py, pz = px[keep] + s * dx, py[keep] + s * dy, pz[keep] + s * dz
        dx, dy, dz = _turn(dx, dy, dz, sample_hg(g, rng.random(len(keep))), 2.0 * np.pi * rng.random(len(keep)))
        order = order[keep] + 1
    cat = (lambda a, dt: np.concatenate(a) if a else np.zeros(0, dt))      # noqa: E731
    return cat(xs, float), cat(ys, float), cat(os_, np.int64), len(px)


def bin_mean(f, r_edges, phi_range=(0.0, 2.0 * np.pi), nodes=8):
    """The mean of ``f(r, phi)`` (arrays in, array out) over each annular bin's sector -> (B,).

    Gauss-Legendre in ``r`` (weighted by ``r``) and in ``phi``, ``nodes`` each, per bin: what a
    model must be averaged to before it is compared with :meth:`Walk.exitance`.
    """
    r_edges = np.asarray(r_edges, dtype=np.float64)
    t, w = np.polynomial.legendre.leggauss(nodes)
    t, w = 0.5 * (t + 1.0), 0.5 * w
    lo, hi = r_edges[:-1, None], r_edges[1:, None]
    r = lo + (hi - lo) * t                                # (B, n)
    p0, p1 = phi_range
    phi = p0 + (p1 - p0) * t                              # (n,)
    vals = f(r[:, :, None], phi[None, None, :])           # (B, n, n)
    num = np.einsum("bij,i,j,bi->b", vals, w, w, r)
    den = np.einsum("i,bi->b", w, r)
    return num / den
