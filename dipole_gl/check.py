"""Every rival render checks itself: a few seeded random points recomputed by the NumPy twin.

After each frame the renderer recomputes :data:`CHECK_POINTS` points of its own result with
:mod:`dipole_gl.twin` (float64) and compares:

* dense gather: covered pixels drawn with ``numpy.random.default_rng(CHECK_SEED)``; the twin
  takes the G-buffer's exit point, normal and light visibility there, the surface samples and
  the irradiance pass's visibility, and evaluates the whole gather (far field over every
  sample, near field, exit Fresnel), :func:`dipole_gl.twin.dense_gather`;
* hierarchical gather: covered pixels drawn as for the dense gather; the twin recomputes the
  irradiance of the octree's samples, their aggregates (:func:`dipole_gl.octree.aggregate`) and the
  descent at the same ``epsilon`` (:func:`dipole_gl.twin_tree.tree_gather`);
* vertex gather: scattering vertices that the display mesh reads (so they reach covered
  pixels), drawn the same way; the twin evaluates their neighbourhood sums ``B``,
  :func:`dipole_gl.twin.vertex_gather` (the raster pass that interpolates ``B`` is not checked);
* atlas gather: covered pixels drawn as for the dense gather; the twin recomputes pass 1 (the
  irradiance of every atlas texel, the MIP-mapped radiosity map), pass 2 at the texels that the
  pixels' bilinear lookups read and pass 3 at the pixels' atlas coordinates
  (:mod:`dipole_gl.twin_atlas`; the raster of pass 3 is not checked, its coordinates are read back);
* single scattering (``terms`` = ``both`` or ``single``, either gather): covered pixels drawn
  the same way; :func:`dipole_gl.single_twin.single_scattering` recomputes S^(1) there from the
  G-buffer's exit points and the light atlas read back (the atlas's raster is not checked).

The result is refused (:class:`harness.errors.ResultRefused`, one line) when
``|GL - twin| > CHECK_RTOL * scale`` at any checked point and colour, ``scale`` the largest
``|twin|`` or ``|GL|`` of that colour over the checked points. GL runs in float32: on the suite
the difference is at most 2e-5 of the scale (``tests/test_dipole_gl.py``); a gather that
drops or repeats a chunk of its sum is off by far more than :data:`CHECK_RTOL`.

Cost (recorded in ``info["check"]``: points, twin kernel evaluations, host ms): the twin's
irradiance over every sample (dense) or vertex, plus per checked point the gather's kernel
evaluations, i.e. ``CHECK_POINTS / pixels`` of the frame's gather work.

Limits: a sample of points, not every pixel: an error confined to a few pixels can pass.
"""

from __future__ import annotations

import time

import numpy as np

from harness.errors import ResultRefused

from . import octree, single_twin, twin, twin_atlas, twin_tree

__all__ = ["CHECK_POINTS", "CHECK_SEED", "CHECK_RTOL", "check_dense", "check_vertex", "check_single", "check_tree", "check_atlas",
           "compare"]

#: Points recomputed by the twin per render.
CHECK_POINTS = 8
#: Seed of the points' draw (the same points every render of a scene and size).
CHECK_SEED = 0
#: The largest ``|GL - twin|``, relative to the checked points' scale, that is accepted.
CHECK_RTOL = 1e-3


def compare(gl, ref, what):
    """Largest ``|gl - ref|`` relative to the per-colour scale; :class:`ResultRefused` beyond :data:`CHECK_RTOL`."""
    gl, ref = np.asarray(gl, np.float64), np.asarray(ref, np.float64)
    scale = np.maximum(np.abs(ref).max(axis=0), np.abs(gl).max(axis=0)) if len(ref) else np.zeros(3)
    err = np.abs(gl - ref).max(axis=0) if len(ref) else np.zeros(3)
    rel = float(np.max(np.where(scale > 0, err / np.where(scale > 0, scale, 1.0), 0.0)))
    if not np.all(np.isfinite(gl)) or rel > CHECK_RTOL:
        raise ResultRefused(f"{what}: the GL result disagrees with the NumPy twin at {len(ref)} checked points "
                            f"(max |GL - twin| = {rel:.3g} of the largest value, tolerance {CHECK_RTOL:g}); "
                            "the result is not kept")
    return rel


def _draw(n):
    rng = np.random.default_rng(CHECK_SEED)
    return np.sort(rng.choice(n, size=min(CHECK_POINTS, n), replace=False)) if n else np.zeros(0, np.int64)


def check_dense(kernel, scene, mat, samples, flux_gl, gbuf, sub, spacing):
    """Recompute :data:`CHECK_POINTS` covered pixels of the dense gather (``gbuf``: position, normal,
    visibility, mask arrays (H, W, ...)) -> the record for ``info["check"]``."""
    t = time.perf_counter()
    eta = float(scene.boundary.eta)
    pos, nrm, area = samples
    flux, dirs = twin.irradiance(pos, nrm, area, scene.lights, eta, flux_gl[..., 3])
    rows, cols = np.nonzero(gbuf["mask"])
    pick = _draw(len(rows))
    r, c = rows[pick], cols[pick]
    ref = twin.dense_gather(kernel, gbuf["position"][r, c], gbuf["normal"][r, c], scene.camera.origin, (pos, nrm),
                            flux, dirs, mat, eta, spacing, scene.lights, gbuf["visibility"][r, c], chunk=1)
    rel = compare(sub[r, c], ref, f"{scene.name}: {kernel} dense gather")
    lit = np.any(flux > 0.0, axis=2).sum() if kernel == "dirpole" else int(np.any(flux > 0.0, axis=(0, 2)).sum())
    return {"points": len(pick), "max_rel_diff": rel, "tolerance": CHECK_RTOL, "ms": (time.perf_counter() - t) * 1e3,
            "twin_evaluations": int(len(pick) * lit + len(pos) * len(scene.lights))}


