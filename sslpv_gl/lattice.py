"""The SSLPV lattice's own transport constants: its Fourier symbol, diffusion coefficient and decay constants.

Equation numbers refer to ``docs/diffusion_mapping.md``, which derives
everything here. In a homogeneous, unbounded grid the propagation step of
Sec. 3.2 / Eq. 3 (transfer rule of ``docs/conventions.md``) is a
shift-invariant linear map on the four SH coefficients per cell. Its Fourier
symbol (Eq. (2)) gives

* the per-step survival ``lambda0 = a exp(-sigma_lpv dx)`` of the total flux
  and the loss ``mu = -ln lambda0`` (Eq. (5)-(6)); ``a`` = sum of the ``c00``
  rows of the six propagation matrices, which is exactly 1 (Eq. (4));
* the lattice diffusion coefficient ``D_lpv(k1)`` in cell^2 per step, from
  second-order perturbation theory of the symbol's leading eigenvalue
  (Eq. (9))::

      D_lpv(k1) = [ m00 + 4 u v k1 / (a - b k1) ] / a

* the exact decay constant of the steady-state lattice Green's function
  along an axis, from the leading eigenvalue of the symbol at imaginary wave
  number (Eq. (12)-(13)).

The numerical route (:func:`measure_spread`) measures the same ``D_lpv`` and
``lambda0`` from the variance growth of a point source propagated by
:func:`sslpv_gl.twin.propagate` itself. The ``diffusion`` mapping built on these
constants is :mod:`sslpv_gl.diffusion`.

Functions
---------

.. list-table::
   :header-rows: 1

   * - function
     - docs equation
     - meaning
   * - ``constants()``
     - (3)-(4)
     - the five matrix entries ``m00, u, v, w_par, w_perp`` and ``a, b``
   * - ``symbol(q, k1, sigma_dx)``
     - (2)
     - ``T(q)`` (4, 4) complex
   * - ``survival(sigma_dx)``, ``step_loss(sigma_dx)``
     - (5), (6)
     - ``lambda0``, ``mu``
   * - ``d_lpv(k1)``, ``k1_for_d_lpv(D)``
     - (9), (10)
     - closed form and its inverse
   * - ``decay_eigenvalue(kappa, k1, direction)``
     - (12)
     - leading eigenvalue of ``T(i kappa n)`` at ``sigma = 0``
   * - ``sigma_dx_for_kappa(kappa, k1)``
     - (13)
     - ``sigma_lpv dx`` that puts the Green's function's pole at ``kappa``
   * - ``measure_spread(k1_values, ...)``
     - (8)
     - numerical ``D_lpv`` and ``lambda0`` with the twin

``python -m sslpv_gl.lattice`` prints the table of ``D_lpv`` against ``k1``,
analytic against numerical.

Limits
------
* Homogeneous, unbounded lattice (:mod:`sslpv_gl.diffusion` applies its constants cell
  by cell in a heterogeneous medium: a local approximation).
* Cubic cells (the propagation matrices assume them).
"""

from __future__ import annotations

import dataclasses
import functools
import time

import numpy as np

from .sh import SOURCE_OFFSETS, propagation_matrices

__all__ = [
    "DIFFUSION_K1",
    "LatticeConstants",
    "constants",
    "symbol",
    "survival",
    "step_loss",
    "d_lpv",
    "k1_for_d_lpv",
    "decay_eigenvalue",
    "d_lpv_direction",
    "sigma_dx_for_kappa",
    "periodic_step",
    "periodic_steady_state",
    "measure_spread",
    "main",
]

#: Eq. 3 band-1 factor used by the ``diffusion`` mapping (docs Sec. 5,
#: "choice of k1"): ``k1 = -1`` (``sigma_s' = 1``, lattice ``g = -1``) makes
#: the lattice's steady-state Green's function the most isotropic of all
#: ``k1`` in ``[-1, 1]``.
DIFFUSION_K1 = -1.0


# ------------------------------------------------------------ the symbol

@dataclasses.dataclass(frozen=True)
class LatticeConstants:
    """Entries of the six propagation matrices that the lattice constants need (Eq. (3)-(4)).

    For the source at ``+x`` (``M = M_{+x}``, coefficient order
    ``(c00, c1-1, c10, c11)``, ``c11 ~ x``): ``m00 = M[0,0]``,
    ``u = M[0,3]`` (band 1 -> band 0), ``v = M[3,0]`` (band 0 -> band 1),
    ``w_par = M[3,3]`` (band-1 component along the step axis) and
    ``w_perp = M[1,1] = M[2,2]`` (across it). The other five matrices are
    their images under the cube's symmetries. ``a = 6 m00`` and
    ``b = 2 w_par + 4 w_perp`` are the band-0 and band-1 diagonal entries of
    ``sum_s M_s`` (Eq. (4)).
    """

    m00: float
    u: float
    v: float
    w_par: float
    w_perp: float

    @property
    def a(self):
        return 6.0 * self.m00

    @property
    def b(self):
        return 2.0 * self.w_par + 4.0 * self.w_perp


