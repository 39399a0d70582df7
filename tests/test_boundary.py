"""sslpv_gl.boundary: the diffuse Fresnel reflectance by two routes, the outside modes' masks,
and the twin's sink cells."""

import numpy as np
import pytest

from sslpv_gl import boundary, bounded, twin
from sslpv_gl.optics import fresnel_reflectance
from sslpv_gl.sh import clamped_cosine_coeffs

OFFSETS = bounded.partial_sink_offsets()


def external_route_fdr(eta, order=400):
    """Second route to Eq. (B1): F_dr from INSIDE via reciprocity, 1 - (1 - F_dr,outside) / eta^2.

    The outside diffuse reflectance has no total internal reflection (a smooth integrand), so plain
    Gauss-Legendre over [0, 1] suffices; energy conservation and reciprocity then give the inside one.
    """
    x, w = np.polynomial.legendre.leggauss(order)
    mu = 0.5 * (x + 1.0)
    f_out = np.sum(0.5 * w * 2.0 * mu * fresnel_reflectance(mu, eta))
    return 1.0 - (1.0 - f_out) / eta**2


class TestDiffuseFresnel:
    @pytest.mark.parametrize("eta", [1.01, 1.1, 1.33, 1.4, 1.5, 1.6, 2.0])
    def test_two_routes_agree(self, eta):
        got = float(boundary.diffuse_fresnel_reflectance(eta))
        assert got == pytest.approx(external_route_fdr(eta), abs=1e-5)

    @pytest.mark.parametrize("eta", [1.1, 1.2, 1.33, 1.5, 1.8])
    def test_egan_hilgeman_fit(self, eta):
        # the fit Jensen et al. 2001 quote is good to about 1e-3 in this range
        assert float(boundary.diffuse_fresnel_reflectance(eta)) == pytest.approx(
            float(boundary.egan_hilgeman_fdr(eta)), abs=2e-3)

    def test_index_matched_boundary_is_transparent(self):
        assert float(boundary.diffuse_fresnel_reflectance(1.0)) == 0.0
        assert float(boundary.a_of_eta(1.0)) == 1.0

    def test_vectorised_matches_scalar(self):
        etas = np.array([1.0, 1.3, 1.6])
        vec = boundary.diffuse_fresnel_reflectance(etas)
        np.testing.assert_allclose(vec, [float(boundary.diffuse_fresnel_reflectance(e)) for e in etas], rtol=1e-14)

    def test_extrapolation_distance(self):
        # z_b = 2 A D, D = 1 / (3 (sigma_a + sigma_s (1 - g))): sigma_t 8, albedo 0.99, g 0.5, eta 1.4
        st, a, g, eta = 8.0, 0.99, 0.5, 1.4
        D = 1.0 / (3.0 * (st * 0.01 + st * 0.99 * 0.5))
        A = (1 + external_route_fdr(eta)) / (1 - external_route_fdr(eta))
        assert float(boundary.extrapolation_distance(st, a, g, eta)) == pytest.approx(2 * A * D, rel=1e-5)


def sphere_mask(N=16, r=0.3):
    c = (np.arange(N) + 0.5) / N - 0.5
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    return x**2 + y**2 + z**2 < r**2


