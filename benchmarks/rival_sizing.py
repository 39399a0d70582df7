"""The rivals' nightly configurations on every suite scene under the sizing rule (``fit = coarsen``): times and sizes.

Renders each suite scene at its committed small size with ``dipole`` and ``dirpole``, each with the
nightly's gathers (``harness/regression/nightly_matrix.toml``: dense at the default spacing, vertex at
density 0.5 and range 2) and ``fit = coarsen`` (``dipole_gl.sizing``), in one process and one GL context
(as the nightly does), and prints a markdown table: the setting used, the samples or vertices and pairs,
the gather's dispatches, the frame (sum of the stages' ms), the precomputation, the spot check against
the twin (``dipole_gl.check``: its difference and host ms) and the wall time of the whole render. A
configuration that fails prints its one-line error in the table instead.

    .venv/bin/python benchmarks/rival_sizing.py [--scenes a,b] [--methods dipole,dirpole] [--gathers dense,vertex]
"""

import argparse
import sys
import time

from harness.regression.accuracy import small_scene
from harness.scene import list_scenes
from dipole_gl.params import DipoleParams
from dipole_gl.renderer import DipoleRenderer

SETTINGS = {"dense": {}, "vertex": {"density": 0.5, "range": 2.0}}


def row(renderer, name, kernel, gather):
    scene = small_scene(name)
    params = DipoleParams(gather=gather, fit="coarsen", **SETTINGS[gather])
    t = time.perf_counter()
    try:
        res = renderer.render(scene, kernel, params)
    except Exception as exc:  # noqa: BLE001 -- the table reports every failure
        return f"| {name} | {kernel} | {gather} | failed: {type(exc).__name__}: {str(exc).splitlines()[0]} |||||||"
    wall = time.perf_counter() - t
    i = res.info
    used = f"spacing {i['spacing_used']:g}" if gather == "dense" else f"density {i['density_used']:g}"
    size = f"{i['samples']:,} samples" if gather == "dense" else f"{i['vertices']:,} vertices, {i['pairs']:,} pairs"
    c = i["check"]
    return (f"| {name} | {kernel} | {gather} | {used} | {size} | {i['dispatches']} | "
            f"{sum(res.timings_ms.values()) / 1e3:.2f} | {sum(res.precompute_ms.values()) / 1e3:.2f} | "
            f"{c['max_rel_diff']:.1e} / {c['ms'] / 1e3:.2f} | {wall:.1f} |")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", help="comma-separated scenes (default: the suite)")
    ap.add_argument("--methods", default="dipole,dirpole")
    ap.add_argument("--gathers", default="dense,vertex")
    args = ap.parse_args(argv)
    names = args.scenes.split(",") if args.scenes else list_scenes()
    print("| scene | method | gather | setting used | size | dispatches | frame s | precompute s | "
          "check: max diff / s | wall s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    renderer = DipoleRenderer()
    try:
        for name in names:
            for kernel in args.methods.split(","):
                for gather in args.gathers.split(","):
                    print(row(renderer, name, kernel, gather), flush=True)
                    print(f"  done {name} {kernel} {gather}", file=sys.stderr, flush=True)
    finally:
        renderer.release()


if __name__ == "__main__":
    main()