@functools.lru_cache(maxsize=4)
def _constants_cached(key):
    mats = propagation_matrices() if key is None else np.asarray(key, dtype=np.float64).reshape(6, 4, 4)
    m = mats[0]
    return LatticeConstants(m00=float(m[0, 0]), u=float(m[0, 3]), v=float(m[3, 0]),
                            w_par=float(m[3, 3]), w_perp=float(m[1, 1]))


def constants(matrices=None):
    """:class:`LatticeConstants` of ``matrices`` (default :func:`sslpv_gl.sh.propagation_matrices`)."""
    key = None if matrices is None else tuple(np.asarray(matrices, dtype=np.float64).ravel())
    return _constants_cached(key)


def _mats(matrices):
    return propagation_matrices() if matrices is None else np.asarray(matrices, dtype=np.float64)


def symbol(q, k1, sigma_dx=0.0, matrices=None):
    """Fourier symbol ``T(q)`` of one homogeneous propagation step (Eq. (2)) -> (4, 4) complex.

    ``T(q) = exp(-sigma dx) sum_s M_s S e^{i q . o_s}``, ``S = diag(1, k1, k1, k1)``,
    ``o_s`` the SOURCE offset (:data:`sslpv_gl.sh.SOURCE_OFFSETS`), ``q`` in
    radians per cell, (x, y, z). A grid ``c(x) = c_hat e^{i q.x}`` becomes
    ``(T(q) c_hat) e^{i q.x}`` after one step, because the destination ``d``
    gathers from ``d + o_s``. A complex ``q`` is allowed (``q = i kappa n``
    gives the real matrix of Eq. (12)).
    """
    mats = _mats(matrices)
    q = np.asarray(q, dtype=np.complex128).reshape(3)
    S = np.diag([1.0, k1, k1, k1])
    T = np.zeros((4, 4), dtype=np.complex128)
    for s, off in enumerate(SOURCE_OFFSETS):
        T += mats[s] @ S * np.exp(1j * np.dot(q, off))
    return np.exp(-float(sigma_dx)) * T


def survival(sigma_dx, matrices=None):
    """Per-step survival of the total flux, ``lambda0 = a exp(-sigma_lpv dx)`` (Eq. (5))."""
    return constants(matrices).a * np.exp(-np.asarray(sigma_dx, dtype=np.float64))


def step_loss(sigma_dx, matrices=None):
    """Per-step loss ``mu = -ln lambda0 = sigma_lpv dx - ln a`` (Eq. (6))."""
    return np.asarray(sigma_dx, dtype=np.float64) - np.log(constants(matrices).a)


def d_lpv(k1, matrices=None):
    """Lattice diffusion coefficient in cell^2 per step (Eq. (9)), vectorised in ``k1``.

    ``D_lpv = [m00 + 4 u v k1 / (a - b k1)] / a``: the first term is the
    direct band-0 hop (``<e0|T2|e0>``), the second the band-0 -> band-1 ->
    band-0 detour of second-order perturbation theory (``T1`` twice through
    the band-1 eigenvalue ``b k1``). Independent of ``sigma_lpv`` and of the
    direction of ``q`` (cubic symmetry, Eq. (9)).
    """
    c = constants(matrices)
    k1 = np.asarray(k1, dtype=np.float64)
    return (c.m00 + 4.0 * c.u * c.v * k1 / (c.a - c.b * k1)) / c.a


def k1_for_d_lpv(D, matrices=None):
    """Inverse of Eq. (9): the ``k1`` whose ``D_lpv`` is ``D`` (Eq. (10)); not clamped."""
    c = constants(matrices)
    t = c.a * np.asarray(D, dtype=np.float64) - c.m00
    return t * c.a / (4.0 * c.u * c.v + t * c.b)


