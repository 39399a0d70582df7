"""Tests for sslpv_gl.steady: the one-step operator (Sec. 3.2, Eq. 3, Sec. 4), the
steady-state solve (S2) and steps = auto, each against the NumPy twin's propagation."""

import numpy as np
import pytest

from sslpv_gl import steady, transfer
from sslpv_gl.sh import SOURCE_OFFSETS, clamped_cosine_coeffs, propagation_matrices
from sslpv_gl.twin import propagate


def random_material(rng, N):
    sig = rng.random((N, N, N, 3))
    sp = rng.random((N, N, N, 3))
    g = rng.random((N, N, N, 3)) * 2 - 1
    return sig, sp, g


def sphere_scene(N, rng, loss=(0.01, 0.05), radius=0.85):
    """Heterogeneous material inside a sphere, vacuum (sigma 0, k1 1) outside, lobes near -x."""
    dx = 2.0 / N
    x = (np.arange(N) + 0.5) * dx - 1.0
    Z, Y, X = np.meshgrid(x, x, x, indexing="ij")
    inside = X**2 + Y**2 + Z**2 < radius**2
    sig = np.zeros((N, N, N, 3))
    sp = np.zeros((N, N, N, 3))
    g = np.zeros((N, N, N, 3))
    n_in = int(inside.sum())
    sig[inside] = rng.uniform(*loss, size=(n_in, 3)) / dx         # loss per step sigma*dx
    sp[inside] = rng.uniform(0.3, 1.0, size=(n_in, 3))
    g[inside] = rng.uniform(-0.5, 0.9, size=(n_in, 3))
    c0 = np.zeros((N, N, N, 3, 4))
    j = N // 2
    i0 = int(np.argmax(inside[j, j, :]))
    lobe = clamped_cosine_coeffs([1.0, 0.2, 0.0]) / np.pi
    for dj in (-1, 0, 1):
        for dk in (-1, 0, 1):
            c0[j + dk, j + dj, i0] += lobe * np.array([1.0, 0.7, 0.4])[:, None]
    return c0, sig, sp, g, dx


def max_err_vs_c00(a, ref):
    """max |a - ref| over all coefficients, relative to max |c00| of ref (per colour)."""
    scale = np.abs(ref[..., 0]).max(axis=(0, 1, 2))                  # (3,)
    return float((np.abs(a - ref).max(axis=(0, 1, 2, 4)) / scale).max())


class TestTransferOperator:
    def test_one_step_matches_twin(self):
        rng = np.random.default_rng(0)
        N = 6
        c0 = rng.standard_normal((N, N, N, 3, 4))
        sig, sp, g = random_material(rng, N)
        dx = (0.3, 0.2, 0.45)                       # per-axis widths, as the twin allows
        ops = steady.transfer_operator(sig, sp, g, dx)
        prop, _ = propagate(c0, sig, sp, g, dx, steps=1, skip=0)
        assert len(ops) == 3
        for col, P in enumerate(ops):
            assert P.shape == (4 * N**3, 4 * N**3)
            got = (P @ c0[..., col, :].reshape(-1)).reshape(N, N, N, 4)
            np.testing.assert_allclose(got, prop[..., col, :], rtol=0, atol=1e-12 * np.abs(prop).max())

    def test_entry_formula_and_ordering(self):
        # one source cell: P[4d + a, 4s + b] = M_s[a, b] exp(-0.5 (sig_s + sig_d) dx) (1 or k1_s)
        N = 4
        sig = np.full((N, N, N, 3), 0.5)
        sig[1, 2, 3] = 2.0                          # destination [z, y, x] = [1, 2, 3]
        sp = np.full((N, N, N, 3), 0.4)
        g = np.full((N, N, N, 3), 0.25)
        P = steady.transfer_operator(sig, sp, g, 0.1)[1]
        M = propagation_matrices()
        d = (1 * N + 2) * N + 3
        s = (1 * N + 2) * N + 2                     # source at -x of the destination
        k1 = 0.6 + 0.4 * 0.25
        block = P[4 * d:4 * d + 4, 4 * s:4 * s + 4].toarray()
        expect = M[1] * np.exp(-0.5 * (0.5 + 2.0) * 0.1) * np.array([1, k1, k1, k1])[None, :]
        np.testing.assert_allclose(block, expect, rtol=1e-14, atol=1e-15)   # M's 1e-20 quadrature noise is dropped

    def test_sparsity(self):
        N = 5
        P = steady.transfer_operator(np.zeros((N, N, N, 3)), 0.0, 0.0, 1.0)[0]
        per_row_block = np.diff(P.indptr).reshape(N, N, N, 4).sum(axis=-1)
        assert per_row_block[2, 2, 2] == 36          # 6 sources x 6 nonzeros of each M_s
        assert per_row_block[0, 0, 0] == 18          # three sources outside the grid
        assert P.has_sorted_indices

    def test_lattice_symbol_radius_at_most_one(self):
        # the module docstring's claim: on the infinite lattice, |eig| <= 1 for |k1| <= 1
        M = propagation_matrices()
        ks = np.linspace(0, np.pi, 7)
        for k1 in (-1.0, 0.0, 0.3, 1.0):
            S = np.diag([1.0, k1, k1, k1])
            worst = 0.0
            for kx in ks:
                for ky in ks:
                    for kz in ks:
                        ph = np.exp(1j * SOURCE_OFFSETS @ np.array([kx, ky, kz]))
                        A = np.einsum("s,sab->ab", ph, M @ S)
                        worst = max(worst, np.abs(np.linalg.eigvals(A)).max())
            assert worst <= 1 + 1e-12


