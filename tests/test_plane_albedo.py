"""Transport theory's exact half-space results (``harness.reference.plane_albedo``) against independent routes.

* ``H(mu)`` from the iterated integral equation (Eq. H2) against Chandrasekhar's explicit integral
  ``ln H(mu) = -(mu/pi) int_0^(pi/2) ln(1 - omega theta cot theta) / (cos^2 theta + mu^2 sin^2 theta) dtheta``
  by adaptive quadrature (a different equation, a different quadrature): within 1e-9.
* The zeroth moment ``int_0^1 H dmu = 2 (1 - sqrt(1 - omega)) / omega`` (Chandrasekhar 1950, Ch. V).
* The plane albedo (Eq. A) against the Monte Carlo table of ``/work/shared/NOTES.md`` ("Transport-theory
  anchors for a half-space", 2e6 photons each, standard error about 3e-4): within 4 of those standard errors.
* Single scattering: Eq. (S) at ``g = 0`` against its closed form ``omega/2 (1 - mu0 ln(1 + 1/mu0))``, and
  for ``g != 0`` against the plane integral of the order-1 exitance (Eq. S_r) in polar coordinates.

Pure NumPy/SciPy, a few seconds.
"""

import numpy as np
import pytest
from scipy.integrate import quad

from harness.reference import plane_albedo as pa


def h_explicit(mu, omega):
    """Chandrasekhar's explicit form of H for isotropic scattering (Radiative Transfer, Ch. V)."""
    def f(th):
        th_cot = th / np.tan(th) if th > 0 else 1.0
        return np.log(1.0 - omega * th_cot) / (np.cos(th) ** 2 + mu * mu * np.sin(th) ** 2)

    return np.exp(-mu / np.pi * quad(f, 0.0, np.pi / 2, limit=200, epsabs=1e-13, epsrel=1e-12)[0])


class TestHFunction:
    @pytest.mark.parametrize("omega", [0.3, 0.5, 0.9, 0.99, 0.999])
    def test_iteration_against_the_explicit_integral(self, omega):
        mus = np.array([0.05, 0.2, 0.5, 0.8, 1.0])
        ours = pa.h_function(mus, omega)
        ref = np.array([h_explicit(m, omega) for m in mus])
        np.testing.assert_allclose(ours, ref, rtol=1e-9)

    @pytest.mark.parametrize("omega", [0.5, 0.9, 0.999])
    def test_zeroth_moment(self, omega):
        x, w = np.polynomial.legendre.leggauss(200)
        t = 0.5 * (x + 1.0)
        moment = np.sum(pa.h_function(t * t, omega) * 2 * t * 0.5 * w)      # mu = t^2
        assert moment == pytest.approx(2 * (1 - np.sqrt(1 - omega)) / omega, rel=1e-9)

    def test_no_scattering_and_the_range(self):
        assert np.all(pa.h_function(np.array([0.1, 1.0]), 0.0) == 1.0)
        with pytest.raises(ValueError, match="albedo"):
            pa.h_function(0.5, 1.0)
        with pytest.raises(ValueError, match="mu"):
            pa.h_function(1.5, 0.5)


class TestPlaneAlbedo:
    #: /work/shared/NOTES.md, "Transport-theory anchors for a half-space": (alpha', 0 deg, 60 deg)
    NOTES = ((0.5, 0.1152, 0.1602), (0.9, 0.4155, 0.5081), (0.99, 0.7529, 0.8149), (0.999, 0.9127, 0.9379))
    NOTES_SE = 3e-4

    @pytest.mark.parametrize("row", NOTES, ids=lambda r: f"alpha{r[0]}")
    def test_against_the_notes_table(self, row):
        omega, normal, oblique = row
        assert pa.plane_albedo(1.0, omega) == pytest.approx(normal, abs=4 * self.NOTES_SE)
        assert pa.plane_albedo(0.5, omega) == pytest.approx(oblique, abs=4 * self.NOTES_SE)


class TestSingleScattering:
    @pytest.mark.parametrize("mu0", [1.0, 0.5, 0.2])
    def test_isotropic_closed_form(self, mu0):
        omega = 0.7
        assert pa.single_scattering_albedo(mu0, omega) == pytest.approx(
            omega / 2 * (1 - mu0 * np.log(1 + 1 / mu0)), rel=1e-10)

    @pytest.mark.parametrize("g,theta", [(0.0, 0.0), (0.6, 0.0), (0.6, 60.0), (-0.4, 60.0)])
    def test_exitance_integrates_to_the_albedo(self, g, theta):
        """int R_1 dA over the plane (polar: 16 geometric panels in r up to 60 mean free paths, 24 Gauss-Legendre
        nodes each, 48 in phi; 100 nodes in s) = Eq. (S)."""
        omega = 0.9
        x, w = np.polynomial.legendre.leggauss(24)
        u, wu = 0.5 * (x + 1.0), 0.5 * w
        xp, wp = np.polynomial.legendre.leggauss(48)
        phi, wphi = np.pi * (xp + 1.0), np.pi * wp          # [0, 2 pi]
        edges = np.concatenate([[0.0], np.geomspace(1e-4, 60.0, 16)])
        total = 0.0
        for a, b in zip(edges[:-1], edges[1:]):
            r = a + (b - a) * u
            f = pa.single_scattering_exitance(r[:, None] * np.cos(phi), r[:, None] * np.sin(phi), omega, g, theta,
                                              nodes=100)
            total += (b - a) * np.einsum("ij,i,j,i->", f, wu, wphi, r)
        ref = pa.single_scattering_albedo(np.cos(np.radians(theta)), omega, g)
        print(f"g {g}, {theta} deg: plane integral {total:.10f}, Eq. (S) {ref:.10f}, rel {total / ref - 1:.1e}")
        assert total == pytest.approx(ref, rel=1e-6)
