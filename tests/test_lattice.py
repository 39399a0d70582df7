"""The lattice constants of sslpv_gl.lattice by two routes (docs/diffusion_mapping.md, Eq. (1)-(13)).

The analytic route is the closed form of Eq. (9) from perturbation theory of
the 4x4 symbol; the numerical route propagates a point source with
``sslpv_gl.twin.propagate`` (the real code) and measures the variance growth.
Nothing is typed in: every expected value is computed here.
"""

import numpy as np
import pytest

from harness.errors import InputError
from sslpv_gl import diffusion, lattice, twin
from sslpv_gl.sh import SOURCE_OFFSETS, propagation_matrices


class TestConstants:
    def test_matrix_structure_is_what_eq3_assumes(self):
        # Eq. (3): M_{+x} has only the entries m00, u, v, w_par, w_perp, and
        # M_{-x} is M_{+x} with u, v negated; y and z are permutations
        M = propagation_matrices()
        c = lattice.constants()
        expect = np.array([[c.m00, 0, 0, c.u], [0, c.w_perp, 0, 0], [0, 0, c.w_perp, 0], [c.v, 0, 0, c.w_par]])
        np.testing.assert_allclose(M[0], expect, atol=1e-12)
        minus = expect.copy()
        minus[0, 3] *= -1
        minus[3, 0] *= -1
        np.testing.assert_allclose(M[1], minus, atol=1e-12)
        for s_plus, comp in ((2, 1), (4, 2)):                      # +y: c1-1, +z: c10 take c11's role
            P = np.eye(4)[[0, 1, 2, 3]]
            P[[comp, 3]] = P[[3, comp]]
            np.testing.assert_allclose(M[s_plus], P @ expect @ P.T, atol=1e-12)
        # sum_s M_s S at q = 0 is diag(a, b k1, b k1, b k1) (Eq. (4))
        k1 = 0.37
        S = np.diag([1, k1, k1, k1])
        np.testing.assert_allclose(sum(m @ S for m in M), np.diag([c.a, c.b * k1, c.b * k1, c.b * k1]),
                                   atol=1e-12)

    def test_flux_conserving_geometry(self):
        # Eq. (4): the five faces subtend exactly the shared face's 2 pi/3, so a = 1
        c = lattice.constants()
        assert abs(c.a - 1.0) < 1e-12
        assert abs(lattice.step_loss(0.0)) < 1e-12
        np.testing.assert_allclose(lattice.survival(0.2), np.exp(-0.2), rtol=1e-12)

    def test_symbol_at_zero(self):
        T = lattice.symbol(np.zeros(3), 0.6, 0.1)
        lam = np.max(np.abs(np.linalg.eigvals(T)))
        np.testing.assert_allclose(lam, lattice.survival(0.1), rtol=1e-12)

    def test_symbol_sign_convention_against_twin_step(self):
        # Eq. (2): one step of the twin == the symbol applied through the FFT,
        # for a field well inside the grid (the twin has zero boundaries)
        rng = np.random.default_rng(3)
        N, k1, sdx = 12, 0.45, 0.07
        c = np.zeros((N, N, N, 4))
        c[4:8, 3:9, 5:8] = rng.normal(size=(4, 6, 3, 4))
        grid = np.repeat(c[:, :, :, None, :], 3, axis=3)
        ones = np.ones((N, N, N, 3))
        p, _ = twin.propagate(grid, sdx * ones, ones, k1 * ones, 1.0, 1, skip=1)
        np.testing.assert_allclose(lattice.periodic_step(c, k1, sdx), p[..., 0, :], atol=1e-12)

    def test_wrong_sign_convention_would_fail(self):
        # power of the test above: the conjugate symbol (gather from d - o_s) differs
        rng = np.random.default_rng(4)
        N, k1 = 10, 0.45
        c = np.zeros((N, N, N, 4))
        c[4:6, 4:6, 4:6] = rng.normal(size=(2, 2, 2, 4))
        mats = propagation_matrices()[[1, 0, 3, 2, 5, 4]]          # offsets reversed
        wrong = lattice.periodic_step(c, k1, 0.0, matrices=mats)
        right = lattice.periodic_step(c, k1, 0.0)
        assert np.abs(wrong - right).max() > 0.1 * np.abs(right).max()


