"""SSLPV propagation as a linear operator: its steady state, and steps until convergence.

Borlum et al. (HPG 2011) propagate light by repeating one step (Sec. 3.2,
Eq. 3, Sec. 4) and summing the propagation grid into the accumulation grid.
One step is linear in the grid, ``c_{k+1} = P c_k``, so after ``K`` steps
with the first ``skip`` left out (Sec. 4, "first two steps")::

    accum_K = sum_{k=skip+1}^{K} P^k c0                                  (S1)

and the converged grid the paper waits for ("the propagation grid is empty",
Sec. 3.2) is the Neumann series::

    accum_inf = sum_{k>skip} P^k c0 = (I - P)^{-1} P^{skip+1} c0         (S2)

which exists when the spectral radius ``rho(P) < 1``. This module solves (S2)
with a Krylov method, and offers the iterated alternative that stops when the
light is gone.

``P`` itself, its ordering and its spectral radius are :mod:`sslpv_gl.transfer` (sparse
matrices) and :mod:`sslpv_gl.stencil` (the same operator applied matrix-free); the
transfer rule is the one of ``docs/conventions.md`` (and of :func:`sslpv_gl.twin.propagate`).

Functions
---------

.. list-table::
   :header-rows: 1

   * - function
     - paper
     - result
   * - ``transfer_operator(sigma_lpv, sigma_s_prime, g, dx, matrices=None, emit=None)``
     - Eq. 3, Sec. 4
     - list of 3 ``scipy.sparse.csr_matrix`` ``(4 N^3, 4 N^3)``, one per colour
   * - ``steady_state(c0, sigma_lpv, sigma_s_prime, g, dx, skip=2, ..., operator="auto")``
     - Sec. 3.2 ("convergence"), Sec. 4 (skip)
     - ``(accum, info)``: (S2), ``accum`` float64 ``(N, N, N, 3, 4)``
   * - ``propagate_until(c0, sigma_lpv, sigma_s_prime, g, dx, tol=1e-3, ...)``
     - Sec. 3.2, Sec. 4
     - ``(accum, steps_used, remaining_fraction)``: (S1) with ``K`` chosen
       by the remaining flux
   * - ``spectral_radius(P)``
     -
     - ``rho(P)`` estimated with ARPACK
   * - ``remaining_fraction(c, c0)``
     -
     - the stopping measure of ``propagate_until`` (below)

Parameters
----------

.. list-table::
   :header-rows: 1

   * - parameter
     - default
     - meaning, limits
   * - ``c0``
     - (required)
     - injected grid ``(N, N, N, 3, 4)`` ``[z, y, x, colour, coeff]``,
       coefficients ``(c00, c1-1, c10, c11)``; finite
   * - ``sigma_lpv``, ``sigma_s_prime``, ``g``
     - (required)
     - per-cell material, each broadcastable to ``(N, N, N, 3)``; finite.
       Any values are accepted (the twin accepts them), but the series (S2)
       only exists when ``rho(P) < 1``, which is checked
   * - ``dx``
     - (required)
     - cell width, scalar or ``(dx, dy, dz)``; finite, > 0
   * - ``skip``
     - ``2``
     - steps not accumulated (paper Sec. 4), integer >= 0
   * - ``matrices``
     - ``propagation_matrices()``
     - ``(6, 4, 4)`` Sec. 4 matrices; entries below ``1e-12 max|M|`` (the
       quadrature's ``1e-18`` noise where the paper prints 0) are dropped
   * - ``rtol`` (``steady_state``)
     - ``1e-8``
     - Krylov relative residual ``||(I-P)x - b|| / ||b||``, in (0, 1). The
       error of ``x`` is at most ``||(I-P)^{-1}||`` times the residual; with
       ``1e-8`` the max-norm error was <= 1e-8 of max c00 in every measured
       case (``tests/test_steady.py``; ``benchmarks/bench_steady.py``: 4e-9,
       1e-8, 7e-9 at N = 16, 32, 64)
   * - ``method`` (``steady_state``)
     - ``"bicgstab"``
     - ``"bicgstab"`` or ``"gmres"`` (restart 50); see "Solver" below
   * - ``maxiter`` (``steady_state``)
     - ``5000``
     - Krylov iterations per colour before giving up (``ValueError``)
   * - ``check_spectrum`` (``steady_state``)
     - ``True``
     - estimate ``rho(P)`` per colour and raise ``ValueError`` if >= 1
   * - ``operator`` (``steady_state``)
     - ``"auto"``
     - ``"sparse"``, ``"stencil"`` (matrix-free) or ``"auto"``: the stencil for
       ``N >= STENCIL_MIN_N`` (48); see "Operator" below
   * - ``tol`` (``propagate_until``)
     - ``1e-3``
     - stop when ``remaining_fraction < tol``, in (0, 1)
   * - ``max_steps`` (``propagate_until``)
     - ``4096``
     - cap on ``K``, integer >= ``skip``
Solver
------
``P`` couples only face neighbours, whose parities ``(x + y + z) % 2``
differ, so in red/black order ``P = [[0, P_rb], [P_br, 0]]`` and
``(I - P) x = b`` reduces exactly to the half-size system
``(I - P_br P_rb) x_b = b_b + P_br b_r``, ``x_r = b_r + P_rb x_b`` (block
elimination; no approximation). With ``boundary_reflect = rdr`` (:mod:`sslpv_gl.reflect`)
``P`` has 4x4 blocks on its diagonal at the surface cells, and the same elimination
keeps them: ``E = (I - P_rr)^{-1}`` (block diagonal, inverted cell by cell),
``(I - P_bb - P_br E P_rb) x_b = b_b + P_br E b_r``, ``x_r = E (b_r + P_rb x_b)``
(:class:`sslpv_gl.transfer._Split`). The eigenvalues of ``P`` come in ``+-``
pairs, which the reduced operator folds onto one (``rho(P_br P_rb) =
rho(P)^2``). Measured on a sphere like that of ``benchmarks/bench_steady.py``
at N = 32 (one colour, rtol 1e-8, one core): BiCGSTAB needed 76 iterations
(0.70 s) on ``I - P`` and 37 (0.20 s) on the reduced system, GMRES(30) 189
and 84. An incomplete LU of the reduced matrix (``spilu``, drop 1e-2) cut
BiCGSTAB to 13 iterations but took 16 s to build, so no further
preconditioner is used. BiCGSTAB was 2-3x faster than GMRES(50-60) at N = 32
and 64 (GMRES's orthogonalisation dominates at these sizes), hence the
default.

Operator
--------
``"sparse"`` builds the CSR matrices of :func:`transfer_operator` for the three colours
at once (and a second set for the first step when ``emit`` is given), then the red/black
blocks of one colour. ``"stencil"`` builds one colour's :class:`sslpv_gl.stencil.StencilOperator`
at a time and applies ``P``, the reduced product and the spectral check by slices; both
solve the same reduced system with the same BiCGSTAB and took the same iterations, and their
grids differed by rounding only. ``"auto"`` takes the stencil from ``N >= STENCIL_MIN_N = 48``:
below, the sparse path was faster (the stencil's Python overhead per slice), from there on the
stencil was as fast or faster, and it always needed less memory. Measured by
``python benchmarks/bench_steady.py --steady-only --sizes 32 64 128 --operator sparse stencil``
(and ``--sizes 24 32 48 64``), each solve in a fresh process, peak resident memory by ``os.wait4``
(the full table is :mod:`sslpv_gl.stencil`'s, "Memory and time"): total 0.7 / 1.1 s (sparse /
stencil) at N = 32, 3.4 / 2.8 s at N = 48, 11.3 / 10.4 s at N = 64 and 161 / 143 s at
N = 128, peak 4.53 / 1.52 GiB at N = 128 (7.51 / 3.79 GiB with ``boundary_reflect = rdr``,
whose spectral check holds 40 full-size vectors); building the sparse matrices and their red/black
blocks alone took 27 s there.

Convergence check
-----------------
When ``rho(P) >= 1`` the series (S2) diverges although ``I - P`` may still be
invertible, so a Krylov solve would return a finite but meaningless grid.
``steady_state`` therefore estimates ``rho(P)`` per colour with ARPACK
(``eigs`` of ``P_br P_rb``, largest modulus, ``tol=1e-3``, which put
``rho`` within 5e-6 of a ``tol=1e-6`` run at N = 32 and 64; 20-35 operator
products, a third to a half of a solve's) and raises ``ValueError`` when it is
>= 1. For physical material (``sigma_lpv >= 0``, ``|k1| <= 1``) the symbol
of ``P`` on the infinite lattice has radius <= 1 (= 1 only at wavenumber 0
and at the checkerboard mode, flux conservation; ``tests/test_steady.py``)
and the grid boundary lets light escape, so ``rho(P) < 1`` is expected, and
was found in every case tried; but without absorption ``rho`` approaches 1
as ``N`` grows, ``1 - rho ~ 3 pi^2 D / N^2`` with ``D`` ~ 0.16-0.21 cell^2
per step (measured in an all-vacuum grid: ``1 - rho`` = 0.0048 at N = 32,
``k1`` = 0.3), and the solve needs more iterations, giving up with
``ValueError`` after ``maxiter``. Negative ``sigma_lpv`` (a gain) can still
leave ``rho < 1`` when the boundary leaks more than it adds; only ``rho``
decides.

Stopping measure of ``propagate_until``
----------------------------------------
The flux of a cell's intensity is ``int I dw = sqrt(4 pi) c00``. The
remaining fraction after step ``k`` is, per colour,
``sum_cells |c00_k| / sum_cells |c00_0|`` (the ``sqrt(4 pi)`` cancels;
absolute values because two-band lobes can carry negative ``c00`` in
places, and a net sum could cancel to zero while light is still moving), and
the reported value is its maximum over the colours that received any flux.
Note that a remaining fraction ``f`` still owes the accumulation about
``f / (1 - rho)`` of the injected flux, so ``tol`` bounds the light still in
flight, not the error of ``accum``. On the sphere of
``benchmarks/bench_steady.py`` the remaining fraction was 2.7e-4, 3.4e-4 and
4.4e-4 (N = 16, 32, 64) at the first step whose accumulation was within
1e-4 of max c00 of the steady state, so ``tol = 2e-4`` gives about that
accuracy there, and the default ``1e-3`` somewhat less.

Limits
------
* Memory: that of ``P`` (:mod:`sslpv_gl.transfer` or :mod:`sslpv_gl.stencil`, above) and of
  ``c0`` and ``accum`` (96 bytes per cell each), the Krylov vectors of one colour (BiCGSTAB: about
  eight vectors of the black cells' unknowns) and a few full-size ones (``b``, ``x``).
* Float64 throughout (the GL renderer stores fp32/fp16).
* ``propagate_until`` applies ``P`` step by step with the sparse operator
  (same rule as the twin to ~1e-16 per step, faster); its cost is the
  number of steps times one sparse product per colour.
"""