def decay_eigenvalue(kappa, k1, direction=(1.0, 0.0, 0.0), matrices=None):
    """Leading eigenvalue ``Lambda(kappa)`` of ``T(i kappa n)`` at ``sigma = 0`` (Eq. (12)).

    Along an axis the ``(c00, c_parallel)`` block is 2x2 and the closed form
    of Eq. (12) is used (vectorised over ``kappa`` and ``k1``); another
    ``direction`` takes the largest real eigenvalue of the real 4x4 matrix.
    """
    c = constants(matrices)
    n = np.asarray(direction, dtype=np.float64)
    n = n / np.linalg.norm(n)
    kappa = np.asarray(kappa, dtype=np.float64)
    k1 = np.asarray(k1, dtype=np.float64)
    if np.count_nonzero(n) == 1:
        ch, sh = np.cosh(kappa), np.sinh(kappa)
        A00 = 2.0 * c.m00 * (ch + 2.0)
        A33 = k1 * (2.0 * c.w_par * ch + 4.0 * c.w_perp)
        prod = 4.0 * c.u * c.v * k1 * sh * sh           # A03 A30 = (-2 u k1 sh)(-2 v sh)
        half = 0.5 * (A00 - A33)
        return 0.5 * (A00 + A33) + np.sqrt(half * half + prod)
    kap_b, k1_b = np.broadcast_arrays(kappa, k1)
    out = np.empty(kap_b.shape)
    for idx in np.ndindex(kap_b.shape):
        T = symbol(1j * kap_b[idx] * n, float(k1_b[idx]), 0.0, matrices).real
        out[idx] = np.max(np.linalg.eigvals(T).real)
    return out


def d_lpv_direction(k1, direction, h=1e-3, matrices=None):
    """Cross-check of Eq. (8)-(9): ``-(ln lambda(h n) - ln lambda0) / h^2`` from the 4x4 eigenproblem.

    Not an independent route (it is the same symbol), but it shows the
    ``q^2`` term's isotropy: the value along x and along (1,1,1) agree to
    ``O(h^2)``; the cubic anisotropy starts at ``q^4``.
    """
    n = np.asarray(direction, dtype=np.float64)
    n = n / np.linalg.norm(n)
    lam = [np.max(np.abs(np.linalg.eigvals(symbol(t * n, k1, 0.0, matrices)))) for t in (0.0, h)]
    return -(np.log(lam[1]) - np.log(lam[0])) / (h * h)


def sigma_dx_for_kappa(kappa, k1, matrices=None):
    """``sigma_lpv dx = ln Lambda(kappa)`` (Eq. (13)): steady-state decay ``exp(-kappa r/dx)`` along the axes.

    The steady state ``sum_k T^k`` has its pole where
    ``exp(-sigma dx) Lambda(kappa) = 1``. Vectorised.
    """
    return np.log(decay_eigenvalue(kappa, k1, (1.0, 0.0, 0.0), matrices))


# ----------------------------------------------- lattice on a periodic grid

def _symbol_grid(N, k1, sigma_dx, matrices=None):
    """``T(q)`` of Eq. (2) at every FFT wave number of a periodic ``N^3`` grid -> (N,N,N,4,4)."""
    mats = _mats(matrices)
    q = 2.0 * np.pi * np.fft.fftfreq(int(N))
    qz, qy, qx = np.meshgrid(q, q, q, indexing="ij")  # [z, y, x] like the SH grids
    S = np.diag([1.0, k1, k1, k1])
    T = np.zeros((N, N, N, 4, 4), dtype=np.complex128)
    for s, off in enumerate(SOURCE_OFFSETS):
        phase = np.exp(1j * (qx * off[0] + qy * off[1] + qz * off[2]))
        T += phase[..., None, None] * (mats[s] @ S)
    return np.exp(-float(sigma_dx)) * T


def periodic_step(c, k1, sigma_dx, matrices=None):
    """One homogeneous step on a PERIODIC grid through the symbol (Eq. (2)); ``c`` (N,N,N,4) -> float64.

    Away from the grid's faces this equals one step of
    :func:`sslpv_gl.twin.propagate` (which has zero boundaries); the tests use
    it to check the symbol's sign convention.
    """
    c = np.asarray(c, dtype=np.float64)
    T = _symbol_grid(c.shape[0], k1, sigma_dx, matrices)
    ch = np.fft.fftn(c, axes=(0, 1, 2))
    return np.fft.ifftn(np.einsum("...ij,...j->...i", T, ch), axes=(0, 1, 2)).real