class TestAnalyticD:
    @pytest.mark.parametrize("k1", [-1.0, 0.0, 0.3, 1.0])
    def test_closed_form_is_the_eigenvalue_curvature(self, k1):
        # Eq. (8)-(9) against the q^2 curvature of the symbol's eigenvalue, along x and (1,1,1)
        d = float(lattice.d_lpv(k1))
        for direction in [(1, 0, 0), (1, 1, 1), (0, 1, 0), (1, 2, 0)]:
            assert lattice.d_lpv_direction(k1, direction, h=1e-3) == pytest.approx(d, rel=1e-5)

    def test_limits(self):
        c = lattice.constants()
        # k1 = 0: band 1 killed before every step, a plain walk with hop weight m00
        assert float(lattice.d_lpv(0.0)) == pytest.approx(c.m00 / c.a, rel=1e-14)
        k1 = np.linspace(-1, 1, 21)
        assert np.all(np.diff(lattice.d_lpv(k1)) > 0)             # monotone: Eq. (10) invertible
        np.testing.assert_allclose(lattice.k1_for_d_lpv(lattice.d_lpv(k1)), k1, atol=1e-12)

    def test_independent_of_sigma(self):
        for sdx in (0.0, 0.3):
            h = 1e-3
            lam0 = np.max(np.abs(np.linalg.eigvals(lattice.symbol(np.zeros(3), 0.8, sdx))))
            lam = np.max(np.abs(np.linalg.eigvals(lattice.symbol([h, 0, 0], 0.8, sdx))))
            assert (1 - lam / lam0) / h**2 == pytest.approx(float(lattice.d_lpv(0.8)), rel=1e-5)

    @pytest.mark.parametrize("k1", [-1.0, 0.0, 0.5, 1.0])
    def test_axis_decay_closed_form(self, k1):
        # Eq. (12): the 2x2 closed form equals the 4x4 eigenproblem at q = i kappa x
        for kappa in (0.0, 0.2, 0.7):
            T = lattice.symbol([1j * kappa, 0, 0], k1, 0.0).real
            assert float(lattice.decay_eigenvalue(kappa, k1)) == pytest.approx(
                np.max(np.linalg.eigvals(T).real), rel=1e-12)
        # and for small kappa Lambda = a (1 + D kappa^2 + ...)
        kap = 1e-3
        assert (float(lattice.decay_eigenvalue(kap, k1)) - 1) / kap**2 == pytest.approx(
            float(lattice.d_lpv(k1)), rel=1e-5)


class TestNumericalRoute:
    def test_spread_matches_closed_form(self):
        # the acceptance: analytic and numerical D_lpv within 1 %
        k1 = np.array([-1.0, 0.0, 0.5, 1.0, 0.2, 0.8])
        num = lattice.measure_spread(k1, N=40, steps=(12, 19))
        ana = lattice.d_lpv(k1)
        np.testing.assert_allclose(num["d_lpv"], ana, rtol=1e-2)
        # in fact far tighter: the slope removes the start-up, the transient is (b k1)^k
        np.testing.assert_allclose(num["d_lpv"], ana, rtol=1e-5)
        # isotropic: every axis and the body diagonal
        np.testing.assert_allclose(num["d_axes"], np.repeat(ana[:, None], 3, axis=1), rtol=1e-5)
        np.testing.assert_allclose(num["d_diag"], ana, rtol=1e-5)
        np.testing.assert_allclose(num["lambda0"], 1.0, atol=1e-12)

    def test_band1_source_and_absorption(self):
        k1 = np.array([0.0, 0.6, 1.0])
        sdx = 0.08
        num = lattice.measure_spread(k1, N=40, steps=(12, 19), sigma_dx=sdx, band1=True)
        np.testing.assert_allclose(num["d_lpv"], lattice.d_lpv(k1), rtol=1e-4)
        np.testing.assert_allclose(num["lambda0"], lattice.survival(sdx), rtol=1e-12)

    def test_a_wrong_formula_fails(self):
        # power: dropping the band-1 detour of Eq. (9) is off by far more than 1 % at k1 = 1
        c = lattice.constants()
        num = lattice.measure_spread([1.0], N=32, steps=(10, 15))
        assert abs(num["d_lpv"][0] / (c.m00 / c.a) - 1) > 0.2

    def test_steps_must_stay_inside(self):
        with pytest.raises(ValueError, match="N//2 - 1"):
            lattice.measure_spread([0.0], N=16, steps=(5, 9))


def test_source_offsets_are_what_symbol_assumes():
    # the gather convention of Eq. (1): M_s acts on the cell at d + o_s
    assert SOURCE_OFFSETS.tolist() == [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]


def test_bad_k1_is_input_error():
    with pytest.raises(InputError, match="k1"):
        diffusion.diffusion_mapping(1.0, 0.9, 0.0, 0.1, k1=1.5)


def test_main_runs(capsys, monkeypatch):
    monkeypatch.setattr(lattice, "measure_spread", _fake_spread)
    assert lattice.main(["--grid", "16", "--steps", "3", "6"]) == 0
    out = capsys.readouterr().out
    assert "analytic" in out and "numerical" in out and "rel diff" in out


def _fake_spread(k1_values, N=48, steps=(14, 23), sigma_dx=0.0, band1=False):
    k1 = np.atleast_1d(np.asarray(k1_values, dtype=float))
    d = lattice.d_lpv(k1)
    return {"k1": k1, "d_axes": np.repeat(d[:, None], 3, 1), "d_diag": d, "d_lpv": d,
            "lambda0": np.full(k1.shape, float(lattice.survival(sigma_dx))), "seconds": 0.0}
