"""Tests for sslpv_gl.stencil: the matrix-free step ``P`` (Sec. 3.2, Eq. 3, Sec. 4) against the sparse matrices
of sslpv_gl.transfer and the NumPy twin, its red/black reduced product, and ``steady_state(operator=...)``.

* the product, per colour, equals the sparse matrix's to 1e-12 of its largest entry on random material with
  non-cubic cells, with and without sinks (``emit``), empty cells (``empty``) and the surface reflection
  (``r_dr``, ``inside``), at odd and even N (the sub-lattices differ in size when N is odd);
* the reduced product ``(P_bb + P_br E P_rb) y`` likewise against :class:`sslpv_gl.transfer._Split`;
* a few steps against :func:`sslpv_gl.twin.propagate` (an independent coding of the same rule, the first step
  without sinks as there);
* the spectral radius, matrix-free, against the sparse route; the steady state with both operators on a
  small sphere; ``operator = "auto"`` and the GL renderer's ``steps = steady`` pick the stencil from
  ``STENCIL_MIN_N`` on; a bad ``operator`` is one line.
"""

import numpy as np
import pytest

from sslpv_gl import steady, stencil, transfer, twin
from sslpv_gl.sh import clamped_cosine_coeffs

DX = (0.3, 0.2, 0.45)                    # per-axis widths (x, y, z)


def _material(N, seed):
    rng = np.random.default_rng(seed)
    sig = rng.uniform(0.0, 2.0, (N, N, N, 3))
    sp = rng.uniform(0.0, 1.0, (N, N, N, 3))
    g = rng.uniform(-0.9, 0.9, (N, N, N, 3))
    c = (np.arange(N) + 0.5) / N - 0.5
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    inside = x**2 + 1.3 * y**2 + 0.8 * z**2 < 0.4**2
    options = {
        "plain": {},
        "emit": {"emit": (rng.random((N, N, N, 3)) < 0.7).astype(np.float64)},
        "empty": {"empty": np.repeat((~inside)[..., None], 3, axis=-1).astype(np.float64)},
        "rdr": {"r_dr": 0.55, "inside": inside},
        "all": {"emit": np.repeat(inside[..., None], 3, axis=-1).astype(np.float64) * rng.uniform(0.5, 1, (N, N, N, 3)),
                "empty": rng.random((N, N, N, 3)), "r_dr": 0.3, "inside": inside},
    }
    return sig, sp, g, options


def _rel(a, b):
    return float(np.abs(a - b).max() / np.abs(b).max())


@pytest.mark.parametrize("N", [6, 7, 12])
@pytest.mark.parametrize("option", ["plain", "emit", "empty", "rdr", "all"])
def test_product_equals_sparse(N, option):
    sig, sp, g, options = _material(N, N)
    kw = options[option]
    ops = transfer.transfer_operator(sig, sp, g, DX, **kw)
    rng = np.random.default_rng(100 + N)
    for col in range(3):
        op = stencil.stencil_operator(sig, sp, g, DX, col, **kw)
        c = rng.standard_normal((N, N, N, 4))
        ref = (ops[col] @ c.reshape(-1)).reshape(N, N, N, 4)
        assert _rel(op.matvec(c), ref) <= 1e-12
        assert op.has_diag == (option in ("rdr", "all"))


@pytest.mark.parametrize("N", [7, 10])
@pytest.mark.parametrize("option", ["plain", "rdr", "all"])
def test_reduced_product_equals_split(N, option):
    sig, sp, g, options = _material(N, 20 + N)
    kw = options[option]
    P = transfer.transfer_operator(sig, sp, g, DX, **kw)[1]
    red, black = transfer._red_black(N)
    split = transfer._Split(P, red, black)
    op = stencil.stencil_operator(sig, sp, g, DX, 1, **kw)
    assert split.diag == op.has_diag
    rng = np.random.default_rng(N)
    full = np.zeros(4 * N**3)
    full[black] = rng.standard_normal(black.size)        # y on the black cells, in the sparse ordering
    y = op.to_parity(full)[op.n_red:]
    got = np.zeros(4 * N**3)
    got[op.n_red:] = op.reduced(y)
    got = op.from_parity(got).reshape(-1)
    ref = split.reduced(full[black])
    assert _rel(got[black], ref) <= 1e-12
    assert not np.any(got[red])
    # the right-hand side and the red cells' recovery of the solve
    b = rng.standard_normal(4 * N**3)
    rhs_ref = b[black] + split.P_br @ split.apply_e(b[red])
    bp = op.to_parity(b)
    assert _rel(op.from_parity(np.concatenate([np.zeros(op.n_red), op.rhs(bp)])).reshape(-1)[black], rhs_ref) <= 1e-12
    x = op.from_parity(op.expand(bp, y)).reshape(-1)
    assert _rel(x[red], split.apply_e(b[red] + split.P_rb @ full[black])) <= 1e-12


@pytest.mark.parametrize("option", ["plain", "emit", "empty", "rdr", "all"])
def test_steps_equal_twin(option):
    N, steps = 9, 4
    sig, sp, g, options = _material(N, 5)
    kw = options[option]
    c0 = np.random.default_rng(6).standard_normal((N, N, N, 3, 4))
    prop, _ = twin.propagate(c0, sig, sp, g, DX, steps, skip=0, **kw)
    for col in range(3):
        op = stencil.stencil_operator(sig, sp, g, DX, col, **kw)
        v = op.to_parity(c0[..., col, :])
        for k in range(steps):
            v = op.apply(v, first_step=k == 0)           # step 1: every cell emits, as in the twin
        assert _rel(op.from_parity(v), prop[..., col, :]) <= 1e-12


