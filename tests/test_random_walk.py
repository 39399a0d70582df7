"""The half-space random walk (``harness.reference.random_walk``) against transport theory's exact results.

Every comparison allows 4.5 standard errors of the walk (the walk's own binomial SE; at a fixed seed the
tests are deterministic, and 4.5 sigma keeps a correct walk passing at any seed with probability better
than 1 - 1e-4 per comparison):

* the total diffuse reflectance, all orders, isotropic scattering, at normal and 60 degree incidence,
  against Chandrasekhar's ``1 - H(mu0) sqrt(1 - omega)`` (``plane_albedo``, Eq. A);
* the single-scattering (order-1) reflectance with Henyey-Greenstein ``g`` of either sign, against the
  hemisphere integral Eq. (S): this is where a walk that ignored ``g`` would show;
* the order-1 exitance per annulus and per sector (forward, sideways, backward) against Eq. (S_r) averaged
  over the same bins: the geometry of the exit points, the bins' areas and the sectors' orientation;
* the sampler alone: HG's mean cosine is ``g``, and its CDF at a few cosines.

Few photons (2e4 - 1e5 per walk): about 5 s on one core.
"""

import numpy as np
import pytest

from harness.reference import plane_albedo as pa
from harness.reference import random_walk as rw

Z = 4.5


def assert_within(value, se, ref, what):
    z = (np.asarray(value) - ref) / np.asarray(se)
    assert np.all(np.abs(z) < Z), f"{what}: walk {value} +- {se} against {ref}: z = {np.round(z, 2)}"


class TestTotalReflectance:
    @pytest.mark.parametrize("theta", [0.0, 60.0])
    @pytest.mark.parametrize("omega", [0.5, 0.9, 0.99])
    def test_against_the_h_function(self, omega, theta):
        w = rw.walk(omega, theta_deg=theta, n_photons=40_000, seed=11)
        value, se = w.reflectance()
        assert_within(value, se, pa.plane_albedo(np.cos(np.radians(theta)), omega), f"omega {omega}, {theta} deg")
        assert w.unfinished == 0
        # the parts add up; nothing leaves unscattered
        assert w.reflectance("single")[0] + w.reflectance("multiple")[0] == pytest.approx(value, abs=1e-15)


class TestSingleScattering:
    @pytest.mark.parametrize("g,theta", [(0.8, 0.0), (0.5, 60.0), (-0.5, 0.0), (-0.3, 60.0)])
    def test_order_one_reflectance_with_anisotropy(self, g, theta):
        omega = 0.8
        w = rw.walk(omega, g=g, theta_deg=theta, n_photons=40_000, seed=12)
        value, se = w.reflectance("single")
        assert_within(value, se, pa.single_scattering_albedo(np.cos(np.radians(theta)), omega, g), f"g {g}")

    @pytest.mark.parametrize("g,theta", [(0.0, 0.0), (0.5, 60.0), (-0.3, 60.0)])
    def test_order_one_exitance_per_annulus_and_sector(self, g, theta):
        omega = 0.8
        edges = np.array([0.5, 1.0, 1.5, 2.0, 3.0, 4.0])
        w = rw.walk(omega, g=g, theta_deg=theta, n_photons=100_000, seed=13, r_edges=edges)
        for sector in (None, rw.FORWARD, 1, w.backward):
            value, se = w.exitance("single", sector)
            phi = (0.0, 2 * np.pi) if sector is None else w.sector_edges(sector)
            ref = rw.bin_mean(lambda r, p: pa.single_scattering_exitance(r * np.cos(p), r * np.sin(p), omega, g, theta),
                              edges, phi)
            keep = value > 0          # an empty bin has no standard error to judge it by
            assert keep.sum() >= 4
            assert_within(value[keep], se[keep], ref[keep], f"g {g}, {theta} deg, sector {sector}")


class TestSampler:
    @pytest.mark.parametrize("g", [-0.7, 0.0, 0.3, 0.9])
    def test_henyey_greenstein(self, g):
        u = (np.arange(200_000) + 0.5) / 200_000                  # stratified: the quadrature of the inverse CDF
        c = rw.sample_hg(g, u)
        assert c.mean() == pytest.approx(g, abs=2e-4)             # <cos> = g
        for c0 in (-0.5, 0.2, 0.9):                                 # CDF by Gauss-Legendre of the density
            x, wq = np.polynomial.legendre.leggauss(200)
            t = 0.5 * (c0 + 1.0) * (x + 1.0) - 1.0
            cdf = 0.5 * (c0 + 1.0) * np.sum(wq * 2 * np.pi * pa.henyey_greenstein(t, g))
            assert np.mean(c <= c0) == pytest.approx(cdf, abs=1e-4)


class TestWalk:
    def test_reproducible_and_seeded(self):
        a = rw.walk(0.9, theta_deg=30.0, n_photons=3000, seed=5, batch=1000)
        b = rw.walk(0.9, theta_deg=30.0, n_photons=3000, seed=5, batch=1000)
        c = rw.walk(0.9, theta_deg=30.0, n_photons=3000, seed=6, batch=1000)
        assert np.array_equal(a.counts, b.counts) and np.array_equal(a.left, b.left)
        assert not np.array_equal(a.counts, c.counts)

    def test_bins_hold_what_left_inside_them(self):
        w = rw.walk(0.9, n_photons=5000, seed=1, r_edges=np.array([0.0, 1e6]))
        assert w.counts.sum() == w.left.sum()

    def test_unfinished_photons_are_counted(self):
        w = rw.walk(0.999, n_photons=2000, seed=1, max_orders=3)
        assert w.unfinished > 0
        assert w.left.sum() + w.unfinished <= w.n_photons

    @pytest.mark.parametrize("kwargs,match", [
        ({"albedo": 1.0}, "albedo"), ({"albedo": 0.5, "g": 1.0}, "g"), ({"albedo": 0.5, "theta_deg": 90.0}, "theta"),
        ({"albedo": 0.5, "n_photons": 0}, "n_photons"), ({"albedo": 0.5, "r_edges": [1.0, 0.5]}, "r_edges"),
        ({"albedo": 0.5, "n_sectors": 3}, "n_sectors")])
    def test_bad_input(self, kwargs, match):
        with pytest.raises(ValueError, match=match):
            rw.walk(**kwargs)