class TestSteadyState:
    def test_heterogeneous_sphere_matches_iterated_twin(self):
        rng = np.random.default_rng(1)
        N = 16
        c0, sig, sp, g, dx = sphere_scene(N, rng)
        accum, info = steady.steady_state(c0, sig, sp, g, dx, skip=2)
        steps = 600
        prop, twin_accum = propagate(c0, sig, sp, g, dx, steps=steps, skip=2)
        # the twin's own tail after `steps` is far below the tolerance checked
        assert steady.remaining_fraction(prop, c0) < 1e-6
        err = max_err_vs_c00(accum, twin_accum)
        print(f"\nN=16 heterogeneous sphere: steady vs twin ({steps} steps) max err = {err:.2e} of max c00; "
              f"iterations {info['iterations']}, rho {np.round(info['rho'], 5).tolist()}")
        assert err < 1e-4
        assert all(r < 1e-7 for r in info["residual"])
        assert all(r < 1 for r in info["rho"])

    def test_the_solve_is_linear_in_the_source_down_to_the_underflow(self):
        """A source of tiny values (light absorbed to near the underflow in a strongly absorbing lattice)
        gives the scaled solution, not a failed solve: the residual's norms must not underflow."""
        rng = np.random.default_rng(1)
        c0, sig, sp, g, dx = sphere_scene(12, rng)
        a, _ = steady.steady_state(c0, sig, sp, g, dx)
        for f in (1e-300, 1e-170, 1e100):
            b, info = steady.steady_state(c0 * f, sig, sp, g, dx)
            assert np.abs(b / f - a).max() <= 1e-12 * np.abs(a).max()
            assert all(r < 1e-7 for r in info["residual"])

    @staticmethod
    def _homogeneous_against_twin(c0, sig, sp, g, dx=0.1, steps=500):
        """Max error of the direct steady solve against ``steps`` iterated twin steps, of max c00."""
        N = c0.shape[0]
        accum, _ = steady.steady_state(c0, np.broadcast_to(sig, (N, N, N, 3)), sp, g, dx)
        prop, twin_accum = propagate(c0, sig, sp, g, dx, steps=steps, skip=2)
        assert steady.remaining_fraction(prop, c0) < 1e-6
        return max_err_vs_c00(accum, twin_accum)

    def test_homogeneous_absorbing_matches_iterated_twin(self):
        N = 12
        c0 = np.zeros((N, N, N, 3, 4))
        c0[6, 6, 1] = clamped_cosine_coeffs([1.0, 0.0, 0.0])
        c0[5, 7, 1] = 0.5 * clamped_cosine_coeffs([1.0, 0.0, 0.3])
        # per unit length: loss 0.02..0.1 per step
        err = self._homogeneous_against_twin(c0, np.array([0.2, 0.5, 1.0]), 0.6, 0.3)
        print(f"\nN=12 homogeneous absorbing: steady vs twin (500 steps) max err = {err:.2e} of max c00")
        assert err < 1e-4

    def test_transport_band1_factor_above_one_matches_iterated_twin(self):
        """The ``transport`` mapping's lattice g = k1 > 1 (sigma_s' = 1): band 1 amplified, the series still
        converges (b k1 < 1, docs Eq. (4)) and the direct solve equals the iterated twin."""
        N = 12
        c0 = np.zeros((N, N, N, 3, 4))
        c0[6, 6, 1] = clamped_cosine_coeffs([1.0, 0.0, 0.0])
        err = self._homogeneous_against_twin(c0, np.array([0.5, 1.0, 2.0]), 1.0, 2.3)     # loss 0.05..0.2 per step
        print(f"\nN=12 homogeneous, k1 = 2.3: steady vs twin (500 steps) max err = {err:.2e} of max c00")
        assert err < 1e-4

    def test_skip_handled_exactly(self):
        rng = np.random.default_rng(2)
        N = 8
        c0 = rng.random((N, N, N, 3, 4))
        sig, sp, g = random_material(rng, N)
        a0, _ = steady.steady_state(c0, sig, sp, g, 0.5, skip=0, rtol=1e-12)
        a3, _ = steady.steady_state(c0, sig, sp, g, 0.5, skip=3, rtol=1e-12)
        _, first3 = propagate(c0, sig, sp, g, 0.5, steps=3, skip=0)
        np.testing.assert_allclose(a0 - a3, first3, atol=1e-9 * np.abs(a0).max())

    def test_gmres_and_bicgstab_agree(self):
        rng = np.random.default_rng(3)
        c0, sig, sp, g, dx = sphere_scene(12, rng)
        a, ia = steady.steady_state(c0, sig, sp, g, dx, method="bicgstab")
        b, ib = steady.steady_state(c0, sig, sp, g, dx, method="gmres")
        assert ia["method"] == "bicgstab" and ib["method"] == "gmres"
        assert max_err_vs_c00(a, b) < 1e-6

    def test_slightly_negative_sigma_still_converges(self):
        # a gain smaller than the leak through the grid boundary: rho < 1, the series exists
        N = 8
        c0 = np.zeros((N, N, N, 3, 4))
        c0[4, 4, 4] = clamped_cosine_coeffs([0.0, 0.0, 1.0])
        sig = np.full((N, N, N, 3), -0.02)          # dx = 1: gain exp(0.02) per step
        accum, info = steady.steady_state(c0, sig, 0.5, 0.0, 1.0)
        assert all(0.9 < r < 1 for r in info["rho"])
        _, twin_accum = propagate(c0, sig, 0.5, 0.0, 1.0, steps=3000, skip=2)
        assert max_err_vs_c00(accum, twin_accum) < 1e-6

    def test_divergent_series_raises(self):
        N = 8
        c0 = np.zeros((N, N, N, 3, 4))
        c0[4, 4, 4] = clamped_cosine_coeffs([0.0, 0.0, 1.0])
        sig = np.full((N, N, N, 3), -0.3)           # gain exp(0.3) per step beats the leak
        with pytest.raises(ValueError, match=r"spectral radius is 1\.\d+ >= 1") as exc:
            steady.steady_state(c0, sig, 0.5, 0.0, 1.0)
        assert "\n" not in str(exc.value)
        # the iterated twin indeed grows without bound
        p10, _ = propagate(c0, sig, 0.5, 0.0, 1.0, steps=10, skip=0)
        p40, _ = propagate(c0, sig, 0.5, 0.0, 1.0, steps=40, skip=0)
        assert steady.remaining_fraction(p40, c0) > 10 * steady.remaining_fraction(p10, c0)

    def test_solver_not_converging_raises(self):
        rng = np.random.default_rng(4)
        c0, sig, sp, g, dx = sphere_scene(10, rng)
        with pytest.raises(ValueError, match="did not converge"):
            steady.steady_state(c0, sig, sp, g, dx, rtol=1e-14, maxiter=2)

    def test_zero_colour_and_zero_input(self):
        rng = np.random.default_rng(5)
        c0, sig, sp, g, dx = sphere_scene(8, rng)
        c0[..., 1, :] = 0.0
        accum, info = steady.steady_state(c0, sig, sp, g, dx)
        assert np.all(accum[..., 1, :] == 0) and info["rho"][1] is None
        zero, _ = steady.steady_state(np.zeros_like(c0), sig, sp, g, dx)
        assert np.all(zero == 0)

    @pytest.mark.parametrize("kwargs, field", [
        ({"c0": np.zeros((4, 4, 4, 3))}, "c0"),
        ({"method": "cg"}, "method"),
        ({"rtol": 0.0}, "rtol"),
        ({"skip": -1}, "skip"),
        ({"dx": -1.0}, "dx"),
        ({"sigma_lpv": np.full((4, 4, 4, 3), np.nan)}, "sigma_lpv"),
    ])
    def test_bad_input_one_line(self, kwargs, field):
        args = {"c0": np.ones((4, 4, 4, 3, 4)), "sigma_lpv": np.zeros((4, 4, 4, 3)), "sigma_s_prime": 0.5,
                "g": 0.0, "dx": 1.0}
        args.update(kwargs)
        with pytest.raises(ValueError, match=field) as exc:
            steady.steady_state(**args)
        assert "\n" not in str(exc.value)


