"""One SSLPV propagation step ``P`` applied matrix-free, per colour, on red/black sub-lattices.

The operator of :func:`sslpv_gl.transfer.transfer_operator` (Borlum et al., HPG 2011, Sec. 3.2,
Eq. 3, Sec. 4) without its matrix: for a destination ``d`` and its six face neighbours ``s``
(``docs/conventions.md``, :func:`sslpv_gl.twin.propagate`)::

    c_d += M_s @ (exp(-0.5 (sigma_lpv[s] + sigma_lpv[d]) dx_axis) (1 - e_s e_d) (1 - r_dr)^[s in, d out]
                  * emit[s] S(s) c_s)                                                      (T1)
    c_s += r_dr exp(-sigma_lpv[s] dx_axis) M_{+o} F_o emit[s] S(s) c_s   per surface face (Eq. (R3))

``S(s) = diag(1, k1, k1, k1)``, ``k1 = (1 - sp[s]) + sp[s] g[s]`` (Eq. 3 on the source cell),
``M_s`` :func:`sslpv_gl.sh.propagation_matrices` (Sec. 4), nothing from outside the grid; ``e``
the ``empty`` mask (``outside = interior``), ``r_dr`` / ``inside`` the surface reflection of
:mod:`sslpv_gl.reflect`. The first step of the steady solve uses ``emit = 1`` (``first_step``).

Layout
------
The grid of one colour is split into the eight sub-lattices ``q = (pz, py, px)``, the cells
``[pz::2, py::2, px::2]``; a cell's parity ``(x + y + z) % 2`` is that of ``pz + py + px``, so
four sub-lattices are red (even) and four black. The face neighbour at offset ``o = +-1`` along
an axis of a cell at index ``i`` of ``q`` is at index ``i + floor((p + o) / 2)`` of the
sub-lattice with ``p`` flipped on that axis: every transfer in (T1) is one slice of one
sub-lattice onto a slice of another, so ``P_rb`` (red rows, black columns) and ``P_br`` are
applied without touching the other half. A vector in *parity layout* holds the red
sub-lattices, then the black ones, each ``(4, nz, ny, nx)``; ``N`` may be odd (the
sub-lattices then differ in size).

Precomputed per colour: per destination sub-lattice and direction the factor of (T1) on its
slice (the transmittance, ``1 - e_s e_d`` and ``1 - r_dr``: six ``(N, N, N)`` arrays in all),
``k1``, ``emit`` and ``emit k1`` per cell, and at the surface cells only the 4x4 blocks of Eq. (R3)
and ``E - I``, ``E = (I - P_rr)^{-1}``. A product applies the nonzero entries of each ``M_s``
(the entries below ``1e-12 max|M|``, the quadrature's noise where the paper prints 0, are
dropped as in ``transfer_operator``: 6 of 16 per matrix; keeping them changes a product by a
relative ~1e-16, rounding, and costs half as much work again) as 16 array operations per
sub-lattice and direction, in slabs of ~2^15 cells along z so that the temporaries stay in cache.

The steady solve (:func:`sslpv_gl.steady.steady_state`, "Solver") uses the reduced product
``(P_bb + P_br E P_rb) y`` on the black cells (:meth:`StencilOperator.reduced`; ``P_bb`` and
``E`` only with the reflection), which costs one product of ``P``. Solving the full system
``(I - P) x = b`` with the same products took twice the BiCGSTAB iterations and 2.5-3x the time
(N = 32 and 64, one colour of the sphere of ``benchmarks/bench_steady.py``), so only the reduced
system is used. The spectral radius is :func:`sslpv_gl.transfer.operator_radius` on these
products (ARPACK, its power-iteration fallback, and dense matrices assembled column by column for
the smallest grids).

Memory and time
---------------
One colour's operator holds about ``10 N^3`` float64 (the six factors, ``k1``, ``emit``,
``emit k1``, a slab buffer) plus the surface cells' blocks, against ``36 * 12`` bytes per cell and
colour for the CSR matrix (values and column indices), built for three colours at once.
``python benchmarks/bench_steady.py --steady-only --sizes 32 64 128 --operator sparse stencil
[--scenes ...]`` measured the steady solve of its sphere (rtol 1e-8; peak resident memory of a
fresh process that builds the scene and solves it once, 0.22-0.27 GiB of it at the call at
N = 128; 2-core shared VM, load average 1.5-7.5; "diff": max ``|sparse - stencil|`` of max c00)::

    scene     N   operator  total [s]  build [s]  spectrum [s]  solve [s]  BiCGSTAB it.  peak [GiB]  diff
    vacuum   32   sparse        0.8       0.26        0.20         0.37    37,37,34         0.13    3e-15
    vacuum   32   stencil       1.0       0.05        0.25         0.65    37,37,34         0.08
    vacuum   64   sparse       11.3       2.65        2.98         5.57    71,68,60         0.65    4e-14
    vacuum   64   stencil      10.4       0.09        3.25         6.83    71,68,60         0.25
    vacuum  128   sparse      161.4      26.97       31.78       101.47    128,119,103      4.53    6e-11
    vacuum  128   stencil     142.7       0.68       38.12       102.23    128,119,103      1.52
    absorb  128   stencil     116.8       1.08       41.72        71.60    90,78,61         1.59
    interior 128  stencil     114.7       1.46       43.11        67.69    91,72,56         1.56
    rdr      64   sparse       29.2       4.36       17.23         7.51    77,70,64         1.02    2e-14
    rdr      64   stencil      25.0       0.14       16.69         7.95    77,70,64         0.54
    rdr     128   sparse      394.1      47.52      213.84       131.40    141,119,90       7.51    5e-09
    rdr     128   stencil     346.5       1.19      230.33       113.30    137,114,90       3.79

Every N = 128 solve reached the full system's relative residual 1e-8 (``info["residual"]``).
The peak is the spectral check's: ARPACK's basis of ``ncv = 20`` vectors of the reduced system
(``k = 2``, ``ncv = 40`` vectors of the full one with ``rdr``, whose check dominates its time
too); during the BiCGSTAB solve itself about half as much was held (``tracemalloc`` at N = 48).

Limits
------
* One product costs about as much as a CSR product at large ``N`` and more at small ``N``
  (Python's overhead per slice: 768 array operations per product at any ``N``), hence
  ``operator = "auto"`` keeps the sparse matrices below :data:`sslpv_gl.steady.STENCIL_MIN_N`.
* Float64, one thread (NumPy's array operations).
* ``matrices`` is any ``(6, 4, 4)``; the work grows with its number of entries above the drop.
"""

