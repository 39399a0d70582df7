"""Tests for sslpv_gl.material: mappings (Sec. 3.2), resampling, lpv_material."""

from types import SimpleNamespace

import numpy as np
import pytest

from harness.errors import InputError
from sslpv_gl.material import MAPPINGS, lpv_material, map_material, resample, resample_medium


def make_medium(sigma_t, albedo, g, extent=2.0):
    return SimpleNamespace(
        bbox_min=np.zeros(3), bbox_max=np.full(3, extent),
        sigma_t=np.asarray(sigma_t, np.float32), albedo=np.asarray(albedo, np.float32),
        g=np.asarray(g, np.float32),
    )


class TestMappings:
    def test_registry(self):
        assert set(MAPPINGS) == {"literal", "collision", "diffusion", "transport"}

    def test_literal_is_identity(self):
        st, a = np.array([0.0, 1.5, 40.0]), np.array([0.9, 0.2, 1.0])
        s_lpv, sp = map_material(st, a, 0.3, "literal")
        np.testing.assert_array_equal(s_lpv, st)
        np.testing.assert_array_equal(sp, a)

    @pytest.mark.parametrize("albedo", [0.0, 0.3, 0.99])
    def test_collision_small_cell_limit(self, albedo):
        st = np.array([0.5, 2.0, 10.0])
        dx = 1e-6
        s_lpv, sp = map_material(st, np.full(3, albedo), dx, "collision")
        np.testing.assert_allclose(s_lpv, st * (1 - albedo), rtol=1e-5)          # sigma_a
        np.testing.assert_allclose(sp / dx, st * albedo, rtol=1e-5, atol=1e-12)  # sigma_s

    def test_collision_conserves_collided_photons(self):
        # kept fraction = unscattered + scattered: exp(-s dx) = exp(-st dx) + P a
        st, a, dx = np.array([3.0]), np.array([0.7]), 0.4
        s_lpv, sp = map_material(st, a, dx, "collision")
        p = 1 - np.exp(-st * dx)
        np.testing.assert_allclose(np.exp(-s_lpv * dx), np.exp(-st * dx) + p * a, rtol=1e-14)
        np.testing.assert_allclose(sp * np.exp(-s_lpv * dx), p * a, rtol=1e-14)

    def test_collision_vacuum_and_white(self):
        s_lpv, sp = map_material(np.array([0.0, 5.0]), np.array([0.5, 1.0]), 0.2, "collision")
        np.testing.assert_array_equal(s_lpv, [0.0, 0.0])
        np.testing.assert_allclose(sp, [0.0, 1 - np.exp(-1.0)], rtol=1e-14)

    def test_unknown_mapping_raises_input_error(self):
        with pytest.raises(InputError, match="unknown mapping 'bogus'") as info:
            map_material(np.ones(2), np.ones(2), 0.1, "bogus")
        assert "literal, collision, diffusion" in str(info.value)
        assert isinstance(info.value, ValueError)
        assert "\n" not in str(info.value)


class TestResample:
    @pytest.mark.parametrize("method", ["box", "point"])
    @pytest.mark.parametrize("n_src, n_dst", [(8, 4), (7, 3), (5, 8)])
    def test_constant_field_is_exact(self, method, n_src, n_dst):
        grid = np.full((n_src, n_src, n_src, 3), [0.5, 2.0, 7.25])
        out = resample(grid, n_dst, method)
        assert out.shape == (n_dst, n_dst, n_dst, 3)
        np.testing.assert_allclose(out, np.broadcast_to([0.5, 2.0, 7.25], out.shape), rtol=1e-14)

    @pytest.mark.parametrize("shape, n_dst", [((8, 8, 8), 4), ((7, 9, 5), 3), ((6, 6, 6), 4)])
    def test_box_conserves_mean(self, shape, n_dst):
        rng = np.random.default_rng(1)
        grid = rng.random(shape + (3,))
        out = resample(grid, n_dst, "box")
        np.testing.assert_allclose(out.mean(axis=(0, 1, 2)), grid.mean(axis=(0, 1, 2)),
                                   rtol=1e-13)

    def test_box_divisible_is_block_mean(self):
        rng = np.random.default_rng(2)
        grid = rng.random((8, 8, 8, 1))
        block = grid.reshape(4, 2, 4, 2, 4, 2, 1).mean(axis=(1, 3, 5))
        np.testing.assert_allclose(resample(grid, 4, "box"), block, rtol=1e-13)

    def test_point_same_resolution_is_identity(self):
        rng = np.random.default_rng(3)
        grid = rng.random((6, 6, 6, 3))
        np.testing.assert_allclose(resample(grid, 6, "point"), grid, rtol=1e-14)

    def test_point_is_trilinear_between_centres(self):
        # 2 -> 4 along x: LPV centres at source index -0.25 (clamped to 0), 0.25, 0.75, 1.25
        grid = np.zeros((2, 2, 2, 1))
        grid[:, :, 1] = 1.0
        out = resample(grid, 4, "point")[0, 0, :, 0]
        np.testing.assert_allclose(out, [0.0, 0.25, 0.75, 1.0], atol=1e-15)

    def test_unknown_method(self):
        with pytest.raises(InputError, match="unknown resample 'cubic'"):
            resample(np.zeros((2, 2, 2, 3)), 2, "cubic")