def periodic_steady_state(c, k1, sigma_dx, matrices=None):
    """``sum_{k>=1} T^k c = (I - T)^{-1} T c`` on a periodic homogeneous grid (Eq. (11)) -> float64.

    ``c`` (N,N,N,4). Exact for the periodic lattice (a 4x4 solve per wave
    number); needs ``lambda0 < 1`` (``sigma_dx > ln a``). Used for the
    steady-state tail after a finite twin propagation and for the lattice
    error tables.
    """
    c = np.asarray(c, dtype=np.float64)
    T = _symbol_grid(c.shape[0], k1, sigma_dx, matrices)
    ch = np.fft.fftn(c, axes=(0, 1, 2))
    rhs = np.einsum("...ij,...j->...i", T, ch)
    sol = np.linalg.solve(np.eye(4) - T, rhs[..., None])[..., 0]
    return np.fft.ifftn(sol, axes=(0, 1, 2)).real


# ------------------------------------------------- the numerical route (twin)

def _moments(c00, centre):
    """Total, mean and covariance (3x3, x y z) of a (N,N,N) density about ``centre`` (x, y, z)."""
    N = c00.shape[0]
    idx = np.arange(N, dtype=np.float64)
    z, y, x = np.meshgrid(idx - centre[2], idx - centre[1], idx - centre[0], indexing="ij")
    pos = np.stack([x, y, z], axis=-1)                      # (N,N,N,3) in cells
    total = c00.sum()
    mean = np.einsum("zyx,zyxi->i", c00, pos) / total
    second = np.einsum("zyx,zyxi,zyxj->ij", c00, pos, pos) / total
    return total, mean, second - np.outer(mean, mean)


def measure_spread(k1_values, N=48, steps=(14, 23), sigma_dx=0.0, band1=False):
    """Numerical ``D_lpv`` and ``lambda0`` with :func:`sslpv_gl.twin.propagate` (Eq. (8)).

    A point source sits in cell ``N//2`` of an ``N^3`` grid with
    ``sigma_lpv dx = sigma_dx``, ``sigma_s' = 1`` and ``g = k1`` (so Eq. 3
    gives exactly ``k1``); one ``k1`` per colour channel. The grid is
    propagated to ``steps[0]`` and on to ``steps[1]``. Every step moves light
    by one cell, so with ``steps[1] <= N//2 - 1`` no light has reached the
    grid's faces: the result is that of the unbounded lattice, exactly.

    * ``D_lpv = (Var(k_b) - Var(k_a)) / (2 (k_b - k_a))`` per axis, the slope
      of the variance of ``c00`` between two late steps (the start-up
      transient decays like ``(b k1)^k`` and cancels in the slope);
    * ``lambda0 = (F(k_b) / F(k_a))^(1 / (k_b - k_a))`` with ``F`` the sum of
      ``c00`` (the total flux over ``sqrt(4 pi)``).

    ``band1=True`` adds band-1 content to the source (a drifting start).
    Returns a dict of float64 arrays over ``k1_values``: ``k1``,
    ``d_axes`` (K, 3) for x, y, z, ``d_diag`` (along (1,1,1)/sqrt 3),
    ``d_lpv`` (mean of the three axes), ``lambda0``, ``seconds``.
    """
    from . import twin                                      # the real code under test

    k_a, k_b = (int(s) for s in steps)
    N = int(N)
    if not 0 < k_a < k_b <= N // 2 - 1:
        raise ValueError(f"need 0 < steps[0] < steps[1] <= N//2 - 1 = {N // 2 - 1}, got {steps}")
    k1_values = np.atleast_1d(np.asarray(k1_values, dtype=np.float64))
    h = N // 2
    centre = np.array([h, h, h], dtype=np.float64)
    diag = np.ones(3) / np.sqrt(3.0)
    out = {"k1": k1_values, "d_axes": [], "d_diag": [], "lambda0": []}
    t0 = time.perf_counter()
    for start in range(0, len(k1_values), 3):
        chunk = k1_values[start:start + 3]
        k1c = np.resize(chunk, 3)                           # fill the three colour channels
        c0 = np.zeros((N, N, N, 3, 4))
        c0[h, h, h, :, 0] = 1.0
        if band1:
            c0[h, h, h, :, 1:] = [0.4, -0.3, 0.6]           # (y, z, x) flux content
        ones = np.ones((N, N, N, 3))
        mat = (sigma_dx * ones, ones, ones * k1c)           # sigma_lpv (dx = 1), sp = 1, g = k1
        p_a, _ = twin.propagate(c0, *mat, 1.0, k_a, skip=k_a)
        p_b, _ = twin.propagate(p_a, *mat, 1.0, k_b - k_a, skip=k_b - k_a)
        for ch in range(len(chunk)):
            f_a, _, cov_a = _moments(p_a[..., ch, 0], centre)
            f_b, _, cov_b = _moments(p_b[..., ch, 0], centre)
            dcov = (cov_b - cov_a) / (2.0 * (k_b - k_a))
            out["d_axes"].append(np.diag(dcov))
            out["d_diag"].append(diag @ dcov @ diag)
            out["lambda0"].append((f_b / f_a) ** (1.0 / (k_b - k_a)))
    out["d_axes"] = np.array(out["d_axes"])
    out["d_diag"] = np.array(out["d_diag"])
    out["d_lpv"] = out["d_axes"].mean(axis=1)
    out["lambda0"] = np.array(out["lambda0"])
    out["seconds"] = time.perf_counter() - t0
    return out


