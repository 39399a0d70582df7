"""Tests for sslpv_gl.twin: injection (Sec. 3.1), propagation (Sec. 3.2, 4), shading (Sec. 3.3)."""

import numpy as np
import pytest

from sslpv_gl.sh import clamped_cosine_coeffs
from sslpv_gl.twin import inject, propagate, sample_trilinear, shade_points

N = 5
BMIN, BMAX = np.zeros(3), np.full(3, 2.5)   # dx = 0.5
DX = 0.5
SQRT_4PI = np.sqrt(4 * np.pi)


def point_source(c=(1.0, 0.0, 0.0, 0.0), at=(2, 2, 2)):
    grid = np.zeros((N, N, N, 3, 4))
    grid[at[2], at[1], at[0]] = c
    return grid


NEIGHBOURS = [(3, 2, 2), (1, 2, 2), (2, 3, 2), (2, 1, 2), (2, 2, 3), (2, 2, 1)]  # (x, y, z)


class TestPropagate:
    def test_isotropic_source_in_vacuum(self):
        prop, _ = propagate(point_source(), 0.0, 0.0, 0.0, DX, steps=1, skip=0)
        # flux int I dw = c00 sqrt(4 pi) is conserved by one step
        np.testing.assert_allclose(prop[..., 0].sum(axis=(0, 1, 2)) * SQRT_4PI, SQRT_4PI,
                                   rtol=1e-12)
        for x, y, z in NEIGHBOURS:
            np.testing.assert_allclose(prop[z, y, x, :, 0], 1 / 6, rtol=1e-12)
        mask = np.ones((N, N, N), bool)
        for x, y, z in NEIGHBOURS:
            mask[z, y, x] = False
        assert np.all(prop[mask] == 0)
        # each neighbour's lobe points away from the source (band 1 along the offset)
        np.testing.assert_array_less(0.0, prop[2, 2, 3, :, 3])
        np.testing.assert_array_less(prop[2, 2, 1, :, 3], 0.0)

    def test_outside_grid_contributes_nothing(self):
        prop, _ = propagate(point_source(at=(0, 0, 0)), 0.0, 0.0, 0.0, DX, steps=1, skip=0)
        np.testing.assert_allclose(prop[..., 0].sum(axis=(0, 1, 2)), 3 / 6, rtol=1e-12)

    def test_accumulation_skips_first_steps(self):
        rng = np.random.default_rng(0)
        c0 = rng.random((N, N, N, 3, 4))
        sig = rng.random((N, N, N, 3))
        sp = rng.random((N, N, N, 3))
        g = rng.random((N, N, N, 3)) - 0.5
        props = [propagate(c0, sig, sp, g, DX, steps=k, skip=0)[0] for k in range(1, 6)]
        for skip in (0, 2, 4):
            prop, accum = propagate(c0, sig, sp, g, DX, steps=5, skip=skip)
            np.testing.assert_allclose(prop, props[-1], rtol=1e-13)
            np.testing.assert_allclose(accum, sum(props[skip:]), rtol=1e-13)

    def test_accumulation_empty_when_skip_covers_all(self):
        _, accum = propagate(point_source(), 0.0, 0.0, 0.0, DX, steps=2, skip=2)
        assert np.all(accum == 0)

    @pytest.mark.parametrize("steps", [1, 3])
    def test_absorption_only_scales_by_beer(self, steps):
        sigma = np.array([0.3, 1.0, 2.5])
        c0 = point_source((0.8, 0.1, -0.2, 0.3))
        vac, _ = propagate(c0, 0.0, 0.0, 0.0, DX, steps=steps, skip=0)
        absorbed, _ = propagate(c0, np.broadcast_to(sigma, (N, N, N, 3)), 0.0, 0.0, DX,
                                steps=steps, skip=0)
        expected = vac * np.exp(-sigma * DX * steps)[:, None]
        np.testing.assert_allclose(absorbed, expected, rtol=1e-12, atol=1e-15)

    def test_scattering_uses_source_cell(self):
        # Eq. 3 on the source: g = 0, sp = 1 removes band 1 before the transfer
        c0 = point_source((0.0, 0.0, 0.0, 1.0))
        sp = np.zeros((N, N, N, 3))
        sp[2, 2, 2] = 1.0
        prop, _ = propagate(c0, 0.0, sp, 0.0, DX, steps=1, skip=0)
        assert np.all(prop == 0)
        sp_dest_only = np.ones((N, N, N, 3))
        sp_dest_only[2, 2, 2] = 0.0
        prop, _ = propagate(c0, 0.0, sp_dest_only, 0.0, DX, steps=1, skip=0)
        assert np.abs(prop).sum() > 0

    def test_half_path_absorption_mean_of_cells(self):
        sig = np.zeros((N, N, N, 3))
        sig[2, 2, 3] = 2.0   # destination at +x only
        prop, _ = propagate(point_source(), sig, 0.0, 0.0, DX, steps=1, skip=0)
        np.testing.assert_allclose(prop[2, 2, 3, :, 0], np.exp(-0.5 * 2.0 * DX) / 6, rtol=1e-12)
        np.testing.assert_allclose(prop[2, 2, 1, :, 0], 1 / 6, rtol=1e-12)


