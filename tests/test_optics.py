"""Tests for sslpv_gl.optics: Snell, Fresnel, Sec. 3.1 texel solid angles, GGX."""

import numpy as np
import pytest

from sslpv_gl.optics import (
    fresnel_reflectance,
    fresnel_transmittance,
    frustum_solid_angle,
    ggx_reflection,
    refract,
    texel_solid_angles,
)

N_UP = np.array([0.0, 0.0, 1.0])


class TestTexelSolidAngles:
    @pytest.mark.parametrize("fov_y, aspect, near", [(60.0, 1.0, 1.0), (90.0, 1.5, 0.1),
                                                      (35.0, 0.75, 7.0)])
    def test_sum_is_frustum_solid_angle(self, fov_y, aspect, near):
        d_omega = texel_solid_angles(256, 256, fov_y, aspect, near)
        assert d_omega.shape == (256, 256)
        fov_x = np.degrees(2 * np.arctan(aspect * np.tan(np.radians(fov_y) / 2)))
        np.testing.assert_allclose(d_omega.sum(), frustum_solid_angle(fov_x, fov_y), rtol=1e-3)

    def test_paper_formula_at_near_one(self):
        # Sec. 3.1 as printed: 4 alpha tan^2(FOV/2) cos^3 / (Nx Ny), alpha = H/W, FOV horizontal
        nx, ny, fov_x = 64, 32, 75.0
        alpha = ny / nx
        fov_y = np.degrees(2 * np.arctan(alpha * np.tan(np.radians(fov_x) / 2)))
        d_omega = texel_solid_angles(nx, ny, fov_y, nx / ny, near=1.0)
        u = ((np.arange(nx) + 0.5) / nx * 2 - 1) * np.tan(np.radians(fov_x) / 2)
        v = ((np.arange(ny) + 0.5) / ny * 2 - 1) * alpha * np.tan(np.radians(fov_x) / 2)
        cos = 1 / np.sqrt(1 + u[None, :] ** 2 + v[:, None] ** 2)
        printed = 4 * alpha * np.tan(np.radians(fov_x) / 2) ** 2 * cos**3 / (nx * ny)
        np.testing.assert_allclose(d_omega, printed, rtol=1e-12)

    def test_independent_of_near(self):
        np.testing.assert_allclose(texel_solid_angles(16, 8, 50, 2, 0.01),
                                   texel_solid_angles(16, 8, 50, 2, 100.0), rtol=1e-12)

    def test_hemisphere_limit(self):
        # a 90x90 degree frustum covers one face of a cube: 4 pi / 6
        np.testing.assert_allclose(frustum_solid_angle(90.0, 90.0), 4 * np.pi / 6, rtol=1e-14)


class TestFresnel:
    @pytest.mark.parametrize("eta", [1.33, 1.5, 2.4])
    def test_normal_incidence(self, eta):
        np.testing.assert_allclose(fresnel_transmittance(1.0, eta),
                                   1 - ((eta - 1) / (eta + 1)) ** 2, rtol=1e-14)

    def test_index_matched_is_one(self):
        cos = np.linspace(-1, 1, 11)
        np.testing.assert_array_equal(fresnel_transmittance(cos, 1.0), np.ones(11))

    def test_total_internal_reflection(self):
        eta = 1.5
        critical = np.sqrt(1 - 1 / eta**2)  # cos of the critical angle, inside
        assert fresnel_transmittance(-(critical - 1e-3), eta) == 0.0
        assert fresnel_transmittance(-(critical + 1e-3), eta) > 0.0

    def test_symmetric_across_interface(self):
        # T for entering at theta_i equals T for leaving along the refracted ray
        eta, cos_i = 1.4, 0.6
        cos_t = np.sqrt(1 - (1 - cos_i**2) / eta**2)
        np.testing.assert_allclose(fresnel_transmittance(cos_i, eta),
                                   fresnel_transmittance(-cos_t, eta), rtol=1e-12)

    def test_reflectance_in_unit_interval(self):
        r = fresnel_reflectance(np.linspace(-1, 1, 201), 1.5)
        assert np.all((r >= 0) & (r <= 1))


