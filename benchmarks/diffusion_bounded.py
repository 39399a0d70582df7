"""The ``diffusion`` mapping in bounded objects against diffusion theory.

Prints, for a slab (Eq. (D1) of :mod:`sslpv_gl.bounded`), a sphere with a point
source at its centre (Eq. (D2)) and one lit from one side (Eq. (D2')), the lattice's fluxes through the extrapolated
boundary against the diffusion solution with the same boundary, at N = 32 and 64.
The slab rows also run the render's injection (Eq. 1's lobe in the first inside
cell, ``lobe``) against the dipole's source at one transport mean free path, and a
second table splits the back-lit deficit into its terms: boundary mode, source depth
and how the render reads the far side (``docs/diffusion_mapping.md``, Sec. 7).

    python benchmarks/diffusion_bounded.py            # slabs, and spheres at N = 32
    python benchmarks/diffusion_bounded.py --sphere64 # also the spheres at N = 64 (minutes)
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sslpv_gl import bounded  # noqa: E402

#: (sigma_t, albedo, g) in units of the slab's thickness: the back-lit sphere of the bounded-domain study
#: (4.5 reduced mean free paths across, albedo 0.99, g = 0.3), a more absorbing slab, a dense one
SLABS = [(4.5 / 0.703, 0.99, 0.3), (10.0 / 0.91, 0.9, 0.0), (20.0, 0.99, 0.0)]
#: (sigma_t, albedo, g) in units of the sphere's radius, one per colour of one solve
SPHERES = [(2.25 / 0.703, 0.99, 0.3), (7.5 / 0.703, 0.99, 0.3), (10.0, 0.9, 0.0)]


def slab_rows():
    print("slab (N cells across), plane source; R, T = flux through the near / far extrapolated boundary")
    print(f"{'medium (st, a, g)':>24} {'N':>3} {'source':>6} {'kappa':>6} {'zb/dx':>6} "
          f"{'R lat':>7} {'R diff':>7} {'ratio':>6} {'T lat':>7} {'T diff':>7} {'ratio':>6}")
    for med in SLABS:
        for N in (32, 64):
            for lobe in (False, True):
                r = bounded.slab_lattice(*med, N, lobe=lobe)
                name = f"({med[0]:.2f}, {med[1]}, {med[2]})"
                print(f"{name:>24} {N:>3} {'lobe' if lobe else 'iso':>6} {r['kappa']:6.3f} {r['zb'] / r['dx']:6.2f} "
                      f"{r['R']:7.4f} {r['R_diff']:7.4f} {r['R'] / r['R_diff']:6.3f} "
                      f"{r['T']:7.4f} {r['T_diff']:7.4f} {r['T'] / r['T_diff']:6.3f}")


def deficit_rows():
    """The back-lit deficit's terms on the slab: boundary mode x source, against Eq. (D1)'s T."""
    print("back-lit slab terms (medium of the first row above): T = flux into the far sinks; T render = "
          "pi L A / P as the render reads the far side (last inside cell: Eq. (21) scale; first outside cell: "
          "Eq. (21) in the extrapolated layer, 1 in a sink; old out: Eq. (21) in a sink too, as before the sink fix; "
          "J in, J out: the same cells' fluence read as the exitance at the boundary, phi / (2 A), Eq. (D5), "
          "over the diffusion T; 0 in a sink)")
    print(f"{'outside':>12} {'source':>18} {'N':>3} {'T lat':>7} {'T diff':>7} {'ratio':>6} "
          f"{'T rend in':>9} {'T rend out':>10} {'out/diff':>8} {'old out':>8} {'J in':>6} {'J out':>6}")
    med = SLABS[0]
    for outside in ("extrapolated", "absorb"):
        for label, kw in (("iso at 1 mfp'", {}), ("lobe at surface", {"lobe": True}),
                          ("lobe at 1 mfp'", {"lobe": True, "lobe_depth_mfp": 1.0})):
            for N in (32, 64):
                r = bounded.slab_lattice(*med, N, outside=outside, **kw)
                print(f"{outside:>12} {label:>18} {N:>3} {r['T']:7.4f} {r['T_diff']:7.4f} "
                      f"{r['T'] / r['T_diff']:6.3f} {r['T_render_in']:9.4f} {r['T_render_out']:10.4f} "
                      f"{r['T_render_out'] / r['T_diff']:8.3f} {r['T_render_out_R']:8.4f} "
                      f"{r['T_exitance_in'] / r['T_diff']:6.3f} {r['T_exitance_out'] / r['T_diff']:6.3f}")


def sphere_rows(N):
    t = time.perf_counter()
    out, info = bounded.sphere_lattice(SPHERES, N)
    for med, o in zip(SPHERES, out):
        name = f"({med[0]:.2f}, {med[1]}, {med[2]})"
        print(f"{name:>24} {N:>3} {o['kappa']:6.3f} {o['zb'] * N / 2:6.2f} {o['escape']:7.4f} {o['escape_diff']:7.4f} "
              f"{o['escape'] / o['escape_diff']:6.3f}   {o['ratio'].min():.3f}..{o['ratio'].max():.3f}")
    print(f"    (N = {N}: {time.perf_counter() - t:.0f} s, Krylov iterations {info['iterations']})")


def side_rows(N, pole):
    t = time.perf_counter()
    out, info = bounded.sphere_lattice(SPHERES, N, depth_mfp=1.0, pole=pole)
    for med, o in zip(SPHERES, out):
        name = f"({med[0]:.2f}, {med[1]}, {med[2]})"
        print(f"{name:>24} {pole:>6} {N:>3} {o['kappa']:6.3f} {o['zb'] * N / 2:6.2f} {o['escape']:7.4f} {o['escape_diff']:7.4f} "
              f"{o['escape'] / o['escape_diff']:6.3f} {o['escape_far']:7.4f} {o['escape_far_diff']:7.4f} "
              f"{o['escape_far'] / o['escape_far_diff']:6.3f}")
    print(f"    (N = {N}, pole on a {pole}: {time.perf_counter() - t:.0f} s, Krylov iterations {info['iterations']})")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sphere64", action="store_true", help="also solve the spheres at N = 64 (minutes)")
    args = ap.parse_args(argv)
    slab_rows()
    print()
    deficit_rows()
    print("\nsphere (N cells across), point source at the centre; escape = flux through the extrapolated sphere;")
    print("phi ratio = lattice / diffusion fluence over the inside cells with 3 <= r/dx <= a/dx - 3")
    print(f"{'medium (st, a, g)':>24} {'N':>3} {'kappa':>6} {'zb/dx':>6} {'esc lat':>7} {'esc dif':>7} "
          f"{'ratio':>6}   phi ratio")
    sphere_rows(32)
    if args.sphere64:
        sphere_rows(64)
    print("\nsphere lit from one side: point source one reduced mean free path below the +x pole (Eq. (D2')); "
          "far = flux through the far hemisphere. pole: where the grid puts the pole, on a cell face (an even grid, "
          "as renders have) or on the centre of the first outside cell (an odd grid: a mask of cell centres puts "
          "that pole's surface half a cell inside the sphere)")
    print(f"{'medium (st, a, g)':>24} {'pole':>6} {'N':>3} {'kappa':>6} {'zb/dx':>6} {'esc lat':>7} {'esc dif':>7} "
          f"{'ratio':>6} {'far lat':>7} {'far dif':>7} {'ratio':>6}")
    for N in (32, 64) if args.sphere64 else (32,):
        for pole in ("face", "centre"):
            side_rows(N, pole)


if __name__ == "__main__":
    from page import run

    raise SystemExit(run(main, "diffusion_bounded", 'The diffusion mapping in a bounded domain: lattice against analytic diffusion'))
