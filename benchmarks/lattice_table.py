"""Steady-state lattice Green's function against diffusion theory (docs/diffusion_mapping.md, Sec. 5-6).

For a point source (``c00`` only) in an unbounded homogeneous lattice, the
steady state ``sum_k T^k s`` is computed exactly on a periodic grid through
the symbol of Eq. (2) (``sslpv_gl.lattice.periodic_steady_state``), with
``sigma_lpv`` and the fluence scale of the ``diffusion`` mapping
(Eq. (16), (18)) for the given ``kappa = sigma_tr dx`` and ``k1``. It prints
``phi_lattice / phi_diffusion`` at the cell centres with ``3 <= r/dx <= 10``
along the axes, the face diagonals and the body diagonals, and the worst
``|ratio - 1|``:

1. against ``k1`` at ``kappa = 0.1`` and ``0.3`` (the choice ``k1 = -1`` of
   the mapping, docs Sec. 5);
2. against ``kappa`` at the mapping's ``k1`` (the resolution the mapping
   needs, docs Sec. 6).

The lattice is scale free: with the ``diffusion`` mapping the result depends
on ``kappa`` and ``k1`` only, not on the medium or ``dx`` separately.

Run: ``.venv/bin/python benchmarks/lattice_table.py`` (about two minutes on
two cores; ``--grid`` sets the periodic grid, default 96, 128 for
``kappa < 0.1`` so that the periodic images stay negligible).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sslpv_gl import diffusion, lattice  # noqa: E402

DIRECTIONS = {"axis": (1, 0, 0), "face diag": (1, 1, 0), "body diag": (1, 1, 1)}


def green_ratios(kappa, k1, N):
    """``{direction: (r, ratio)}`` of the mapped lattice fluence to Eq. (14)'s Green's function.

    Medium: ``dx = 1``, ``g = 0``, ``sigma_t' = 1`` and ``sigma_a`` chosen so
    that ``sigma_tr = kappa`` (any medium with the same ``kappa`` gives the
    same ratios).
    """
    sigma_a = kappa * kappa / 3.0                       # sigma_tr^2 = 3 sigma_a sigma_t'
    sigma_t, albedo = 1.0, 1.0 - sigma_a                # sigma_t' = sigma_t (g = 0) = 1
    m = diffusion.diffusion_mapping(sigma_t, albedo, 0.0, 1.0, k1)
    c = np.zeros((N, N, N, 4))
    c[0, 0, 0, 0] = 1.0                                  # s = 1, P = sqrt(4 pi)
    U = lattice.periodic_steady_state(c, k1, float(m["sigma_lpv"]))[..., 0]
    D = 1.0 / 3.0
    out = {}
    for name, d in DIRECTIONS.items():
        rows = []
        for j in range(1, 11):
            off = np.array(d) * j
            r = float(np.linalg.norm(off))
            if 3.0 <= r <= 10.0 + 1e-9:
                phi = float(m["fluence_scale"]) * U[off[2], off[1], off[0]]
                exact = np.sqrt(4 * np.pi) * np.exp(-kappa * r) / (4 * np.pi * D * r)
                rows.append((r, phi / exact))
        out[name] = np.array(rows)
    return out


def _line(label, res):
    worst = max(float(np.abs(v[:, 1] - 1).max()) for v in res.values())
    parts = [f"{n} {v[0, 1]:.3f}..{v[-1, 1]:.3f}" for n, v in res.items()]
    return f"{label}  worst {worst:.3f}   " + "   ".join(parts), worst


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid", type=int, default=96, help="periodic grid (128 is used for kappa < 0.1)")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    print("ratio phi_lattice / phi_diffusion at r/dx = 3 .. 10 (first..last point per direction)")
    for kappa in (0.1, 0.3):
        print(f"\n1. against k1, kappa = sigma_tr dx = {kappa}")
        for k1 in (1.0, 0.5, 0.0, -0.5, -1.0):
            print("   " + _line(f"k1 = {k1:+.1f}", green_ratios(kappa, k1, args.grid))[0])
    print(f"\n2. against kappa, k1 = {lattice.DIFFUSION_K1} (the diffusion mapping)")
    for kappa in (0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.7, 1.0):
        grid = max(args.grid, 128) if kappa < 0.1 else args.grid   # periodic images decay slowly
        print("   " + _line(f"kappa = {kappa:.2f}", green_ratios(kappa, lattice.DIFFUSION_K1, grid))[0])
    print(f"\n{time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    from page import run

    raise SystemExit(run(main, "lattice_table", "The steady-state lattice's Green's function against diffusion theory"))