class TestMasks:
    def test_modes(self):
        inside = sphere_mask()
        ins = inside[..., None].repeat(3, -1)
        mat, emit = boundary.outside_masks(inside, "vacuum")
        assert np.array_equal(mat > 0, ins) and emit.all()
        mat, emit = boundary.outside_masks(inside, "material")
        assert mat.all() and emit.all()
        mat, emit = boundary.outside_masks(inside, "absorb")
        assert np.array_equal(mat > 0, ins) and np.array_equal(emit > 0, ins)

    def test_extrapolated_layer(self):
        inside = sphere_mask()
        thin, thin_emit = boundary.outside_masks(inside, "extrapolated", np.full(3, 0.2), OFFSETS)
        absorb, _ = boundary.outside_masks(inside, "absorb")
        assert np.array_equal(thin, absorb) and np.array_equal(thin_emit, absorb)   # z_b under 0.43 cells: no layer
        one, emit = boundary.outside_masks(inside, "extrapolated", np.full(3, 1.0), OFFSETS)
        two, _ = boundary.outside_masks(inside, "extrapolated", np.full(3, 2.0), OFFSETS)
        assert absorb.sum() < one.sum() < two.sum()
        # every added cell is an outside cell next to the surface: within z_b + 1/2 + o(0) cells of an inside centre
        from scipy.ndimage import distance_transform_edt
        dist = distance_transform_edt(~inside)
        added = (one[..., 0] > 0) & ~inside
        assert added.any() and dist[added].max() <= 1.5 + 0.075
        # the medium's cells pass on all they receive but the partial sinks (Eq. (B4)), which pass on a fraction
        partial = (emit > 0) & (emit < 1)
        assert partial.any() and np.all(one[partial] == 1) and np.all(emit[one == 0] == 0)
        assert np.all(emit[(one == 1) & ~partial] == 1)

    def test_whole_cells_without_the_lattices_offsets(self):
        """No Eq. (B4) table: every outside cell whose centre lies within z_b of the surface keeps the medium."""
        from scipy.ndimage import distance_transform_edt
        inside = sphere_mask()
        dist = distance_transform_edt(~inside)
        for zb in (0.2, 1.0, 2.0):
            keep, emit = boundary.outside_masks(inside, "extrapolated", np.full(3, zb))
            assert np.array_equal(keep, emit) and set(np.unique(emit)) <= {0.0, 1.0}
            np.testing.assert_array_equal(keep[..., 0] > 0, inside | (dist - 0.5 <= zb))

    @pytest.mark.parametrize("mapping, partial", [("diffusion", True), ("collision", False), ("literal", False)])
    def test_partial_sinks_are_the_diffusion_lattices(self, mapping, partial):
        """Eq. (B4)'s offsets are measured on the diffusion lattice: only that mapping gets partial sinks."""
        from types import SimpleNamespace

        from sslpv_gl.material import lpv_material
        N = 16
        med = SimpleNamespace(bbox_min=[0, 0, 0], bbox_max=[1, 1, 1],
                              sigma_t=np.full((4, 4, 4, 3), 3.0, np.float32),
                              albedo=np.full((4, 4, 4, 3), 0.95, np.float32), g=np.zeros((4, 4, 4, 3), np.float32))
        # z_b = 2 / (3 sigma_t') = 0.22: 3.6 cells
        emit = lpv_material(med, sphere_mask(N), N, mapping, outside="extrapolated")["emit"]
        assert bool(((emit > 0) & (emit < 1)).any()) is partial

    def test_partial_sink_places_the_zero(self):
        """Eq. (B4) on a laterally uniform slab: the lattice's zero lies ``z_b`` past the surface (Eq. (D4))."""
        f_tab, o_tab = OFFSETS
        for zb in (0.6, 1.07, 1.94, 2.5):
            inside = np.zeros((1, 1, 12), dtype=bool)
            inside[..., 8:] = True                   # surface at x = 7.5 (cells), outside towards x = 0
            _, emit = boundary.outside_masks(inside, "extrapolated", np.full(3, zb), OFFSETS)
            e = emit[0, 0, :, 0]
            p = int(np.flatnonzero((e > 0) & (e < 1))[0])
            # the partial cell's own zero, o(f), beyond its centre: at the surface plus z_b
            assert p - float(np.interp(e[p], f_tab, o_tab)) == pytest.approx(7.5 - zb, abs=1e-9)
            assert np.all(e[:p] == 0) and np.all(e[p + 1:] == 1)

    def test_per_colour(self):
        inside = sphere_mask()
        mat, _ = boundary.outside_masks(inside, "extrapolated", np.array([0.2, 1.0, 2.0]), OFFSETS)
        counts = mat.reshape(-1, 3).sum(0)
        assert counts[0] < counts[1] < counts[2]

    def test_unknown_mode(self):
        with pytest.raises(ValueError, match="unknown outside mode"):
            boundary.outside_masks(sphere_mask(), "leaky")


class TestTwinSinks:
    def _setup(self, N=12):
        inside = sphere_mask(N, 0.35)
        c0 = np.zeros((N, N, N, 3, 4))
        c0[N // 2, N // 2, N // 2, :, :] = clamped_cosine_coeffs(np.array([1.0, 0.0, 0.0]))
        zeros = np.zeros((N, N, N, 3))
        return inside, c0, zeros

    def test_sinks_pass_nothing_on_after_step_one(self):
        inside, _, zeros = self._setup()
        N = inside.shape[0]
        c = np.ones((N, N, N, 3, 4))
        sinks = np.zeros((N, N, N, 3))               # every cell a sink
        one, _ = twin.propagate(c, zeros, zeros, zeros, 1.0 / N, 1, skip=0, emit=sinks)
        two, _ = twin.propagate(c, zeros, zeros, zeros, 1.0 / N, 2, skip=0, emit=sinks)
        assert np.abs(one).max() > 0.1              # step 1: the injected light goes on from every cell
        assert np.abs(two).max() == 0.0             # step 2: sinks pass nothing on
        two_vac, _ = twin.propagate(c, zeros, zeros, zeros, 1.0 / N, 2, skip=0)   # power: vacuum does
        assert np.abs(two_vac).max() > 0.1

    def test_emit_one_is_bit_identical(self):
        inside, c0, zeros = self._setup()
        a = twin.propagate(c0, zeros + 0.5, zeros + 0.3, zeros + 0.2, 0.1, 6)
        b = twin.propagate(c0, zeros + 0.5, zeros + 0.3, zeros + 0.2, 0.1, 6, emit=np.ones_like(zeros))
        assert all(np.array_equal(x, y) for x, y in zip(a, b))

    def test_absorb_removes_light_outside(self):
        inside, c0, zeros = self._setup()
        N = inside.shape[0]
        _, emit = boundary.outside_masks(inside, "absorb")
        _, acc_v = twin.propagate(c0, zeros, zeros, zeros, 1.0 / N, 24, skip=0)
        _, acc_a = twin.propagate(c0, zeros, zeros, zeros, 1.0 / N, 24, skip=0, emit=emit)
        share = lambda acc: acc[~inside][..., 0].sum() / acc[..., 0].sum()   # noqa: E731
        # a sink holds what entered it for one step only, so far less light sits outside
        assert share(acc_a) < 0.5 * share(acc_v)