class TestRefract:
    def test_no_bending_when_index_matched(self):
        d = np.array([[0.3, -0.4, -0.866], [0.9, 0.1, -0.1]])
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        np.testing.assert_allclose(refract(d, N_UP, 1.0), d, atol=1e-15)

    @pytest.mark.parametrize("eta", [1.33, 1.5])
    def test_snell(self, eta):
        d = np.array([0.6, 0.2, -0.7])
        d /= np.linalg.norm(d)
        t = refract(d, N_UP, eta)
        sin_i = np.linalg.norm(np.cross(d, N_UP))
        sin_t = np.linalg.norm(np.cross(t, N_UP))
        np.testing.assert_allclose(sin_i, eta * sin_t, rtol=1e-12)
        assert t[2] < 0  # goes inside
        # coplanar with the incident direction and the normal
        np.testing.assert_allclose(np.dot(np.cross(d, N_UP), t), 0.0, atol=1e-14)

    def test_tir_is_nan(self):
        d = np.array([0.9, 0.0, np.sqrt(1 - 0.81)])  # from inside, steep
        assert np.all(np.isnan(refract(d, N_UP, 1.5)))


def hemisphere_grid(n_theta=200, n_phi=200):
    mu, w_mu = np.polynomial.legendre.leggauss(n_theta)
    mu, w_mu = 0.5 * (mu + 1), 0.5 * w_mu
    phi = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    m, p = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1 - m**2)
    dirs = np.stack([s * np.cos(p), s * np.sin(p), m], -1).reshape(-1, 3)
    w = (w_mu[:, None] * np.full(n_phi, 2 * np.pi / n_phi)).reshape(-1)
    return dirs, w


class TestGGX:
    def test_reciprocity(self):
        rng = np.random.default_rng(3)
        wi = rng.normal(size=(50, 3))
        wo = rng.normal(size=(50, 3))
        wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]), np.abs(wo[:, 2])
        np.testing.assert_allclose(ggx_reflection(wi, wo, N_UP, 0.3, 1.5),
                                   ggx_reflection(wo, wi, N_UP, 0.3, 1.5), rtol=1e-12)

    @pytest.mark.parametrize("alpha", [0.2, 0.5])
    @pytest.mark.parametrize("theta_deg", [0.0, 45.0, 75.0])
    def test_albedo_matches_half_vector_integral(self, alpha, theta_deg):
        # int f cos dw_o over w_o, against the same integral written over the
        # half vector (dw_o = 4 (w_o.h) dw_h), with D and G typed from Walter 2007
        th = np.radians(theta_deg)
        wi = np.array([np.sin(th), 0.0, np.cos(th)])
        dirs, w = hemisphere_grid()
        albedo = np.sum(ggx_reflection(wi, dirs, N_UP, alpha, 1.5) * dirs[:, 2] * w)

        h = dirs
        cos_h = h[:, 2]
        d = alpha**2 / (np.pi * cos_h**4 * (alpha**2 + (1 - cos_h**2) / cos_h**2) ** 2)
        ih = h @ wi
        wo = 2 * ih[:, None] * h - wi

        def g1(v):
            c = v[..., 2]
            return np.where(c > 0, 2 / (1 + np.sqrt(1 + alpha**2 * (1 - c**2) / c**2)), 0.0)

        f = fresnel_reflectance(ih, 1.5)
        integrand = np.where((ih > 0) & (wo[:, 2] > 0), d * f * g1(wi) * g1(wo) * ih / wi[2], 0)
        via_h = np.sum(integrand * w)
        assert 0.0 < albedo <= 1.0
        np.testing.assert_allclose(albedo, via_h, rtol=2e-3)

    def test_smooth_limit_at_normal_incidence(self):
        # small alpha: the albedo tends to the smooth Fresnel reflectance 0.04
        dirs, w = hemisphere_grid(400, 64)
        albedo = np.sum(ggx_reflection(N_UP, dirs, N_UP, 0.2, 1.5) * dirs[:, 2] * w)
        np.testing.assert_allclose(albedo, 0.04, rtol=0.05)

    def test_below_horizon_is_zero(self):
        assert ggx_reflection(np.array([0, 0.6, 0.8]), np.array([0, 0.6, -0.8]), N_UP, 0.3,
                              1.5) == 0.0

    def test_index_matched_reflects_nothing(self):
        assert ggx_reflection(np.array([0, 0.6, 0.8]), np.array([0, -0.6, 0.8]), N_UP, 0.3,
                              1.0) == 0.0