from __future__ import annotations

import itertools

import numpy as np

from .sh import SOURCE_OFFSETS, neighbour_slices, propagation_matrices, scatter_factors
from .transfer import _DROP, _bad, _dx, _finite, _grid_size, _material, operator_radius

__all__ = ["StencilOperator", "stencil_operator"]

#: Cells per slab of a sub-lattice in one pass of the product (fits the temporaries in a core's L2 cache).
_CHUNK = 1 << 15
#: The eight sub-lattices ``(pz, py, px)`` (cells ``[pz::2, py::2, px::2]``), red (even parity) first.
_BLOCKS = tuple(sorted(itertools.product((0, 1), repeat=3), key=lambda q: (sum(q) % 2, q)))


def stencil_operator(sigma_lpv, sigma_s_prime, g, dx, colour, matrices=None, emit=None, empty=None, r_dr=0.0,
                     inside=None):
    """``P`` of one colour (0, 1, 2) as a :class:`StencilOperator`; arguments as :func:`transfer_operator`."""
    N = _grid_size(sigma_lpv, sigma_s_prime, g)
    sig, spr, gg = _material(sigma_lpv, sigma_s_prime, g, N)
    em = None if emit is None else _material(emit, 0.0, 0.0, N)[0][..., colour]
    emp = None if empty is None else _material(empty, 0.0, 0.0, N)[0][..., colour]
    mats = propagation_matrices() if matrices is None else np.asarray(matrices, dtype=np.float64)
    if mats.shape != (6, 4, 4):
        _bad("matrices", f"shape {mats.shape} is not (6, 4, 4)", "pass propagation_matrices()")
    _finite("matrices", mats)
    k1 = scatter_factors(spr[..., colour], gg[..., colour])[..., 1]
    ins = np.asarray(inside, dtype=bool) if (r_dr and inside is not None) else None
    return StencilOperator(sig[..., colour], k1, _dx(dx), mats, em, emp, float(r_dr), ins)