class TestSpectralRadius:
    def test_dense_path_matches_full_eigenvalues(self):
        rng = np.random.default_rng(6)
        c0, sig, sp, g, dx = sphere_scene(6, rng)
        P = steady.transfer_operator(sig, sp, g, dx)[2]
        full = np.abs(np.linalg.eigvals(P.toarray())).max()     # no red/black folding at all
        assert abs(steady.spectral_radius(P) - full) < 1e-10

    def test_arpack_matches_dense(self, monkeypatch):
        rng = np.random.default_rng(6)
        c0, sig, sp, g, dx = sphere_scene(8, rng)
        P = steady.transfer_operator(sig, sp, g, dx)[2]
        monkeypatch.setattr(transfer, "_DENSE_EIG_MAX", 10**6)
        dense = steady.spectral_radius(P)
        monkeypatch.setattr(transfer, "_DENSE_EIG_MAX", 0)
        arpack = steady.spectral_radius(P)
        assert abs(arpack - dense) < 1e-5


class TestPropagateUntil:
    def test_stops_at_first_step_below_tol(self):
        rng = np.random.default_rng(7)
        c0, sig, sp, g, dx = sphere_scene(10, rng, loss=(0.02, 0.06))
        tol = 1e-2
        accum, K, rem = steady.propagate_until(c0, sig, sp, g, dx, tol=tol, skip=2)
        assert 2 < K < 4096 and rem < tol
        prev, _ = propagate(c0, sig, sp, g, dx, steps=K - 1, skip=2)
        last, twin_accum = propagate(c0, sig, sp, g, dx, steps=K, skip=2)
        assert steady.remaining_fraction(prev, c0) >= tol
        assert steady.remaining_fraction(last, c0) == pytest.approx(rem, rel=1e-10)
        np.testing.assert_allclose(accum, twin_accum, rtol=0, atol=1e-12 * np.abs(twin_accum).max())

    def test_cap(self):
        rng = np.random.default_rng(8)
        c0, sig, sp, g, dx = sphere_scene(8, rng)
        accum, K, rem = steady.propagate_until(c0, sig, sp, g, dx, tol=1e-9, max_steps=5, skip=2)
        _, twin_accum = propagate(c0, sig, sp, g, dx, steps=5, skip=2)
        assert K == 5 and rem > 1e-9
        np.testing.assert_allclose(accum, twin_accum, rtol=0, atol=1e-12 * np.abs(twin_accum).max())

    def test_converges_to_steady_state(self):
        rng = np.random.default_rng(9)
        c0, sig, sp, g, dx = sphere_scene(10, rng)
        accum, K, rem = steady.propagate_until(c0, sig, sp, g, dx, tol=1e-7)
        ref, _ = steady.steady_state(c0, sig, sp, g, dx)
        assert max_err_vs_c00(accum, ref) < 1e-5

    def test_measure_is_abs_c00_fraction(self):
        c0 = np.zeros((2, 2, 2, 3, 4))
        c0[0, 0, 0, :, 0] = [2.0, 1.0, 0.0]
        c = np.zeros_like(c0)
        c[0, 0, 1, :, 0] = [0.5, -0.3, 0.0]
        c[1, 0, 1, :, 0] = [-0.5, 0.0, 0.0]
        assert steady.remaining_fraction(c, c0) == pytest.approx(0.5)   # colour 0: 1.0 / 2.0


