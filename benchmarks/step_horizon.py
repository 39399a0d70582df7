"""How much light K propagation steps can deliver: the truth's path lengths beside SSLPV's energy after K steps.

SSLPV's propagation moves all light by exactly one cell per step (each step gathers a cell's radiance
from its six face neighbours; ``docs/diffusion_mapping.md``, Eq. (1)), and the image after ``K`` steps
accumulates the light of ages ``1..K``. A lattice that models transport therefore shows after ``K`` steps
the light whose path inside the medium is at most ``K`` cells long. This benchmark measures, per
sphere scene of the suite (``harness.reference.path_length``: a homogeneous, index-matched sphere),

* **truth <= K**: the share of the reference image's energy (over its mask, the three channels
  summed) carried by paths of at most ``K`` cells inside the medium, with its standard error, from the
  path-length tracer (which reproduces the committed Mitsuba references' energy,
  ``tests/test_path_length.py``);
* **SSLPV K / truth**: SSLPV's subsurface energy against the committed reference at grid ``N``: the
  paper's ``collision`` mapping with the paper's ``outside = vacuum`` and with ``absorb`` (no light
  crosses empty cells, so no light reaches the shading around the object, which has no counterpart
  in the truth), and the ``transport`` mapping (an extension: one step is one cell of path,
  ``docs/diffusion_mapping.md`` Sec. 11) with ``absorb``, and the share of its masked pixels with a
  negative channel;
* **outer ring**: the share of an image's masked energy in its outer ring (pixels beyond 7/8 of the
  largest distance of a masked pixel from the sphere's projected centre), the reference's beside
  SSLPV's: where the lattice's light has not travelled far, it lies next to the silhouette;
* **diffusion speed**: the medium's diffusion coefficient per cell of path, ``D = l_tr / 3`` cells
  (``l_tr = 1 / (sigma_t (1 - albedo g) dx)``, the reduced mean free path in cells), against the
  lattice's, ``D_lpv(k1)`` cells^2 per step (Eq. (9) there, ``k1`` from the collision mapping; at most
  0.2258 at ``k1 = 1``). Where ``D / D_lpv`` is large, diffusing light needs that many times more steps
  in the lattice than cells of path in the medium, and absorbs accordingly more on the way.

Usage: ``python benchmarks/step_horizon.py [--scenes A,B] [--grid 32] [--photons 65536] [--write]``
(about 5 minutes on 2 cores). ``--write`` writes ``docs/benchmarks/step_horizon.md``.

Limits: sphere scenes only (the tracer's); the grid's cells are taken as cubes of the medium box's x
extent over ``N``; the truth's share is of the whole masked image, not per pixel.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from page import Page  # noqa: E402

from harness.errors import InputError  # noqa: E402

STEPS = (8, 16, 32, 64, 128, 256, 512, 1024)


def eligible_scenes():
    """Suite scenes the path-length tracer models (homogeneous, index-matched spheres)."""
    from harness.reference import path_length as pl
    from harness.scene import list_scenes, load_scene

    out = []
    for name in list_scenes():
        try:
            pl.sphere_scene(load_scene(name))
        except InputError:
            continue
        out.append(name)
    return out


def truth_shares(sphere, mask, dx, photons, seed=0):
    """``{K: (share, se)}`` of the masked image energy with in-medium path <= K cells (channels summed)."""
    from harness.reference import path_length as pl

    edges = np.arange(0, max(STEPS) + 1) * dx
    runs = [pl.trace(sphere, c, edges, photons=photons, batches=16, seed=seed, mask=mask) for c in range(3)]
    energy = sum(r.batch_energy for r in runs)
    out = {}
    for k in STEPS:
        part = sum(r.batch_hist[:, :k].sum(axis=1) for r in runs)
        out[k] = pl._ratio(part, energy)
    return out


def diffusion_speed(sphere, dx):
    """Per channel: the medium's ``D = l_tr / 3`` (cells), the lattice's ``D_lpv(k1)`` (collision mapping)."""
    from sslpv_gl.material import lattice_diffusion, medium_diffusion

    args = (sphere.sigma_t, sphere.albedo, sphere.g, dx)
    return medium_diffusion(*args), lattice_diffusion(*args)


def outer_ring(sphere, mask):
    """The masked pixels beyond 7/8 of the largest masked distance from the sphere's projected centre."""
    from harness.reference import path_length as pl

    ix, iy, _ = pl.project(sphere.camera, sphere.centre[None])
    yy, xx = np.mgrid[0:mask.shape[0], 0:mask.shape[1]]
    r = np.hypot(xx - ix[0], yy - iy[0])
    return mask & (r > 0.875 * r[mask].max())


def ring_share(image, mask, ring):
    img = np.asarray(image, float).sum(axis=2)
    return float(img[ring].sum() / img[mask].sum())


def sslpv_energy(renderer, scene, ref, mask, ring, grid, outside, mapping="collision"):
    """``{K or 'steady': (energy ratio, outer-ring share)}`` of ``mapping`` with ``outside``."""
    from harness.metrics import compute
    from sslpv_gl.params import SSLPVParams

    def figures(r):
        img = np.asarray(r.subsurface, float)
        return (float(compute("energy_ratio", img, ref, mask).value), ring_share(img, mask, ring),
                float((img[mask] < 0).any(axis=-1).mean()))

    p = SSLPVParams(N=grid, steps=max(STEPS), mapping=mapping, outside=outside)
    out = {k: figures(r) for k, r in zip(STEPS, renderer.render_steps(scene, p, list(STEPS)))}
    out["steady"] = figures(renderer.render(scene, p.replace(steps="steady")))
    return out