from __future__ import annotations

import inspect
import numbers
import time

import numpy as np
import scipy.sparse.linalg as spla

from .stencil import stencil_operator
from .transfer import _bad, _c0, _material, _red_black, _skip, _Split, spectral_radius, transfer_operator

__all__ = [
    "transfer_operator",
    "steady_state",
    "propagate_until",
    "spectral_radius",
    "remaining_fraction",
]

_METHODS = ("bicgstab", "gmres")
# scipy < 1.12 calls the relative tolerance `tol` (the project allows scipy >= 1.11)
_RTOL = "rtol" if "rtol" in inspect.signature(spla.bicgstab).parameters else "tol"
_GMRES_RESTART = 50
#: ``operator`` choices of :func:`steady_state`.
OPERATORS = ("auto", "sparse", "stencil")
#: ``operator = "auto"`` uses the matrix-free stencil from this grid size on (module docstring, "Operator").
STENCIL_MIN_N = 48


# ------------------------------------------------------------ steady state

def steady_state(c0, sigma_lpv, sigma_s_prime, g, dx, skip=2, matrices=None, rtol=1e-8,
                 method="bicgstab", maxiter=5000, check_spectrum=True, emit=None, empty=None, r_dr=0.0,
                 inside=None, operator="auto"):
    """Converged accumulation grid ``sum_{k>skip} P^k c0`` (Sec. 3.2, Eq. 3, Sec. 4) -> ``(accum, info)``.

    The paper's accumulation grid once "the propagation grid is empty"
    (Sec. 3.2), with the first ``skip`` steps not accumulated (Sec. 4). The
    first ``skip + 1`` steps are applied exactly, ``b = P^{skip+1} c0``; then
    ``(I - P) x = b`` is solved per colour by BiCGSTAB or GMRES on the exact
    red/black reduction (module docstring, "Solver"), so ``x = (I - P)^{-1}
    b`` is the series (S2).

    ``operator``: ``"sparse"`` (the matrices of :func:`transfer_operator`, all colours built at
    once), ``"stencil"`` (:mod:`sslpv_gl.stencil`, matrix-free, one colour at a time) or
    ``"auto"`` (the stencil from ``N >=`` :data:`STENCIL_MIN_N` on; module docstring, "Operator").

    ``accum``: float64 ``(N, N, N, 3, 4)``. ``info``: dict with ``method``, ``operator`` (the one
    used), ``rtol``, per colour lists ``iterations`` (Krylov iterations),
    ``products`` (applications of ``P``, the skip steps and the spectral
    check included), ``residual`` (true ``||(I-P)x - b|| / ||b||`` on the full
    system), ``rho`` (spectral radius estimate, ``None`` unchecked), and
    ``time`` (seconds: ``operator`` (build and red/black split), ``spectrum``,
    ``solve``, ``total``).

    ``emit``: sink cells, ``empty``: empty cells, ``r_dr`` and ``inside``: the surface
    reflection (:mod:`sslpv_gl.reflect`), as in :func:`transfer_operator`.

    Raises ``ValueError`` (one line) on bad input, when ``rho(P) >= 1`` for a
    colour that carries light (the series diverges: no steady state), or
    when the solver does not reach ``rtol`` within ``maxiter`` iterations.
    """
    t_start = time.perf_counter()
    c0 = _c0(c0)
    N = c0.shape[0]
    skip = _skip(skip)
    if method not in _METHODS:
        _bad("method", f"unknown method {method!r}", "use one of: " + ", ".join(_METHODS))
    if not (isinstance(rtol, numbers.Real) and 0.0 < rtol < 1.0):
        _bad("rtol", f"must be in (0, 1), got {rtol!r}", "pass e.g. 1e-8")
    if isinstance(maxiter, bool) or not isinstance(maxiter, (int, np.integer)) or maxiter < 1:
        _bad("maxiter", f"must be an integer >= 1, got {maxiter!r}", "pass e.g. 5000")
    if not isinstance(operator, str) or operator not in OPERATORS:
        _bad("operator", f"unknown operator {operator!r}", "use one of: " + ", ".join(OPERATORS))
    if operator == "auto":
        operator = "stencil" if N >= STENCIL_MIN_N else "sparse"
    sig, spr, gg = _material(sigma_lpv, sigma_s_prime, g, N)

    if operator == "sparse":
        ops = transfer_operator(sig, spr, gg, dx, matrices, emit, empty, r_dr, inside)
        # step 1 carries the injected light, which has crossed the surface inwards: every cell emits
        ops1 = ops if emit is None else transfer_operator(sig, spr, gg, dx, matrices, None, empty, r_dr, inside)
        red, black = _red_black(N)
    else:
        em = None if emit is None else _material(emit, 0.0, 0.0, N)[0]
        emp = None if empty is None else _material(empty, 0.0, 0.0, N)[0]
    t_op = time.perf_counter() - t_start
    accum = np.zeros_like(c0)
    info = {"method": method, "operator": operator, "rtol": float(rtol), "iterations": [], "products": [],
            "residual": [], "rho": [], "time": {"operator": t_op, "spectrum": 0.0, "solve": 0.0}}
    rho_cache = []                           # (key, rho): grey materials give equal operators
    for col in range(3):
        t0 = time.perf_counter()
        if operator == "sparse":
            op = _SparseColour(ops[col], ops1[col], red, black)
            key = (ops[col].data,)
        else:                                # one colour at a time: only its operator is held
            op = stencil_operator(sig, spr, gg, dx, col, matrices, em, emp, r_dr, inside)
            key = tuple(None if a is None else a[..., col] for a in (sig, spr, gg, em, emp))
        info["time"]["operator"] += time.perf_counter() - t0
        b = op.step(op.vec(c0[..., col, :]), first_step=True)
        for _ in range(skip):                # the skipped steps and the first accumulated one, exactly
            b = op.step(b)
        if not np.any(b):
            info["iterations"].append(0)
            info["products"].append(skip + 1)
            info["residual"].append(0.0)
            info["rho"].append(None)
            continue
        # the series is linear in b: solve for b / max|b| and scale back, so that a source of tiny values
        # (a cell's light absorbed to near the underflow) does not underflow the norms of the residual
        scale = float(np.abs(b).max())
        b = b / scale

        rho = None
        if check_spectrum:
            t0 = time.perf_counter()
            for seen, r in rho_cache:
                if all((x is None and y is None) or (x is not None and y is not None and x.shape == y.shape
                                                     and np.array_equal(x, y)) for x, y in zip(seen, key)):
                    rho = r
                    break
            if rho is None:
                rho = op.radius()
                rho_cache.append((key, rho))
            info["time"]["spectrum"] += time.perf_counter() - t0
            if rho >= 1.0:
                _bad("steady_state", f"colour {col}: the transfer operator's spectral radius is {rho:.6g} >= 1, "
                     "so the step series diverges and there is no steady state",
                     "check sigma_lpv >= 0 and |k1| <= 1, or use a fixed step count")

        t0 = time.perf_counter()
        rhs = op.rhs(b)
        # the red rows of the full residual vanish (x_r is formed exactly), its
        # black rows are the reduced residual: scale rtol so that it bounds
        # the full system's relative residual, as documented
        rtol_reduced = float(rtol) * float(np.linalg.norm(b) / max(np.linalg.norm(rhs), np.finfo(float).tiny))
        m = rhs.size
        lin = spla.LinearOperator((m, m), matvec=lambda y, o=op: y - o.reduced(y), dtype=np.float64)
        iters = [0]

        def count(*_args):
            iters[0] += 1

        if method == "bicgstab":
            xb, flag = spla.bicgstab(lin, rhs, **{_RTOL: rtol_reduced}, atol=0.0, maxiter=int(maxiter), callback=count)
        else:
            xb, flag = spla.gmres(lin, rhs, **{_RTOL: rtol_reduced}, atol=0.0, restart=_GMRES_RESTART,
                                  maxiter=max(1, int(maxiter) // _GMRES_RESTART + 1),
                                  callback=count, callback_type="pr_norm")
        del rhs, lin
        x = op.expand(b, xb)
        # check on the full system, independent of the solver's own estimate
        res = float(np.linalg.norm(x - op.step(x) - b) / np.linalg.norm(b))
        info["time"]["solve"] += time.perf_counter() - t0
        if flag != 0 or not np.all(np.isfinite(x)) or not res <= 10.0 * rtol:
            why = "broke down" if flag < 0 else f"did not converge in {iters[0]} iterations"
            rho_txt = "unchecked" if rho is None else f"{rho:.8f}"
            _bad("steady_state", f"colour {col}: {method} {why} (relative residual {res:.3g}, rtol {rtol:g}, "
                 f"spectral radius {rho_txt}); the series converges too slowly or not at all",
                 "add absorption, raise maxiter, or use propagate_until")
        accum[..., col, :] = op.grid(x) * scale
        info["iterations"].append(int(iters[0]))
        info["products"].append(skip + 1 + op.products + 2)
        info["residual"].append(res)
        info["rho"].append(rho)
        del op, b, x, xb
    info["time"]["total"] = time.perf_counter() - t_start
    return accum, info


class _SparseColour:
    """One colour's sparse ``P`` (and ``P1``, step 1 without sinks) behind the interface of
    :class:`sslpv_gl.stencil.StencilOperator` that :func:`steady_state` uses (vectors in the
    ordering of :func:`transfer_operator`)."""

    def __init__(self, P, P1, red, black):
        self.P, self.P1, self.red, self.black = P, P1, red, black
        self.split = _Split(P, red, black)

    @property
    def products(self):
        return self.split.products

    def vec(self, grid):
        return np.asarray(grid, dtype=np.float64).reshape(-1)

    def grid(self, v):
        N = round((v.size // 4) ** (1.0 / 3.0))
        return v.reshape(N, N, N, 4)

    def step(self, v, first_step=False):
        return (self.P1 if first_step else self.P) @ v

    def reduced(self, y):
        return self.split.reduced(y)

    def radius(self):
        return spectral_radius(self.P, _split=self.split)

    def rhs(self, b):
        split, red, black = self.split, self.red, self.black
        return b[black] + split.P_br @ split.apply_e(b[red])

    def expand(self, b, xb):
        split, red, black = self.split, self.red, self.black
        x = np.empty_like(b)
        x[black] = xb
        x[red] = split.apply_e(b[red] + split.P_rb @ xb)
        return x


# --------------------------------------------------------- steps until done

def remaining_fraction(c, c0):
    """Light still in the propagation grid ``c`` relative to the injected grid ``c0``.

    Per colour ``sum |c00(c)| / sum |c00(c0)|`` (flux ``sqrt(4 pi) c00``, the
    factor cancels); the maximum over colours whose ``c0`` carries flux, 0 if
    none does. ``c``, ``c0``: ``(N, N, N, 3, 4)``.
    """
    c = np.asarray(c, dtype=np.float64)
    c0 = np.asarray(c0, dtype=np.float64)
    inj = np.abs(c0[..., 0]).sum(axis=(0, 1, 2))
    now = np.abs(c[..., 0]).sum(axis=(0, 1, 2))
    lit = inj > 0
    if not np.any(lit):
        return 0.0
    return float((now[lit] / inj[lit]).max())


def propagate_until(c0, sigma_lpv, sigma_s_prime, g, dx, tol=1e-3, max_steps=4096, skip=2, matrices=None,
                    emit=None, empty=None, r_dr=0.0, inside=None):
    """Propagate until the light is gone (Sec. 3.2, Eq. 3, Sec. 4) -> ``(accum, steps_used, remaining)``.

    ``steps = auto``: apply the one-step operator (same rule as
    :func:`sslpv_gl.twin.propagate`) and stop after the first step ``K >=
    skip`` at which :func:`remaining_fraction` of the propagation grid is
    below ``tol``, or at ``K = max_steps``. ``accum`` is the twin's
    accumulation grid for ``K`` steps, ``sum_{k=skip+1}^{K} P^k c0``;
    ``remaining`` is the fraction after step ``K`` (>= ``tol`` only when the
    cap was reached; the caller decides whether that is acceptable).
    """
    c0 = _c0(c0)
    N = c0.shape[0]
    skip = _skip(skip)
    if not (isinstance(tol, numbers.Real) and 0.0 < tol < 1.0):
        _bad("tol", f"must be in (0, 1), got {tol!r}", "pass e.g. 1e-3")
    if isinstance(max_steps, bool) or not isinstance(max_steps, (int, np.integer)) or max_steps < skip:
        _bad("max_steps", f"must be an integer >= skip ({skip}), got {max_steps!r}", "raise max_steps")
    sig, spr, gg = _material(sigma_lpv, sigma_s_prime, g, N)
    ops = transfer_operator(sig, spr, gg, dx, matrices, emit, empty, r_dr, inside)
    ops1 = ops if emit is None else transfer_operator(sig, spr, gg, dx, matrices, None, empty, r_dr,
                                                      inside)   # step 1: every cell emits

    c = [c0[..., col, :].reshape(-1).copy() for col in range(3)]
    inj = np.abs(c0[..., 0]).sum(axis=(0, 1, 2))
    lit = [col for col in range(3) if inj[col] > 0]
    acc = [np.zeros(4 * N ** 3) for _ in range(3)]

    def fraction():
        if not lit:
            return 0.0
        return max(float(np.abs(c[col][0::4]).sum() / inj[col]) for col in lit)

    k = 0
    remaining = fraction()
    while k < int(max_steps) and (k < skip or remaining >= tol):
        k += 1
        for col in range(3):
            c[col] = (ops1 if k == 1 else ops)[col] @ c[col]
            if k > skip:
                acc[col] += c[col]
        remaining = fraction()
    accum = np.stack([a.reshape(N, N, N, 4) for a in acc], axis=3)
    return accum, k, remaining