# ------------------------------------------------------------------- table

def _table(k1_values, N, steps):
    num = measure_spread(k1_values, N=N, steps=steps)
    ana = d_lpv(num["k1"])
    rows = []
    for i, k1 in enumerate(num["k1"]):
        rows.append((k1, ana[i], num["d_lpv"][i], num["d_diag"][i], num["d_lpv"][i] / ana[i] - 1.0))
    return rows, num


def main(argv=None):
    """Print ``D_lpv(k1)``, analytic (Eq. (9)) against numerical (twin, Eq. (8)), and ``lambda0``."""
    import argparse

    parser = argparse.ArgumentParser(prog="python -m sslpv_gl.lattice", description=main.__doc__)
    parser.add_argument("--grid", type=int, default=48, help="grid N for the twin runs (default 48)")
    parser.add_argument("--steps", type=int, nargs=2, default=(14, 23), metavar=("KA", "KB"),
                        help="the two late step counts of the variance slope (default 14 23)")
    args = parser.parse_args(argv)

    c = constants()
    print("SSLPV lattice constants (docs/diffusion_mapping.md)")
    print(f"  m00 = {c.m00:.9f}  u = {c.u:.9f}  v = {c.v:.9f}  w_par = {c.w_par:.9f}  w_perp = {c.w_perp:.9f}")
    print(f"  a = 6 m00 = {c.a:.15f} (a - 1 = {c.a - 1.0:.1e}),  b = 2 w_par + 4 w_perp = {c.b:.9f}")
    print(f"  D_lpv(k1) = [m00 + 4 u v k1 / (a - b k1)] / a,  4 u v = {4 * c.u * c.v:.9f}")
    k1s = np.round(np.arange(0.0, 1.0001, 0.1), 10)
    rows, num = _table(np.concatenate([k1s, [DIFFUSION_K1]]), args.grid, tuple(args.steps))
    print(f"\nD_lpv in cell^2/step; numerical = twin.propagate, point source in a {args.grid}^3 grid, "
          f"variance slope between steps {args.steps[0]} and {args.steps[1]} (no light reaches the faces)")
    print(f"{'k1':>6} {'analytic':>12} {'numerical':>12} {'num (1,1,1)':>12} {'rel diff':>10}")
    for k1, a_, n_, d_, rel in rows:
        tag = "   <- diffusion mapping" if k1 == DIFFUSION_K1 else ""
        print(f"{k1:6.2f} {a_:12.8f} {n_:12.8f} {d_:12.8f} {rel:10.2e}{tag}")
    print("\nq^2 term along x and along (1,1,1) (curvature of the 4x4 symbol's eigenvalue, h = 1e-3):")
    for k1 in (0.0, 0.5, 1.0, DIFFUSION_K1):
        dx_, dd_ = d_lpv_direction(k1, (1, 0, 0)), d_lpv_direction(k1, (1, 1, 1))
        print(f"  k1 = {k1:5.2f}: x {dx_:.8f}  (1,1,1) {dd_:.8f}  Eq. (9) {float(d_lpv(k1)):.8f}")
    sig = 0.05
    flux = measure_spread([0.0, 0.5, 1.0], N=min(args.grid, 32), steps=(6, 15), sigma_dx=sig)
    print(f"\nper-step survival of the total flux at sigma_lpv dx = {sig}: analytic a exp(-sigma dx) = "
          f"{float(survival(sig)):.12f}; twin (k1 = 0, 0.5, 1): "
          + ", ".join(f"{x:.12f}" for x in flux["lambda0"]))
    print(f"at sigma = 0: lambda0 = a = {c.a:.15f}, mu = -ln a = {float(step_loss(0.0)):.1e}"
          f"  (the five faces subtend exactly the shared face's 2 pi / 3)")
    print(f"twin time: {num['seconds'] + flux['seconds']:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
