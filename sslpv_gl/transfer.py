"""One SSLPV propagation step as a linear operator ``P``: a sparse matrix per colour, and its spectral radius.

One step of Borlum et al.'s propagation (HPG 2011, Sec. 3.2, Eq. 3, Sec. 4) is linear in
the grid, ``c_{k+1} = P c_k``; :mod:`sslpv_gl.steady` sums its powers.

The transfer rule is the one of ``docs/conventions.md`` (and of
:func:`sslpv_gl.twin.propagate`); for a destination ``d`` and its six
neighbours ``s``::

    c_d += M_s @ (exp(-0.5 (sigma_lpv[s] + sigma_lpv[d]) dx_axis) * S(s) c_s)

``S(s) = diag(1, k1, k1, k1)``, ``k1 = (1 - sp[s]) + sp[s] g[s]`` (Eq. 3 on
the SOURCE cell), ``M_s`` = :func:`sslpv_gl.sh.propagation_matrices` (Sec. 4),
nothing enters from outside the grid. Colours are independent.
``emit`` (default 1) multiplies what a source cell sends on (0: a sink cell), and
``empty`` multiplies the entry from ``s`` to ``d`` by ``1 - empty[s] empty[d]``
(``outside = interior``). ``r_dr`` with ``inside`` (``boundary_reflect = rdr``,
:mod:`sslpv_gl.reflect`) scales the entries across surface faces by ``1 - r_dr`` and
adds the reflected part as a 4x4 block on the diagonal of each surface cell.

Ordering of the operator
------------------------
Per colour, the unknown for cell ``[z, y, x]`` and coefficient ``a`` is row
``4 * ((z * N + y) * N + x) + a``, i.e. ``grid[..., colour, :].reshape(-1)``
of a C-ordered ``(N, N, N, 3, 4)`` grid. ``P[4d + a, 4s + b] = M_s[a, b] *
exp(-0.5 (sigma[s] + sigma[d]) dx_axis) * (1 if b == 0 else k1[s])``.

:func:`spectral_radius` estimates ``rho(P)`` on the red/black reduced operator
(``rho(P_br P_rb) = rho(P)^2``; :mod:`sslpv_gl.steady`, "Solver"): with dense
eigenvalues up to ``_DENSE_EIG_MAX`` unknowns, else with ARPACK (by power iteration where
ARPACK stops on an invariant subspace). With the reflection's diagonal blocks that relation
no longer holds, and ``rho(P)`` is estimated on ``P`` itself (dense up to twice that size, else
ARPACK with two Ritz values, else power iteration on ``P^2``). :func:`operator_radius` is that
route for any coding of ``P`` that offers its products (the matrix-free :mod:`sslpv_gl.stencil`).
The input checks shared with :mod:`sslpv_gl.steady` are here too.

Limits
------
* Memory: ``P`` has 36 stored entries per cell and colour (9.4 M at
  ``N = 64``, ~110 MB per colour in CSR; 75 M, ~0.9 GB per colour at ``N = 128``), built for
  the three colours at once, and :class:`_Split` copies one colour's red/black blocks again.
  Measured by ``python benchmarks/bench_steady.py --steady-only --sizes 32 64 128 --operator
  sparse stencil`` (peak resident memory of a whole :func:`sslpv_gl.steady.steady_state`,
  fresh process): 0.65 GiB at ``N = 64``, 4.53 GiB at ``N = 128`` (7.51 GiB with the
  reflection, whose spectral check adds 40 full-size ARPACK vectors); the build took 27 s there.
  The matrix-free :mod:`sslpv_gl.stencil` applies the same operator in a fraction of that
  memory; ``steady_state(operator="auto")`` uses it for large grids.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .sh import SOURCE_OFFSETS, neighbour_slices, propagation_matrices, scatter_factors

_DENSE_EIG_MAX = 512           # reduced systems up to this size use dense eigvals
_DROP = 1e-12                  # relative size below which matrix entries are quadrature noise


# ------------------------------------------------------------------ inputs

def _bad(field, problem, fix):
    # one line: "<setting>: <field>: <problem>; <fix>" (docs/conventions.md)
    raise ValueError(f"sslpv_gl.steady: {field}: {problem}; {fix}")


def _finite(name, a):
    if not np.all(np.isfinite(a)):
        _bad(name, "contains NaN or Inf", "pass finite values")
    return a


def _material(sigma_lpv, sigma_s_prime, g, N):
    shape = (N, N, N, 3)
    out = []
    for name, a in (("sigma_lpv", sigma_lpv), ("sigma_s_prime", sigma_s_prime), ("g", g)):
        a = np.asarray(a, dtype=np.float64)
        try:
            a = np.broadcast_to(a, shape)
        except ValueError:
            _bad(name, f"shape {a.shape} does not broadcast to {shape}", "pass (N, N, N, 3) or a scalar")
        out.append(_finite(name, a))
    return out


def _grid_size(*arrays):
    """N from the first material array with at least 3 dimensions."""
    for a in arrays:
        a = np.asarray(a)
        if a.ndim >= 3:
            if not a.shape[0] == a.shape[1] == a.shape[2] >= 1:
                _bad("sigma_lpv", f"shape {a.shape} is not (N, N, N, ...)", "pass a cubic grid")
            return int(a.shape[0])
    _bad("sigma_lpv", "no material array has a grid shape", "pass (N, N, N, 3) arrays")


def _dx(dx):
    d = np.asarray(dx, dtype=np.float64)
    try:
        d = np.broadcast_to(d, (3,)).copy()
    except ValueError:
        _bad("dx", f"shape {d.shape} is not scalar or (3,)", "pass the cell width or (dx, dy, dz)")
    if not np.all(np.isfinite(d)) or np.any(d <= 0):
        _bad("dx", f"must be finite and > 0, got {dx!r}", "pass the cell width")
    return d


def _c0(c0):
    c = np.asarray(c0, dtype=np.float64)
    if c.ndim != 5 or c.shape[3:] != (3, 4) or not c.shape[0] == c.shape[1] == c.shape[2]:
        _bad("c0", f"shape {c.shape} is not (N, N, N, 3, 4)", "pass an SH grid [z, y, x, colour, coeff]")
    return _finite("c0", c)


def _skip(skip):
    if isinstance(skip, bool) or not isinstance(skip, (int, np.integer)) or skip < 0:
        _bad("skip", f"must be an integer >= 0, got {skip!r}", "pass e.g. 2 (paper Sec. 4)")
    return int(skip)


# ---------------------------------------------------------------- operator

def transfer_operator(sigma_lpv, sigma_s_prime, g, dx, matrices=None, emit=None, empty=None, r_dr=0.0,
                      inside=None):
    """One propagation step (Sec. 3.2, Eq. 3, Sec. 4) as sparse matrices, one per colour.

    Returns a list of three ``scipy.sparse.csr_matrix`` of shape
    ``(4 N^3, 4 N^3)`` such that, per colour ``col``,
    ``(P[col] @ c[..., col, :].reshape(-1)).reshape(N, N, N, 4)`` is one step
    of :func:`sslpv_gl.twin.propagate` (module docstring: ordering and entry
    formula). Material arrays broadcast to ``(N, N, N, 3)``; ``N`` is taken
    from the first of them that has three or more dimensions. ``dx`` is a
    scalar or ``(dx, dy, dz)``; the step along an axis uses that axis' width.
    ``emit`` (default 1) multiplies what each SOURCE cell sends on: 0 makes a
    sink cell (:mod:`sslpv_gl.boundary`), as in :func:`sslpv_gl.twin.propagate`
    (whose first step, like :func:`steady_state`'s, uses the operator without sinks).
    ``empty`` (default 0) marks empty cells: the entry from ``s`` to ``d`` is multiplied
    by ``1 - empty[s] empty[d]`` (``outside = interior``, at every step).
    ``r_dr`` with ``inside`` ((N, N, N) bool): Eq. (R3) of :mod:`sslpv_gl.reflect`, the
    entries from an inside to an outside cell times ``1 - r_dr``, and per surface cell a
    diagonal block ``r_dr exp(-sigma dx) emit M_{+o} F_o S`` per outside neighbour ``o``.

    All three matrices share one sparsity pattern (36 entries per cell away
    from the boundary). It is built once, vectorised, directly in CSR order
    (destination cell, row coefficient, source, column coefficient: no sort);
    each colour's ``data`` is then two gathers.
    """
    N = _grid_size(sigma_lpv, sigma_s_prime, g)
    sig, spr, gg = _material(sigma_lpv, sigma_s_prime, g, N)
    em = _material(1.0 if emit is None else emit, 0.0, 0.0, N)[0]
    emp = None if empty is None else _material(empty, 0.0, 0.0, N)[0]
    dxs = _dx(dx)
    mats = propagation_matrices() if matrices is None else np.asarray(matrices, dtype=np.float64)
    if mats.shape != (6, 4, 4):
        _bad("matrices", f"shape {mats.shape} is not (6, 4, 4)", "pass propagation_matrices()")
    _finite("matrices", mats)
    k1 = scatter_factors(spr, gg)[..., 1]    # Eq. 3, band 1 of the SOURCE cell; band 0 is 1
    drop = _DROP * max(float(np.abs(mats).max()), np.finfo(float).tiny)
    reflecting = bool(r_dr) and inside is not None
    ins = np.asarray(inside, dtype=bool) if reflecting else None
    n_cells = N ** 3
    cells = np.arange(n_cells, dtype=np.int64).reshape(N, N, N)

    # Entries are laid out [destination cell, row coefficient a, source s, column
    # coefficient b], which is CSR row order; sources ordered -z, -y, -x, +x, +y, +z
    # have ascending cell numbers, so the column indices come out sorted too.
    order = [5, 3, 1, 0, 2, 4]
    src_cell = np.full((n_cells, 6), -1, dtype=np.int64)
    att = np.zeros((n_cells, 6, 3))
    k1_src = np.zeros((n_cells, 6, 3))
    for j, s in enumerate(order):
        offset = SOURCE_OFFSETS[s]
        dst, src = neighbour_slices(offset)
        axis = int(np.flatnonzero(offset)[0])
        src_cell[cells[dst].ravel(), j] = cells[src].ravel()
        # half the path lies in each cell (conventions: mean of source and destination)
        a = np.exp(-0.5 * (sig[src] + sig[dst]) * dxs[axis]) * em[src]
        if emp is not None:                          # no link between two empty cells
            a = a * (1.0 - emp[src] * emp[dst])
        if reflecting:                               # Eq. (R3): only 1 - R_dr crosses a surface face
            a = a * np.where((ins[src] & ~ins[dst])[..., None], 1.0 - r_dr, 1.0)
        att[cells[dst].ravel(), j] = a.reshape(-1, 3)
        k1_src[cells[dst].ravel(), j] = k1[src].reshape(-1, 3)
    m = mats[order].transpose(1, 0, 2)                       # (a, s, b)
    keep = (np.abs(m) > drop)[None] & (src_cell >= 0)[:, None, :, None]   # (cell, a, s, b)
    kept = np.flatnonzero(keep.ravel())
    n = 4 * n_cells
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(keep.reshape(n, -1).sum(axis=1), out=indptr[1:])
    del keep
    # decompose the kept positions once; every colour then needs two gathers
    cell, rest = np.divmod(kept, 96)
    a_sb = rest % 24                                         # (s, b) within the row
    m_idx = rest                                             # (a, s, b) in m
    csb = cell * 24 + a_sb                                   # (cell, s, b) of the factor below
    del kept, rest
    indices = (4 * src_cell.ravel()[cell * 6 + a_sb // 4] + a_sb % 4).astype(np.int32)
    del cell, a_sb
    idx_dtype = np.int32 if indptr[-1] < np.iinfo(np.int32).max else np.int64
    indptr = indptr.astype(idx_dtype)
    indices = indices.astype(idx_dtype, copy=False)
    m_flat = m.ravel()[m_idx]
    del m_idx
    out = []
    for col in range(3):
        # band 0 leaves the source unscaled, band 1 is scaled by the source's k1 (Eq. 3)
        factor = np.empty((n_cells, 6, 4))
        factor[:, :, 0] = att[:, :, col]
        factor[:, :, 1:] = (att[:, :, col] * k1_src[:, :, col])[:, :, None]
        mat = sp.csr_matrix((m_flat * factor.ravel()[csb], indices, indptr), shape=(n, n))
        mat.has_sorted_indices = True
        if reflecting:
            mat = (mat + _reflection_blocks(ins, sig[..., col], k1[..., col], em[..., col], dxs, mats, r_dr)).tocsr()
            mat.sort_indices()
        out.append(mat)
    return out


def _reflection_blocks(ins, sig, k1, em, dxs, mats, r_dr):
    """The diagonal blocks of Eq. (R3) (:mod:`sslpv_gl.reflect`) for one colour -> ``bsr_matrix`` (4 N^3)^2."""
    from .reflect import AXIS_COEFF, surface_faces

    N = ins.shape[0]
    blocks = np.zeros((N, N, N, 4, 4))
    for s, offset in enumerate(SOURCE_OFFSETS):
        axis = int(np.flatnonzero(offset)[0])
        flip = np.ones(4)
        flip[AXIS_COEFF[axis]] = -1.0                # F_o: the lobe mirrored about the face
        w = surface_faces(ins, offset) * np.exp(-sig * dxs[axis]) * em * r_dr
        scale = np.concatenate([np.ones((N, N, N, 1)), np.repeat(k1[..., None], 3, axis=-1)], axis=-1)   # S(s)
        blocks += w[..., None, None] * (mats[s] * flip[None, :])[None, None, None] * scale[..., None, :]
    n = N ** 3
    return sp.bsr_matrix((blocks.reshape(n, 4, 4), np.arange(n), np.arange(n + 1)), shape=(4 * n, 4 * n))


def _red_black(N):
    """Row indices of the even and odd cells ((x + y + z) % 2), 4 coefficients each."""
    z, y, x = np.meshgrid(*(np.arange(N),) * 3, indexing="ij")
    par = np.repeat(((x + y + z) % 2).ravel(), 4)
    return np.flatnonzero(par == 0), np.flatnonzero(par == 1)


class _Split:
    """``P`` in red/black blocks; ``reduced`` applies the Schur complement's operator on the black cells.

    Face neighbours have opposite parities, so without ``boundary_reflect`` the red/red and
    black/black blocks are zero and ``reduced`` is ``P_br P_rb``. The reflection of
    :mod:`sslpv_gl.reflect` puts 4x4 blocks on the diagonal (``P_rr``, ``P_bb``); then
    ``(I - P) x = b`` reduces exactly to ``(I - P_bb - P_br E P_rb) x_b = b_b + P_br E b_r``,
    ``x_r = E (b_r + P_rb x_b)`` with ``E = (I - P_rr)^{-1}``, block diagonal (``diag``).
    """

    def __init__(self, P, red, black):
        self.red, self.black = red, black
        Pr = P[red]
        Pb = P[black]
        self.P_rb = Pr[:, black].tocsr()     # red rows, black columns
        self.P_br = Pb[:, red].tocsr()
        P_rr = Pr[:, red].tocsr()
        P_bb = Pb[:, black].tocsr()
        P_rr.eliminate_zeros()
        P_bb.eliminate_zeros()
        self.diag = bool(P_rr.nnz or P_bb.nnz)
        self.P_bb = P_bb
        self.E = _block_inverse(P_rr) if self.diag else None
        self.products = 0                    # counts of the reduced operator, ~ one full P product each

    def apply_e(self, v):
        """``E v`` (``v`` itself without diagonal blocks)."""
        return v if self.E is None else self.E @ v

    def reduced(self, y):
        self.products += 1
        if self.E is None:
            return self.P_br @ (self.P_rb @ y)
        return self.P_bb @ y + self.P_br @ (self.E @ (self.P_rb @ y))


def _block_inverse(P_rr):
    """``(I - P_rr)^{-1}`` for a block-diagonal ``P_rr`` of 4x4 blocks -> csr."""
    n = P_rr.shape[0] // 4
    coo = P_rr.tocoo()
    if np.any(coo.row // 4 != coo.col // 4):
        raise AssertionError("red/red block of P is not block diagonal")
    blocks = np.zeros((n, 4, 4))
    np.add.at(blocks, (coo.row // 4, coo.row % 4, coo.col % 4), coo.data)
    inv = np.linalg.inv(np.eye(4)[None] - blocks)
    return sp.bsr_matrix((inv, np.arange(n), np.arange(n + 1)), shape=P_rr.shape).tocsr()


def spectral_radius(P, tol=1e-3, _split=None):
    """Spectral radius of one colour's transfer operator ``P`` (ARPACK, or dense when small).

    Uses ``rho(P) = sqrt(rho(P_br P_rb))`` (:mod:`sslpv_gl.steady`, "Solver"): the
    reduced operator has no ``+-`` pairs, so ARPACK's largest-modulus Ritz
    value converges in one or two restarts. The start vector is a seeded
    random one, so no symmetry of the scene hides the dominant mode.
    Returns a float.
    """
    n = P.shape[0]
    if _split is None:
        N = round((n // 4) ** (1.0 / 3.0))
        _split = _Split(P, *_red_black(N))
    return operator_radius(_split.reduced, _split.black.size, lambda v: P @ v, n, _split.diag, tol,
                           dense_reduced=lambda: (_split.P_br @ _split.P_rb).toarray(), dense_full=P.toarray)


def operator_radius(reduced, m, full, n, diag, tol=1e-3, dense_reduced=None, dense_full=None):
    """``rho(P)`` from products alone: ``reduced`` (``m`` unknowns) and ``full`` (``n``), both callables.

    The route of :func:`spectral_radius` for any coding of ``P`` (the sparse matrices here, the
    matrix-free :mod:`sslpv_gl.stencil`): ``diag`` says whether ``P`` has the reflection's diagonal
    blocks (then ``rho`` is estimated on ``full``). ``dense_reduced`` / ``dense_full`` return the
    dense matrices for the small cases; without them they are assembled column by column.
    """
    if m == 0:
        return 0.0
    if diag:
        return _full_radius(full, n, tol, dense_full)
    if m <= _DENSE_EIG_MAX:
        Q = dense_reduced() if dense_reduced is not None else _dense(reduced, m)
        return float(np.sqrt(np.abs(np.linalg.eigvals(Q)).max()))
    op = spla.LinearOperator((m, m), matvec=reduced, dtype=np.float64)
    v0 = np.random.default_rng(12345).random(m) + 0.5
    try:
        w = spla.eigs(op, k=1, which="LM", tol=tol, ncv=min(20, m - 1), maxiter=200,
                      v0=v0, return_eigenvectors=False)
    except spla.ArpackNoConvergence as exc:
        w = exc.eigenvalues
        if w is None or len(w) == 0:
            _bad("steady_state", "ARPACK could not estimate the spectral radius of the transfer operator",
                 "pass check_spectrum=False to skip the check, or use propagate_until")
    except spla.ArpackError:
        # ARPACK stops when its Krylov space closes on an invariant subspace (seen as
        # "starting vector is zero" on a scene whose lit cells reach only part of the grid):
        # estimate the radius by power iteration on the reduced operator instead
        return _power_radius(reduced, v0)
    return float(np.sqrt(np.abs(w).max()))


def _dense(apply, m):
    """The ``m x m`` matrix of the linear map ``apply``, column by column."""
    return np.column_stack([apply(e) for e in np.eye(m)])


def _full_radius(full, n, tol, dense=None):
    """``rho(P)`` on ``P`` itself, for an operator with diagonal blocks (no ``rho(P)^2`` relation)."""
    if n <= 2 * _DENSE_EIG_MAX:
        A = dense() if dense is not None else _dense(full, n)
        return float(np.abs(np.linalg.eigvals(A)).max())
    v0 = np.random.default_rng(12345).random(n) + 0.5
    op = spla.LinearOperator((n, n), matvec=full, dtype=np.float64)
    try:
        # k = 2: the near +- pairs of the bipartite part are both kept in the Krylov space
        w = spla.eigs(op, k=2, which="LM", tol=tol, ncv=min(40, n - 1), maxiter=500, v0=v0,
                      return_eigenvectors=False)
    except (spla.ArpackNoConvergence, spla.ArpackError):
        return _power_radius(lambda y: full(full(y)), v0)
    return float(np.abs(w).max())


def _power_radius(apply, v, iterations=400):
    """sqrt of the growth rate of ``||Q^k v||`` (the reduced operator Q = P_br P_rb, or P^2) over ``iterations``."""
    v = v / np.linalg.norm(v)
    rate = 0.0
    for k in range(iterations):
        w = apply(v)
        norm = float(np.linalg.norm(w))
        if norm == 0.0:
            return 0.0                               # nilpotent on this start: the series converges
        rate = norm
        v = w / norm
    return float(np.sqrt(rate))