def main(argv=None):
    from harness.calibration.run import _reference
    from harness.io.images import read_exr
    from harness.reference import path_length as pl
    from sslpv_gl.renderer import SSLPVRenderer

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", help="comma-separated scene names (default: every sphere scene of the suite)")
    ap.add_argument("--grid", type=int, default=32, help="the LPV grid N")
    ap.add_argument("--photons", type=int, default=1 << 16, help="photons per light and channel")
    ap.add_argument("--write", action="store_true", help="write docs/benchmarks/step_horizon.md")
    args = ap.parse_args(argv)
    names = args.scenes.split(",") if args.scenes else eligible_scenes()
    renderer = SSLPVRenderer()
    page = Page("step_horizon", "How much light K propagation steps can deliver: the truth's path lengths and "
                "SSLPV's energy after K steps")
    page.gl_renderer = renderer.gl_renderer
    page.para(f"Grid N = {args.grid}; the paper's `collision` mapping; {args.photons} photons per light and "
              "channel for the truth's path lengths (`harness.reference.path_length`). \"truth <= K\": the share of "
              "the reference image's energy carried by paths of at most K cells inside the medium (± its standard "
              "error). \"vacuum\", \"absorb\": SSLPV's subsurface energy after K steps against the reference, with "
              "the paper's outside treatment and with empty cells absorbing. \"D / D_lpv\": how many times faster "
              "light diffuses in the medium (per cell of path) than in the lattice (per step), per channel.")
    summary = []
    for name in names:
        try:
            scene, folder = _reference(name, None)
            sphere = pl.sphere_scene(scene)
        except InputError as exc:
            print(f"error: {exc}", file=sys.stderr)
            raise SystemExit(2) from None
        ref = read_exr(folder / "subsurface.exr")["rgb"]
        mask = read_exr(folder / "mask.exr")["rgb"][..., 0] >= 0.999
        dx = float(scene.medium.bbox_max[0] - scene.medium.bbox_min[0]) / args.grid
        shares = truth_shares(sphere, mask, dx, args.photons)
        d_med, d_lat = diffusion_speed(sphere, dx)
        ring = outer_ring(sphere, mask)
        vac = sslpv_energy(renderer, scene, ref, mask, ring, args.grid, "vacuum")
        ab = sslpv_energy(renderer, scene, ref, mask, ring, args.grid, "absorb")
        tr = sslpv_energy(renderer, scene, ref, mask, ring, args.grid, "absorb", mapping="transport")
        across = 2.0 * sphere.radius / dx
        page.heading(name)
        page.para(f"Sphere {across:.1f} cells across; reduced mean free path "
                  f"{' / '.join(f'{3 * d:.2f}' for d in d_med)} cells (R / G / B); D = l_tr / 3 = "
                  f"{' / '.join(f'{d:.3f}' for d in d_med)}, D_lpv = {' / '.join(f'{d:.3f}' for d in d_lat)}: "
                  f"D / D_lpv = {' / '.join(f'{a / b:.1f}' for a, b in zip(d_med, d_lat))}.")
        truth_ring = ring_share(ref, mask, ring)
        rows = [[str(k), f"{shares[k][0]:.3f} ± {shares[k][1]:.3f}", f"{vac[k][0]:.3g}", f"{ab[k][0]:.3g}",
                 f"{ab[k][1]:.2f}", f"{tr[k][0]:.3g}", f"{tr[k][1]:.2f}", f"{tr[k][2]:.3f}"] for k in STEPS]
        rows.append(["steady", "1", f"{vac['steady'][0]:.3g}", f"{ab['steady'][0]:.3g}", f"{ab['steady'][1]:.2f}",
                     f"{tr['steady'][0]:.3g}", f"{tr['steady'][1]:.2f}", f"{tr['steady'][2]:.3f}"])
        page.table(["K", "truth <= K", "collision vacuum", "collision absorb", "its outer ring", "transport absorb",
                    "its outer ring", "its pixels < 0"], rows,
                   note=f"The reference's outer ring holds {truth_ring:.2f} of its energy.")
        summary.append([name, f"{across:.0f}", f"{float(np.mean(d_med / d_lat)):.1f}",
                        f"{shares[32][0]:.3f}", f"{vac[32][0]:.3g}", f"{ab[32][0]:.3g}", f"{tr[32][0]:.3g}",
                        f"{ab['steady'][0]:.3g}", f"{tr['steady'][0]:.3g}", f"{truth_ring:.2f} / {ab[32][1]:.2f}"])
    page.heading("Summary at K = 32")
    page.table(["scene", "cells across", "D / D_lpv (mean)", "truth <= 32", "collision vacuum K = 32",
                "collision absorb K = 32", "transport absorb K = 32", "collision absorb steady",
                "transport absorb steady", "outer ring: truth / collision absorb K = 32"], summary)
    page.finish(args.write)


if __name__ == "__main__":
    main()
