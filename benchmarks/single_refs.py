"""Mitsuba's single-scattering images of the S^(1) validation cases -> ``tests/data/single/<case>.npz``.

``python benchmarks/single_refs.py [--spp 256] [--seeds 8] [--cases A,B]`` renders each case of
:data:`CASES` with Mitsuba's path tracer cut after the first scattering vertex and writes the
mean image, its per-pixel standard error (``std / sqrt(seeds)`` over independent seeds) and the
pixel coverage (the share of each pixel's footprint that sees the mesh) as a small ``.npz``,
which ``tests/test_dipole_single.py`` and ``benchmarks/single_scattering.py`` read.

Single scattering in Mitsuba (``max_depth`` counts path segments, a null interface counts none,
a refraction one, :mod:`harness.reference.mnee`): index-matched ``volpath`` with ``max_depth = 2``
(camera -> scattering vertex -> light); behind a smooth dielectric ``mneevolpath`` with
``max_depth = 4`` (camera -> refraction -> scattering vertex -> manifold connection, two segments).
:func:`check_depths` renders one depth less (black) and one more (brighter) to confirm it.

A case is a suite scene with its medium made grey (``sigma_t``, ``albedo``) and ``g = 0.5``,
its boundary index-matched or a smooth dielectric of ``eta = 1.3``, its light in front of or
behind the object, a slab possibly made thicker, at :data:`SIZE` (:func:`case_scene`).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

OUT = ROOT / "tests" / "data" / "single"
SIZE = 24
G = 0.5
FRONT = (0.6, 0.5, 2.4)
#: case -> (suite scene, eta, light position or None for the scene's own, sigma_t, albedo, thickness scale)
CASES = {
    "sphere_front_eta1": ("sphere_homogeneous", 1.0, None, 8.0, 0.95, 1.0),
    "sphere_front_eta13": ("sphere_homogeneous", 1.3, None, 8.0, 0.95, 1.0),
    "slab_back_eta1": ("backlit_slab", 1.0, None, 6.0, 0.95, 1.0),
    "slab_back_eta13": ("backlit_slab", 1.3, None, 6.0, 0.95, 1.0),
    "thick_front_eta1": ("backlit_slab", 1.0, FRONT, 6.0, 0.95, 3.0),
    "thick_front_eta13": ("backlit_slab", 1.3, FRONT, 6.0, 0.95, 3.0),
    "slab_front_eta1": ("backlit_slab", 1.0, FRONT, 6.0, 0.95, 1.0),
}


def case_scene(name):
    """The scene of case ``name`` (see the module docstring)."""
    from harness.scene import load_scene
    from harness.scene.load import Boundary, PointLight, scene_hash

    base, eta, light, sigma_t, albedo, thick = CASES[name]
    sc = load_scene(base).with_resolution(SIZE, SIZE)
    if thick != 1.0:                                   # the slab made thicker along z (the camera's axis)
        mesh = dataclasses.replace(sc.mesh, vertices=sc.mesh.vertices * np.array([1.0, 1.0, thick]))
        sc = dataclasses.replace(sc, mesh=mesh)
    m = sc.medium
    sc = sc.with_medium(sigma_t=np.full_like(m.sigma_t, sigma_t), albedo=np.full_like(m.albedo, albedo),
                        g=np.full_like(m.g, G))
    boundary = Boundary("index-matched") if eta == 1.0 else Boundary("dielectric", eta=eta, roughness=0.0)
    lights = sc.lights if light is None else (PointLight(tuple(light), sc.lights[0].intensity),)
    sc = dataclasses.replace(sc, name=name, boundary=boundary, lights=lights, content_hash="")
    return dataclasses.replace(sc, content_hash=scene_hash(sc))


def single_depth(scene):
    """Mitsuba's ``max_depth`` that keeps exactly the single-scattering paths of ``scene`` (module docstring)."""
    return 2 if scene.boundary.index_matched else 4


def render_single(scene, spp, seeds, max_depth=None):
    """``(mean, se)`` (H, W, 3) of Mitsuba at ``max_depth`` (default :func:`single_depth`) over ``seeds`` seeds."""
    from harness.reference import mitsuba_scene as ms

    mi = ms.use_variant()
    d = ms.build_scene_dict(scene, spp=spp, max_depth=single_depth(scene) if max_depth is None else max_depth)
    msc = mi.load_dict(d)
    imgs = np.stack([np.asarray(mi.render(msc, seed=1000 + k, spp=spp), np.float64)[..., :3] for k in range(seeds)])
    return imgs.mean(axis=0), imgs.std(axis=0, ddof=1) / np.sqrt(seeds)


def check_depths(scene, spp=16):
    """Mean image at ``single_depth - 1``, ``single_depth`` and ``+ 1`` (the first must be 0)."""
    d = single_depth(scene)
    return [float(render_single(scene, spp, 2, max_depth=k)[0].mean()) for k in (d - 1, d, d + 1)]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--check-depths", action="store_true", help="print the mean at one depth less and more")
    args = ap.parse_args(argv)
    from harness.reference.mitsuba_scene import coverage_mask

    OUT.mkdir(parents=True, exist_ok=True)
    for name in args.cases.split(","):
        sc = case_scene(name)
        t = time.perf_counter()
        if args.check_depths:
            print(name, "mean at depth d-1, d, d+1:", check_depths(sc), flush=True)
        mean, se = render_single(sc, args.spp, args.seeds)
        cov = coverage_mask(sc)
        np.savez_compressed(OUT / f"{name}.npz", mean=mean.astype(np.float32), se=se.astype(np.float32),
                            coverage=cov.astype(np.float32), spp=args.spp, seeds=args.seeds,
                            max_depth=single_depth(sc))
        full = cov >= 1.0
        print(f"{name}: {time.perf_counter() - t:.1f} s, mean {mean[full].mean():.5g}, "
              f"median rel SE {np.median(se[full] / np.maximum(mean[full], 1e-30)):.3g}", flush=True)


if __name__ == "__main__":
    main()