def check_vertex(kernel, scene, mat, pre, flux_gl, b):
    """Recompute ``B`` at :data:`CHECK_POINTS` scattering vertices that the display mesh reads -> ``info["check"]``."""
    t = time.perf_counter()
    eta = float(scene.boundary.eta)
    flux, dirs = twin.irradiance(pre.positions, pre.normals, pre.areas, scene.lights, eta, flux_gl[..., 3])
    shown = np.unique(pre.display_index)
    pick = shown[_draw(len(shown))]
    ref = twin.vertex_gather(kernel, pre, flux, dirs, mat, eta, vertices=pick)
    rel = compare(b[pick], ref, f"{scene.name}: {kernel} vertex gather")
    rows = int(np.diff(pre.offsets)[pick].sum())
    return {"points": len(pick), "max_rel_diff": rel, "tolerance": CHECK_RTOL, "ms": (time.perf_counter() - t) * 1e3,
            "twin_evaluations": int(rows * (len(scene.lights) if kernel == "dirpole" else 1)
                                    + len(pre.positions) * len(scene.lights))}


def check_single(scene, mat, views, size, atlas, gbuf, s1):
    """Recompute S^(1) at :data:`CHECK_POINTS` covered pixels (``gbuf``: position, normal, mask (H, W, ...);
    ``atlas`` from :func:`dipole_gl.single.read_atlas`, tile ``size``) -> the record for ``info["single"]``."""
    t = time.perf_counter()
    rows, cols = np.nonzero(gbuf["mask"])
    pick = _draw(len(rows))
    r, c = rows[pick], cols[pick]
    ref = single_twin.single_scattering(gbuf["position"][r, c], gbuf["normal"][r, c], scene.camera.origin, atlas,
                                        views, scene.lights, mat, float(scene.boundary.eta), size)
    rel = compare(s1[r, c], ref, f"{scene.name}: single scattering")
    return {"points": len(pick), "max_rel_diff": rel, "tolerance": CHECK_RTOL, "ms": (time.perf_counter() - t) * 1e3,
            "twin_evaluations": int(len(pick) * single_twin.N_MARCH * len(scene.lights))}


def check_tree(kernel, scene, mat, tree, flux_gl, gbuf, sub, spacing, epsilon):
    """Recompute :data:`CHECK_POINTS` covered pixels of the hierarchical gather (``tree``: the
    :class:`dipole_gl.octree.Octree`; ``gbuf`` as :func:`check_dense`) -> the record for ``info["check"]``."""
    t = time.perf_counter()
    eta = float(scene.boundary.eta)
    flux, dirs = twin.irradiance(tree.positions, tree.normals, tree.areas, scene.lights, eta, flux_gl[..., 3])
    agg = octree.aggregate(tree, flux, dirs)
    rows, cols = np.nonzero(gbuf["mask"])
    pick = _draw(len(rows))
    r, c = rows[pick], cols[pick]
    ref, visits = twin_tree.tree_gather(kernel, tree, agg, gbuf["position"][r, c], gbuf["normal"][r, c],
                                        scene.camera.origin, flux, dirs, mat, eta, spacing, scene.lights,
                                        gbuf["visibility"][r, c], epsilon)
    rel = compare(sub[r, c], ref, f"{scene.name}: {kernel} hierarchical gather")
    L = len(scene.lights)
    return {"points": len(pick), "max_rel_diff": rel, "tolerance": CHECK_RTOL, "ms": (time.perf_counter() - t) * 1e3,
            "twin_evaluations": int(visits.sum() * (L if kernel == "dirpole" else 1) + len(tree.positions) * L)}


def check_atlas(scene, atlas, lk, flux_gl, frag, sub):
    """Recompute :data:`CHECK_POINTS` covered pixels of the atlas gather (``frag``: the pass-3 fragments' position,
    normal, atlas coordinates and mask (H, W, ...)) -> the record for ``info["check"]``."""
    t = time.perf_counter()
    eta = float(scene.boundary.eta)
    P = atlas.texels
    flux, _ = twin.irradiance(atlas.position.reshape(P, 3), atlas.normal.reshape(P, 3), atlas.area.reshape(P),
                              scene.lights, eta, flux_gl[..., 3])
    mips = twin_atlas.radiosity_map(atlas, flux)
    rows, cols = np.nonzero(frag["mask"])
    pick = _draw(len(rows))
    r, c = rows[pick], cols[pick]
    uv = frag["uv"][r, c]
    texels = twin_atlas.footprint(atlas.size, uv)
    scatter = np.zeros((P, 3))
    scatter[texels] = twin_atlas.gather(lk, mips, texels)
    ref = twin_atlas.shade(scatter.reshape(atlas.size, atlas.size, 3), uv, frag["position"][r, c],
                           frag["normal"][r, c], scene.camera.origin, eta)
    rel = compare(sub[r, c], ref, f"{scene.name}: dipole atlas gather")
    return {"points": len(pick), "max_rel_diff": rel, "tolerance": CHECK_RTOL, "ms": (time.perf_counter() - t) * 1e3,
            "twin_evaluations": int(lk.count[texels].sum() + P * len(scene.lights))}
