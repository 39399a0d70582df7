"""The back-lit deficit in renders: per-channel subsurface energy against the reference.

Renders back-lit, index-matched suite scenes (default ``backlit_slab``, which has a
committed small reference) with SSLPV at N = 32, ``steps = steady``, ``skip = 0``,
for each mapping and outside mode, with the injection at the surface (the paper) and
moved one reduced mean free path inwards (``inject_offset = 1 / sigma_t'``, the
dipole's source depth; the mean over colours and cells of the scene's medium), and
prints E(SSLPV) / E(reference) per colour channel over the pixels both cover.
``benchmarks/diffusion_bounded.py`` prints the same terms on a slab lattice.

    python benchmarks/backlit_deficit.py [--scenes backlit_slab] [--grid 32]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

CASES = (("diffusion", "vacuum"), ("diffusion", "extrapolated"), ("diffusion", "absorb"), ("diffusion", "interior"),
         ("collision", "vacuum"), ("collision", "absorb"), ("collision", "interior"))


def main(argv=None):
    from harness.regression.accuracy import load_case_reference, small_scene
    from sslpv_gl.params import SSLPVParams
    from sslpv_gl.renderer import SSLPVRenderer

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default="backlit_slab")
    ap.add_argument("--grid", type=int, default=32)
    args = ap.parse_args(argv)
    renderer = SSLPVRenderer()
    print(f"GL renderer: {renderer.gl_renderer}; N = {args.grid}, steps = steady, skip = 0")
    print(f"{'scene':<16} {'mapping':<10} {'outside':<13} {'offset':>7}   E / E_ref (R, G, B)")
    for name in args.scenes.split(","):
        scene = small_scene(name)
        ref, _ = load_case_reference(scene)
        med = scene.medium
        st, a, g = (np.asarray(v, dtype=np.float64) for v in (med.sigma_t, med.albedo, med.g))
        offset = float(1.0 / np.mean(st * (1.0 - a) + st * a * (1.0 - g)))
        for mapping, outside in CASES:
            for off in (0.0, offset):
                p = SSLPVParams(N=args.grid, steps="steady", mapping=mapping, outside=outside, skip=0,
                                inject_offset=off)
                res = renderer.render(scene, p)
                m = np.asarray(ref["mask"], bool) & res.mask
                e = res.subsurface[m].sum(axis=0) / np.asarray(ref["subsurface"])[m].sum(axis=0)
                print(f"{name:<16} {mapping:<10} {outside:<13} {off:7.3f}   " + "  ".join(f"{v:.4f}" for v in e),
                      flush=True)


if __name__ == "__main__":
    main()