class StencilOperator:
    """``P`` for one colour, applied by slices on the eight sub-lattices ``[pz::2, py::2, px::2]``.

    Vectors are in *parity layout*: the four red sub-lattices, then the four black ones, each
    stored ``(4, nz, ny, nx)`` (coefficient first) and flattened; :meth:`to_parity` and
    :meth:`from_parity` convert an ``(N, N, N, 4)`` grid. ``n_red``, ``n_black``: unknowns of each.
    """

    def __init__(self, sig, k1, dxs, mats, em=None, emp=None, r_dr=0.0, ins=None):
        N = sig.shape[0]
        self.N = N
        self.shapes = {q: tuple(len(range(p, N, 2)) for p in q) for q in _BLOCKS}
        sizes = {q: 4 * int(np.prod(s)) for q, s in self.shapes.items()}
        self.offsets, off = {}, 0
        for q in _BLOCKS:
            self.offsets[q] = off
            off += sizes[q]
        self.n = off
        self.red, self.black = _BLOCKS[:4], _BLOCKS[4:]
        self.n_red = sum(sizes[q] for q in self.red)
        self.n_black = self.n - self.n_red
        self.products = 0                      # reduced products applied (each ~ one full product)

        def block(a, q):
            return np.ascontiguousarray(a[q[0]::2, q[1]::2, q[2]::2])

        # per source cell: band 0 times emit, band 1 times emit k1 (Eq. 3), as S(s) of the module docstring
        self.k1 = {q: block(k1, q) for q in _BLOCKS}
        self.em = None if em is None else {q: block(em, q) for q in _BLOCKS}
        self.ek = None if em is None else {q: self.em[q] * self.k1[q] for q in _BLOCKS}

        # the nonzero entries of each M_s, grouped by row: [(a, [(b, m_ab), ...]), ...]
        drop = _DROP * max(float(np.abs(mats).max()), np.finfo(float).tiny)
        self.rows = []
        for s in range(6):
            rows = []
            for a in range(4):
                terms = [(b, float(mats[s, a, b])) for b in range(4) if abs(mats[s, a, b]) > drop]
                if terms:
                    rows.append((a, terms))
            self.rows.append(rows)

        # per destination sub-lattice and source direction: the source sub-lattice, the two slices and the
        # factor on the destination's slice, exp(-0.5 (sigma[s] + sigma[d]) dx_axis) (1 - e_s e_d) (1 - r_dr)
        self.pieces = {q: [] for q in _BLOCKS}
        cross = None
        for s, offset in enumerate(SOURCE_OFFSETS):
            axis = int(np.flatnonzero(offset)[0])
            dst, src = neighbour_slices(offset)
            a = np.zeros((N, N, N))
            a[dst] = np.exp(-0.5 * (sig[src] + sig[dst]) * dxs[axis])
            if emp is not None:
                a[dst] *= 1.0 - emp[src] * emp[dst]
            if ins is not None:
                cross = ins[src] & ~ins[dst]
                a[dst] *= np.where(cross, 1.0 - r_dr, 1.0)
            ax = 2 - axis                                    # array axis of x, y, z
            o = int(offset[axis])
            for q in _BLOCKS:
                p = q[ax]
                qs = tuple(1 - v if i == ax else v for i, v in enumerate(q))
                shift = (p + o) // 2                         # source index along ax = destination index + shift
                lo, hi = max(0, -shift), min(self.shapes[q][ax], self.shapes[qs][ax] - shift)
                if hi <= lo:
                    continue
                dsl, ssl = [slice(None)] * 3, [slice(None)] * 3
                dsl[ax], ssl[ax] = slice(lo, hi), slice(lo + shift, hi + shift)
                att = np.ascontiguousarray(block(a, q)[tuple(dsl)])
                self.pieces[q].append((s, qs, tuple(dsl), tuple(ssl), att))
        del a, cross

        # Eq. (R3) of sslpv_gl.reflect: per surface cell a 4x4 block acting on S(s) c_s
        self.diag = {}
        if ins is not None and r_dr:
            from .reflect import AXIS_COEFF, surface_faces

            faces = [surface_faces(ins, offset) for offset in SOURCE_OFFSETS]
            surf = np.flatnonzero(np.logical_or.reduce(faces).ravel())     # the surface cells only
            D = np.zeros((surf.size, 4, 4))
            for s, offset in enumerate(SOURCE_OFFSETS):
                axis = int(np.flatnonzero(offset)[0])
                flip = np.ones(4)
                flip[AXIS_COEFF[axis]] = -1.0                # F_o: the lobe mirrored about the face
                w = faces[s].ravel()[surf] * np.exp(-sig.ravel()[surf] * dxs[axis]) * r_dr
                D += w[:, None, None] * (mats[s] * flip[None, :])
            z, y, x = np.unravel_index(surf, (N, N, N))
            for q in _BLOCKS:
                sel = (z % 2 == q[0]) & (y % 2 == q[1]) & (x % 2 == q[2])
                sel[sel] = np.any(D[sel] != 0.0, axis=(1, 2))
                if sel.any():
                    _, ny, nx = self.shapes[q]
                    self.diag[q] = (((z[sel] // 2) * ny + y[sel] // 2) * nx + x[sel] // 2, D[sel])
            del faces, D
        self.has_diag = bool(self.diag)
        # E = (I - P_rr)^{-1} on the red surface cells, stored as E - I (the identity elsewhere)
        self.e_minus_i = {}
        for q in self.red:
            if q in self.diag:
                idx, Dq = self.diag[q]
                scale = np.ones((idx.size, 4))
                if self.em is not None:
                    scale[:, 0] = self.em[q].reshape(-1)[idx]
                    scale[:, 1:] = self.ek[q].reshape(-1)[idx, None]
                else:
                    scale[:, 1:] = self.k1[q].reshape(-1)[idx, None]
                B = Dq * scale[:, None, :]
                self.e_minus_i[q] = (idx, np.linalg.inv(np.eye(4)[None] - B) - np.eye(4)[None])
        self._buf = np.empty(max(sizes.values()) // 4)
        self._buf2 = np.empty(max(sizes.values()) // 4)
        self._chunk(_CHUNK)

    def _chunk(self, cells):
        """Split each destination sub-lattice into slabs of about ``cells`` cells along z (cache-sized work)."""
        self.chunks = {}
        for q in _BLOCKS:
            nz, ny, nx = self.shapes[q]
            step = max(1, cells // max(ny * nx, 1))
            out = []
            for z0 in range(0, nz, step):
                z1 = min(nz, z0 + step)
                work = []
                for s, qs, dsl, ssl, att in self.pieces[q]:
                    lo, hi = dsl[0].indices(nz)[:2]
                    shift = ssl[0].indices(10**9)[0] - lo
                    a, b = max(lo, z0), min(hi, z1)
                    if b <= a:
                        continue
                    work.append((s, qs, (slice(a - z0, b - z0),) + dsl[1:], (slice(a + shift, b + shift),) + ssl[1:],
                                 att[a - lo:b - lo]))
                out.append((z0, z1, work))
            self.chunks[q] = out

    # ------------------------------------------------------------ layout

    def view(self, v, q, first=None):
        """The ``(4, nz, ny, nx)`` view of sub-lattice ``q`` in ``v`` (a full vector, or a red/black half)."""
        first = self.red[0] if first is None else first
        o = self.offsets[q] - self.offsets[first]
        return v[o:o + 4 * int(np.prod(self.shapes[q]))].reshape((4,) + self.shapes[q])

    def to_parity(self, grid):
        """``(N, N, N, 4)`` -> flat vector in parity layout (red cells, then black)."""
        g = np.asarray(grid, dtype=np.float64).reshape(self.N, self.N, self.N, 4)
        return np.concatenate([np.moveaxis(g[q[0]::2, q[1]::2, q[2]::2], -1, 0).ravel() for q in _BLOCKS])

    def from_parity(self, v):
        """Flat vector in parity layout -> ``(N, N, N, 4)``."""
        g = np.empty((self.N, self.N, self.N, 4))
        for q in _BLOCKS:
            g[q[0]::2, q[1]::2, q[2]::2] = np.moveaxis(self.view(v, q), 0, -1)
        return g

    # ------------------------------------------------------------ products

    def _scaled(self, v, qs, first_step):
        """``S(s) c`` of the cells of ``qs`` in ``v``, with ``emit`` unless ``first_step`` -> dict of arrays."""
        out = {}
        v = np.asarray(v, dtype=np.float64)
        for q in qs:
            c = self.view(v, q, qs[0])
            sc = np.empty_like(c)
            if self.em is None or first_step:
                sc[0] = c[0]
                np.multiply(c[1:], self.k1[q], out=sc[1:])
            else:
                np.multiply(c[0], self.em[q], out=sc[0])
                np.multiply(c[1:], self.ek[q], out=sc[1:])
            out[q] = sc
        return out

    def _gather(self, dst, sc, out):
        """``out`` (a red or black half vector) = what the cells of ``dst`` receive from the sources ``sc``."""
        for q in dst:
            o = self.view(out, q, dst[0])
            o.fill(0.0)
            for z0, z1, work in self.chunks[q]:
                oc = o[:, z0:z1]
                for s, qs, dsl, ssl, att in work:
                    src = sc[qs]
                    tmp = self._buf[:att.size].reshape(att.shape)
                    tmp2 = self._buf2[:att.size].reshape(att.shape)
                    for a, terms in self.rows[s]:
                        b, m = terms[0]
                        np.multiply(src[b][ssl], m, out=tmp)
                        for b, m in terms[1:]:
                            np.multiply(src[b][ssl], m, out=tmp2)
                            tmp += tmp2
                        tmp *= att
                        oc[a][dsl] += tmp
        return out

    def _add_diag(self, dst, sc, out):
        """``out += D S c`` on the surface cells of ``dst`` (Eq. (R3))."""
        for q in dst:
            if q in self.diag:
                idx, Dq = self.diag[q]
                o = self.view(out, q, dst[0]).reshape(4, -1)
                o[:, idx] += np.einsum("nab,bn->an", Dq, sc[q].reshape(4, -1)[:, idx])
        return out

    def apply(self, v, first_step=False):
        """``P v`` for ``v`` in parity layout; ``first_step``: every cell emits (step 1 of the twin)."""
        v = np.asarray(v, dtype=np.float64)
        out = np.empty(self.n)
        r, b = out[:self.n_red], out[self.n_red:]
        sr = self._scaled(v[:self.n_red], self.red, first_step)
        sb = self._scaled(v[self.n_red:], self.black, first_step)
        self._gather(self.red, sb, r)
        self._gather(self.black, sr, b)
        if self.has_diag:
            self._add_diag(self.red, sr, r)
            self._add_diag(self.black, sb, b)
        return out

    def matvec(self, c, first_step=False):
        """``P c`` in the ordering of :func:`sslpv_gl.transfer.transfer_operator` (flat or ``(N, N, N, 4)``)."""
        c = np.asarray(c, dtype=np.float64)
        out = self.from_parity(self.apply(self.to_parity(c), first_step))
        return out.reshape(c.shape)

    def apply_e(self, v):
        """``E v = (I - P_rr)^{-1} v`` for a red half vector (``v`` itself without reflection)."""
        if not self.e_minus_i:
            return v
        v = np.array(v, dtype=np.float64, copy=True)
        for q, (idx, Em) in self.e_minus_i.items():
            c = self.view(v, q, self.red[0]).reshape(4, -1)
            c[:, idx] += np.einsum("nab,bn->an", Em, c[:, idx])
        return v

    def rb(self, y):
        """``P_rb y``: the red cells' share of ``P`` applied to a black half vector."""
        return self._gather(self.red, self._scaled(y, self.black, False), np.empty(self.n_red))

    def br(self, x):
        """``P_br x``: the black cells' share of ``P`` applied to a red half vector."""
        return self._gather(self.black, self._scaled(x, self.red, False), np.empty(self.n_black))

    def reduced(self, y):
        """``(P_bb + P_br E P_rb) y`` on a black half vector (:class:`sslpv_gl.transfer._Split`)."""
        self.products += 1
        out = self.br(self.apply_e(self.rb(y)))
        if self.has_diag:
            self._add_diag(self.black, self._scaled(y, self.black, False), out)
        return out

    # ------------------------------------------------ the steady solve's pieces (sslpv_gl.steady)

    def vec(self, grid):
        """As :meth:`to_parity`."""
        return self.to_parity(grid)

    def grid(self, v):
        """As :meth:`from_parity`."""
        return self.from_parity(v)

    def step(self, v, first_step=False):
        """One step ``P v`` in parity layout (as :meth:`apply`)."""
        return self.apply(v, first_step)

    def rhs(self, b):
        """Right-hand side of the reduced system, ``b_b + P_br E b_r``."""
        return b[self.n_red:] + self.br(self.apply_e(b[:self.n_red]))

    def expand(self, b, xb):
        """The full solution from the black cells' ``xb``: ``x_r = E (b_r + P_rb x_b)``."""
        return np.concatenate([self.apply_e(b[:self.n_red] + self.rb(xb)), xb])

    def radius(self, tol=1e-3):
        """``rho(P)`` (:func:`sslpv_gl.transfer.operator_radius`, matrix-free)."""
        return operator_radius(self.reduced, self.n_black, self.apply, self.n, self.has_diag, tol)
