"""Light that bypasses the object: SSLPV's image split by where its light travelled.

The lattice is linear, and ``outside = vacuum`` (the paper's treatment) differs from
``outside = interior`` (:mod:`sslpv_gl.boundary`) only in the transfers between two
empty cells, which ``interior`` cuts. Every lattice path either makes no such hop (it
stayed inside the medium, or stepped out to a surface cell and straight back) or makes
at least one. So, exactly,

    image(vacuum) = image(interior)            light that stayed in the medium
                  + [image(vacuum) - image(interior)]   light that crossed empty cells

per pixel, at any K. Per suite scene at N = 32 and K = 8, 32 (one propagation per
mode, ``render_steps``), the table prints the subsurface energy of each part against
the committed small reference (``baselines/refs``; "-" where a scene has none), the
bypass share ``1 - E(interior) / E(vacuum)``, and ``absorb`` (every empty cell a sink)
for comparison. Mapping: ``collision`` (the default), or ``--mapping``.

    python benchmarks/bypass_table.py [--scenes a,b] [--steps 8,32] [--mapping collision]

Limits: at a curved surface the outside-centred cells that hold surface points form a
shell; a hop between two neighbouring shell cells counts as bypass here, although part
of each such cell holds medium. The share therefore bounds the around-the-object light
from above by that lateral surface transport.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

MODES = ("vacuum", "interior", "absorb")


def _energy(res, ref):
    from harness.metrics import compute

    if ref is None:
        return float(res.subsurface[res.mask].sum())
    return float(compute("energy_ratio", res.subsurface, ref["subsurface"], ref["mask"]).value)


def main(argv=None):
    from harness.regression.accuracy import load_case_reference, small_scene
    from harness.scene import list_scenes
    from sslpv_gl.params import SSLPVParams
    from sslpv_gl.renderer import SSLPVRenderer

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", help="comma-separated scene names (default: the suite)")
    ap.add_argument("--steps", default="8,32", help="propagation step counts K")
    ap.add_argument("--mapping", default="collision")
    ap.add_argument("--grid", type=int, default=32)
    args = ap.parse_args(argv)
    scenes = args.scenes.split(",") if args.scenes else list_scenes()
    ks = [int(k) for k in args.steps.split(",")]
    renderer = SSLPVRenderer()
    print(f"GL renderer: {renderer.gl_renderer}; N = {args.grid}, mapping {args.mapping}; "
          "E = subsurface energy / reference's (absolute energy where no reference)")
    print(f"{'scene':<24} {'lit':<6} {'K':>3} {'E vacuum':>9} {'E stayed':>9} {'E crossed':>9} {'bypass':>7} "
          f"{'E absorb':>9}")
    for name in scenes:
        t0 = time.perf_counter()
        scene = small_scene(name)
        try:
            ref, _ = load_case_reference(scene)
        except Exception:                      # a scene without a committed reference: absolute energies
            ref = None
        lit = "back" if "back-lit" in scene.tags else "front"
        e = {}
        for mode in MODES:
            p = SSLPVParams(N=args.grid, steps=ks[0], mapping=args.mapping, outside=mode)
            for k, res in zip(ks, renderer.render_steps(scene, p, ks)):
                e[mode, k] = _energy(res, ref)
        for k in ks:
            v, i, a = e["vacuum", k], e["interior", k], e["absorb", k]
            share = 1.0 - i / v if v > 0 else float("nan")
            print(f"{name:<24} {lit:<6} {k:>3} {v:9.4g} {i:9.4g} {v - i:9.4g} {share:7.3f} {a:9.4g}"
                  + ("" if ref is not None else "   (no reference: absolute)"), flush=True)
        print(f"    ({time.perf_counter() - t0:.0f} s)", file=sys.stderr)


if __name__ == "__main__":
    main()