class TestResampleMedium:
    def test_weighted_albedo_and_g(self):
        # two voxels along x merged into one LPV cell: a dense scatterer and a
        # thin absorber; albedo and g follow the dense one
        st = np.zeros((1, 1, 2, 3)); st[..., 0, :], st[..., 1, :] = 9.0, 1.0
        a = np.zeros_like(st); a[..., 0, :], a[..., 1, :] = 0.8, 0.0
        g = np.zeros_like(st); g[..., 0, :], g[..., 1, :] = 0.5, -0.9
        # make it a 1-cell LPV from a (1, 1, 2) grid
        s, alb, gg = resample_medium(make_medium(st, a, g), 1, "box")
        np.testing.assert_allclose(s, 5.0, rtol=1e-7)
        np.testing.assert_allclose(alb, 9 * 0.8 / 10, rtol=1e-6)
        np.testing.assert_allclose(gg, 0.5, rtol=1e-6)

    def test_zero_density_falls_back_to_plain_mean(self):
        st = np.zeros((2, 2, 2, 3))
        a = np.full_like(st, 0.25)
        s, alb, gg = resample_medium(make_medium(st, a, np.full_like(st, 0.1)), 1, "box")
        np.testing.assert_allclose(alb, 0.25, rtol=1e-6)
        np.testing.assert_allclose(gg, 0.1, rtol=1e-6)


class TestLpvMaterial:
    def test_vacuum_outside_and_dtypes(self):
        st = np.full((4, 4, 4, 3), 3.0)
        med = make_medium(st, np.full_like(st, 0.9), np.full_like(st, 0.2))
        mask = np.zeros((4, 4, 4), bool)
        mask[1:3, 1:3, 1:3] = True
        out = lpv_material(med, mask, 4)
        for key in ("sigma_lpv", "sigma_s_prime", "g"):
            assert out[key].dtype == np.float32 and out[key].shape == (4, 4, 4, 3)
        assert np.all(out["sigma_lpv"][~mask] == 0) and np.all(out["sigma_s_prime"][~mask] == 0)
        s_ref, sp_ref = map_material(3.0, 0.9, 0.5, "collision")
        np.testing.assert_allclose(out["sigma_lpv"][mask], s_ref, rtol=1e-6)
        np.testing.assert_allclose(out["sigma_s_prime"][mask], sp_ref, rtol=1e-6)

        kept = lpv_material(med, mask, 4, outside="material")
        np.testing.assert_allclose(kept["sigma_lpv"], s_ref, rtol=1e-6)

    def test_accepts_scene_and_rejects_bad_choices(self):
        st = np.ones((2, 2, 2, 3))
        med = make_medium(st, st * 0.5, st * 0)
        scene = SimpleNamespace(medium=med)
        np.testing.assert_array_equal(lpv_material(scene, None, 2)["sigma_lpv"],
                                      lpv_material(med, None, 2)["sigma_lpv"])
        with pytest.raises(InputError, match="unknown mapping 'x'"):
            lpv_material(med, None, 2, mapping="x")
        with pytest.raises(InputError, match="unknown outside"):
            lpv_material(med, None, 2, outside="air")

    def test_non_cubic_cells_rejected(self):
        st = np.ones((2, 2, 2, 3))
        med = make_medium(st, st, st * 0)
        med.bbox_max = np.array([2.0, 2.0, 3.0])
        with pytest.raises(InputError, match="not cubes"):
            lpv_material(med, None, 2)