class TestInject:
    def test_single_texel_index_matched(self):
        light = np.array([1.2, 4.0, 1.0])
        x_p = np.array([1.3, 2.4, 1.1])          # cell (2, 4, 2)
        n_p = np.array([0.0, 1.0, 0.0])
        phi = np.array([2.0, 1.0, 0.5])
        texels = np.array([np.r_[x_p, n_p, phi, 1.0], np.r_[x_p, n_p, 9, 9, 9, 0.0]])
        grid = inject(texels, light, BMIN, BMAX, N, eta=1.0)
        w_i = (x_p - light) / np.linalg.norm(x_p - light)
        expected = phi[:, None] / np.pi * clamped_cosine_coeffs(w_i)[None, :]
        np.testing.assert_allclose(grid[2, 4, 2], expected, rtol=1e-13)
        grid[2, 4, 2] = 0
        assert np.all(grid == 0)

    def test_dielectric_refracts_and_transmits(self):
        light = np.array([0.0, 1.25, 3.0])
        x_p = np.array([1.25, 1.25, 2.4])
        n_p = np.array([0.0, 0.0, 1.0])
        grid = inject(np.r_[x_p, n_p, 1.0, 1.0, 1.0, 1.0][None], light, BMIN, BMAX, N, eta=1.5)
        c = grid[4, 2, 2, 0]
        w_i = (x_p - light) / np.linalg.norm(x_p - light)
        sin_t = np.linalg.norm(np.cross(w_i, n_p)) / 1.5
        # band 1 / c00 gives the lobe direction: (c11, c1-1, c10) / sqrt(pi/3) * sqrt(pi)/2
        d = np.array([c[3], c[1], c[2]]) / c[0] * (np.sqrt(np.pi) / 2) / np.sqrt(np.pi / 3)
        np.testing.assert_allclose(np.linalg.norm(d), 1.0, rtol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(np.cross(d, n_p)), sin_t, rtol=1e-12)
        # flux of Eq. 1's lobe is T Phi; T from the textbook s/p amplitudes
        cos_i = -w_i @ n_p
        cos_t = np.sqrt(1 - sin_t**2)
        r_s = ((cos_i - 1.5 * cos_t) / (cos_i + 1.5 * cos_t)) ** 2
        r_p = ((cos_t - 1.5 * cos_i) / (cos_t + 1.5 * cos_i)) ** 2
        np.testing.assert_allclose(c[0] * SQRT_4PI, 1 - 0.5 * (r_s + r_p), rtol=1e-12)

    def test_offset_moves_into_the_next_cell(self):
        light = np.array([1.25, 1.25, 5.0])
        tex = np.r_[1.25, 1.25, 2.1, 0, 0, 1, 1, 1, 1, 1][None]
        assert inject(tex, light, BMIN, BMAX, N)[4, 2, 2, 0, 0] > 0
        assert inject(tex, light, BMIN, BMAX, N, offset=0.2)[3, 2, 2, 0, 0] > 0


class TestShade:
    def test_isotropic_cell_radiance(self):
        # Eq. 5: an isotropic point light c00 gives L = (2/A) c00 / sqrt(4 pi)
        accum = point_source((3.0, 0, 0, 0))
        p = np.array([[1.2, 1.3, 1.1]])
        L = shade_points(accum, BMIN, BMAX, p, np.array([[0.0, 0.6, 0.8]]))
        np.testing.assert_allclose(L, 2 / DX**2 * 3.0 / SQRT_4PI, rtol=1e-13)

    def test_trilinear_at_centre_equals_cell(self):
        rng = np.random.default_rng(5)
        accum = rng.random((N, N, N, 3, 4))
        centres = np.array([[0.75, 1.25, 1.75], [0.25, 0.25, 2.25]])
        nrm = np.array([[0.0, 0, 1], [1.0, 0, 0]])
        np.testing.assert_allclose(shade_points(accum, BMIN, BMAX, centres, nrm, "trilinear"),
                                   shade_points(accum, BMIN, BMAX, centres, nrm, "cell"),
                                   rtol=1e-13)

    def test_trilinear_is_linear_and_clamped(self):
        grid = np.zeros((N, N, N, 1))
        grid[..., 0] = np.arange(N)[None, None, :] * 1.0   # value = x index
        pts = np.array([[0.5, 1.0, 1.0], [0.1, 1.0, 1.0], [2.45, 1.0, 1.0]])
        np.testing.assert_allclose(sample_trilinear(grid, pts, BMIN, BMAX)[:, 0], [0.5, 0.0, 4.0],
                                   atol=1e-14)

    def test_fresnel_factor(self):
        accum = point_source((1.0, 0, 0, 0))
        p = np.array([[1.2, 1.3, 1.1]])
        n = np.array([[0.0, 0.0, 1.0]])
        L1 = shade_points(accum, BMIN, BMAX, p, n)
        L15 = shade_points(accum, BMIN, BMAX, p, n, eta=1.5, view_dirs=n)
        np.testing.assert_allclose(L15 / L1, 0.96, rtol=1e-13)
        with pytest.raises(ValueError):
            shade_points(accum, BMIN, BMAX, p, n, eta=1.5)