@pytest.mark.parametrize("N, option", [(5, "plain"), (4, "rdr"), (9, "plain"), (9, "rdr")])
def test_spectral_radius_matrix_free(N, option):
    """Dense (N = 4, 5) and ARPACK (N = 9) routes, on the reduced operator and, with reflection, on P itself."""
    sig, sp, g, options = _material(N, 40)
    sig *= 0.05
    P = transfer.transfer_operator(sig, sp, g, DX, **options[option])[0]
    op = stencil.stencil_operator(sig, sp, g, DX, 0, **options[option])
    ref = transfer.spectral_radius(P)
    assert 0.3 < ref < 1
    assert op.radius() == pytest.approx(ref, abs=1e-5)


def _sphere(N, seed=1):
    rng = np.random.default_rng(seed)
    dx = 2.0 / N
    x = (np.arange(N) + 0.5) * dx - 1.0
    Z, Y, X = np.meshgrid(x, x, x, indexing="ij")
    inside = X**2 + Y**2 + Z**2 < 0.85**2
    sig = np.zeros((N, N, N, 3))
    sp = np.zeros((N, N, N, 3))
    g = np.zeros((N, N, N, 3))
    n_in = int(inside.sum())
    sig[inside] = rng.uniform(0.01, 0.05, (n_in, 3)) / dx
    sp[inside] = rng.uniform(0.3, 1.0, (n_in, 3))
    g[inside] = rng.uniform(-0.5, 0.9, (n_in, 3))
    c0 = np.zeros((N, N, N, 3, 4))
    j = N // 2
    c0[j, j, int(np.argmax(inside[j, j, :]))] = (clamped_cosine_coeffs([1.0, 0.2, 0.0]) / np.pi)[None, :] * \
        np.array([1.0, 0.7, 0.4])[:, None]
    return c0, sig, sp, g, dx, inside


@pytest.mark.parametrize("kw", [{}, {"r_dr": 0.5}, {"emit": "outside"}, {"empty": "outside"}],
                         ids=["vacuum", "rdr", "sinks", "interior"])
def test_steady_state_operators_agree(kw):
    N, rtol = 12, 1e-8
    c0, sig, sp, g, dx, inside = _sphere(N)
    kw = dict(kw)
    out = np.repeat(inside[..., None], 3, axis=-1).astype(np.float64)
    if "r_dr" in kw:
        kw["inside"] = inside
    if "emit" in kw:
        kw["emit"] = out
    if "empty" in kw:
        kw["empty"] = 1.0 - out
    a, ia = steady.steady_state(c0, sig, sp, g, dx, rtol=rtol, operator="sparse", **kw)
    b, ib = steady.steady_state(c0, sig, sp, g, dx, rtol=rtol, operator="stencil", **kw)
    assert (ia["operator"], ib["operator"]) == ("sparse", "stencil")
    assert all(r <= 10 * rtol for r in ib["residual"])
    scale = np.abs(a[..., 0]).max(axis=(0, 1, 2))
    assert float((np.abs(a - b).max(axis=(0, 1, 2, 4)) / scale).max()) <= rtol
    assert ib["rho"] == pytest.approx(ia["rho"], abs=1e-5)


def test_auto_picks_the_stencil_from_stencil_min_n(monkeypatch):
    N = 8
    c0, sig, sp, g, dx, _ = _sphere(N)
    _, info = steady.steady_state(c0, sig, sp, g, dx)
    assert info["operator"] == "sparse"
    monkeypatch.setattr(steady, "STENCIL_MIN_N", N)
    acc, info = steady.steady_state(c0, sig, sp, g, dx)
    assert info["operator"] == "stencil"
    ref, _ = steady.steady_state(c0, sig, sp, g, dx, operator="sparse")
    assert np.abs(acc - ref).max() <= 1e-8 * np.abs(ref[..., 0]).max()


@pytest.mark.parametrize("value", ["dense", "", None, 3])
def test_bad_operator_one_line(value):
    with pytest.raises(ValueError, match=r"^sslpv_gl\.steady: operator: .*; use one of: auto, sparse, stencil$") as exc:
        steady.steady_state(np.ones((4, 4, 4, 3, 4)), np.zeros((4, 4, 4, 3)), 0.5, 0.0, 1.0, operator=value)
    assert "\n" not in str(exc.value)


@pytest.mark.gl
def test_renderer_steady_uses_the_auto_choice(gl_renderer, monkeypatch):
    """``steps = steady`` in the GL renderer: the stencil from ``STENCIL_MIN_N`` on, the sparse matrices below."""
    from harness.scene import load_scene
    from sslpv_gl.params import SSLPVParams

    used = []
    solve = steady.steady_state

    def spy(*args, **kwargs):
        acc, info = solve(*args, **kwargs)
        used.append(info["operator"])
        return acc, info

    monkeypatch.setattr(steady, "steady_state", spy)
    scene = load_scene("backlit_slab").with_resolution(16, 16)
    params = SSLPVParams(N=16, steps="steady", skip=0, rsm_size=64, inject_size=32)
    gl_renderer.render(scene, params)
    monkeypatch.setattr(steady, "STENCIL_MIN_N", params.N)
    gl_renderer.render(scene, params)
    assert used == ["sparse", "stencil"]