def test_sink_cells_match_the_twin():
    """Sink cells (outside = absorb, sslpv_gl.boundary): steady state against the twin iterated to convergence."""
    from sslpv_gl import boundary, twin
    from sslpv_gl.steady import steady_state

    N, dx = 10, 0.1
    rng = np.random.default_rng(3)
    c = (np.arange(N) + 0.5) / N - 0.5
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    inside = x**2 + y**2 + z**2 < 0.4**2
    _, emit = boundary.outside_masks(inside, "absorb")
    sig = rng.uniform(0.0, 0.3, (N, N, N, 3))
    sp = rng.uniform(0.0, 1.0, (N, N, N, 3))
    g = rng.uniform(-0.5, 0.8, (N, N, N, 3))
    c0 = np.zeros((N, N, N, 3, 4))
    c0[inside, :, 0] = rng.uniform(0.5, 1.0, (int(inside.sum()), 3))
    acc, info = steady_state(c0, sig, sp, g, dx, skip=1, emit=emit)
    _, ref = twin.propagate(c0, sig, sp, g, dx, 1500, skip=1, emit=emit)
    err = np.abs(acc - ref).max() / np.abs(ref[..., 0]).max()
    assert err < 1e-4, err
    # power: the same solve without the sinks is a different grid
    acc_vac, _ = steady_state(c0, sig, sp, g, dx, skip=1)
    assert np.abs(acc_vac - ref).max() > 1e-2 * np.abs(ref[..., 0]).max()


def test_power_radius_fallback():
    """The power-iteration fallback (used when ARPACK closes on an invariant subspace) finds a known radius."""
    from sslpv_gl.transfer import _power_radius

    d = np.linspace(0.1, 0.81, 50)                 # Q = diag(d): rho(P) = sqrt(rho(Q)) = 0.9
    assert _power_radius(lambda v: d * v, np.ones(50)) == pytest.approx(0.9, rel=1e-6)
    assert _power_radius(lambda v: 0.0 * v, np.ones(50)) == 0.0
