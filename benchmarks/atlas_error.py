"""Where the atlas gather's error comes from: the atlas's sampling of the surface, or the clustering of its links.

Carr, Hall & Hart 2003 make two approximations on the way from the BSSRDF integral to a frame (their Sec. 4.1):

1. **Sampling**: the surface is the atlas's patches, one per texel inside its triangle, each at the surface point
   of its texel centre (:mod:`dipole_gl.atlas`), and the image is the scattered radiosity looked up bilinearly.
2. **Clustering**: a link to a MIP node takes the irradiance uniform over the node's cluster (the node's mean
   ``E_c``) while its throughput ``F_bc`` is exact (Eq. 10 summed over the cluster's base texels,
   :mod:`dipole_gl.links`).

Per scene (``--scenes``, at its committed small size), against the dense gather of the standard dipole (spacing
1 l', diffusion term alone), this prints the normalised squared error ``sum (x - y)^2 / sum y^2`` and the energy
ratio ``sum x / sum y`` over the pixels both cover, of:

* ``links``: the atlas gather at ``--budget`` (the GL image; its twin agrees pass by pass, ``tests/test_dipole_atlas.py``);
* ``midpoint``: the same atlas with every texel gathering every base texel (level 0, no clustering), from the
  twin (:func:`dipole_gl.links.throughput` for every receiver, in float64): approximation 1 alone;
* ``uniform E``: the links' gather of a flux uniform per unit area (``E = 1``) against the midpoint rule's of the
  same flux, over all patches: approximation 2 where the irradiance does not vary, which bounds what the links'
  own estimate of ``F_bc`` contributes.

``links`` minus ``midpoint`` is then the clustering's error with the scene's irradiance.

    .venv/bin/python benchmarks/atlas_error.py [--scenes a,b] [--budget 128:links=64] [--write]

Cost: the midpoint rule evaluates the kernel for every pair of texels (``size^4``; about 1.5 min at 128 on this
machine per scene).
"""

import argparse
import sys
import time

import numpy as np

from bench_atlas import budget_params, warm_up
from page import Page

from harness.regression.accuracy import small_scene
from dipole_gl import links, twin, twin_atlas
from dipole_gl.atlas_gather import exit_coefficients
from dipole_gl.medium import scene_material
from dipole_gl.params import DipoleParams
from dipole_gl.renderer import DipoleRenderer

SCENES = "apple_sphere,skin_torus,backlit_slab,jade_backlit_dielectric"
BUDGET = "128:links=64"
ROWS = 256                                   # receivers per block of the midpoint rule


def midpoint(at, m, *fluxes):
    """Per texel ``B_b = sum_t F_bt E_t`` with every base texel ``t`` (level 0), for each flux (P, 3) of ``E a``
    (the throughputs computed once for all)."""
    P = at.texels
    area = at.area.reshape(P)
    es = [np.where(area[:, None] > 0, f / np.maximum(area, 1e-300)[:, None], 0.0) for f in fluxes]
    out = [np.zeros((P, 3)) for _ in fluxes]
    for s in range(0, P, ROWS):
        rows = np.arange(s, min(s + ROWS, P))
        F = links.throughput(at, m, rows)[0].reshape(len(rows), P, 3)
        for o, e in zip(out, es):
            o[rows] = np.einsum("rpc,pc->rc", F, e)
    return out


def image(res, at, scatter, scene):
    f, mask = res.debug["fragments"], res.mask
    out = np.zeros(res.subsurface.shape[:2] + (3,))
    out[mask] = twin_atlas.shade(scatter.reshape(at.size, at.size, 3), f["uv"][mask], f["position"][mask],
                                 f["normal"][mask], scene.camera.origin, scene.boundary.eta)
    return out


def scores(x, y, both):
    a, b = x[both], y[both]
    return float(np.sum((a - b) ** 2) / np.sum(b ** 2)), float(a.sum() / b.sum())


def decompose(renderer, name, budget):
    scene = small_scene(name)
    dense = renderer.render(scene, "dipole", DipoleParams(terms="diffusion"))
    res = renderer.render(scene, "dipole", budget_params(budget), debug=True)
    d = res.debug
    at, lk = d["atlas"], d["links"]
    P = at.texels
    flux, _ = twin.irradiance(at.position.reshape(P, 3), at.normal.reshape(P, 3), at.area.reshape(P), scene.lights,
                              scene.boundary.eta, d["flux"][..., 3])
    m = exit_coefficients(scene_material(scene), at.position.reshape(P, 3), at.normal.reshape(P, 3),
                          float(scene.boundary.eta))
    uniform = np.repeat(at.area.reshape(P, 1), 3, axis=1)
    t = time.perf_counter()
    full, mb = midpoint(at, m, twin_atlas.radiosity_map(at, flux)[0].reshape(P, 3), uniform)
    seconds = time.perf_counter() - t
    ref, both = dense.subsurface[..., :3], dense.mask & res.mask
    live = at.area.reshape(P) > 0
    lb = twin_atlas.gather(lk, twin_atlas.radiosity_map(at, uniform[None]))
    u_err = float(np.sum((lb[live] - mb[live]) ** 2) / np.sum(mb[live] ** 2))
    return [name, *scores(res.subsurface[..., :3], ref, both), *scores(image(res, at, full, scene), ref, both),
            u_err, float(lb[live].sum() / mb[live].sum()), seconds]


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default=SCENES, help=f"comma-separated suite scenes (default {SCENES})")
    ap.add_argument("--budget", default=BUDGET, help=f"SIZE:links=L or SIZE:level=l (default {BUDGET})")
    ap.add_argument("--write", action="store_true", help="write docs/benchmarks/atlas_error.md")
    args = ap.parse_args(argv)
    page = Page("atlas_error", "Where the atlas gather's error comes from: sampling or clustering",
                argv=[a for a in ([sys.argv[0]] + list(argv)) if a != "--write"])
    renderer = DipoleRenderer()
    page.gl_renderer = renderer.gl_renderer
    warm_up(renderer)
    rows = []
    for name in args.scenes.split(","):
        r = decompose(renderer, name, args.budget)
        rows.append([r[0]] + [f"{v:.3g}" for v in r[1:7]] + [f"{r[7]:.0f}"])
        print(f"  {rows[-1]}", file=sys.stderr)
    renderer.release()
    page.para(f"The standard dipole's atlas gather at `{args.budget}` against the dense gather (spacing 1 l', "
              "diffusion term), per scene at its committed small size: normalised squared error / energy ratio of "
              "the links' image, of the same atlas's midpoint rule (every texel gathering every base texel: the "
              "atlas's sampling alone) and of the links against the midpoint rule when the irradiance is uniform "
              "(over the atlas's patches). Seconds: the midpoint rule's gather (NumPy, float64).")
    page.table(["scene", "links: error", "links: energy", "midpoint: error", "midpoint: energy", "uniform E: error",
                "uniform E: energy", "midpoint [s]"], rows)
    page.finish(args.write)


if __name__ == "__main__":
    main()
