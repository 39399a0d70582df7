"""Every cubemap render checks itself: a few seeded random points of each compute pass recomputed by the twin.

As :mod:`dipole_gl.check` for the other gathers, after the frame:

* ``gather``: :data:`dipole_gl.check.CHECK_POINTS` covered face texels drawn with
  ``numpy.random.default_rng(CHECK_SEED)``; :func:`dipole_gl.twin_cubemap.gather` recomputes their
  ``C^f`` (every frame's rotation) from the GL light buffers and the texels' exit points;
* ``combine``: as many covered camera pixels; :func:`dipole_gl.twin_cubemap.combine` recomputes them
  from the GL G-buffer, the faces (coverage, depth) and the GL ``C^f``.

A point whose lookup lies within float32 rounding of a texel edge (``ambiguous``, or a disc sample
with ``slack``: GL and the float64 twin may pick neighbouring texels, both right) is not drawn; the
draw takes the next of :data:`CANDIDATES` candidates.
Either pass off by more than :data:`dipole_gl.check.CHECK_RTOL` of the checked points' scale refuses
the result (:class:`harness.errors.ResultRefused`, one line). The raster passes (light buffer, faces,
G-buffer) are not checked here (``tests/test_dipole_cubemap.py`` checks them against a ray caster).

Cost (``info["check"]``): ``points x L x samples x frames`` twin kernel evaluations, and the twin's
combination of the candidate pixels.
"""

from __future__ import annotations

import time

import numpy as np

from sslpv_gl.rsm import bounding_sphere

from . import twin_cubemap
from .check import CHECK_POINTS, CHECK_RTOL, CHECK_SEED, compare

__all__ = ["check_cubemap"]

#: Candidates drawn per pass, of which the first CHECK_POINTS unambiguous ones are checked.
CANDIDATES = 4 * CHECK_POINTS


def _candidates(n):
    rng = np.random.default_rng(CHECK_SEED)
    return rng.permutation(n)[:CANDIDATES] if n else np.zeros(0, np.int64)


def check_cubemap(kernel, scene, mat, views, raw, params):
    """Recompute a few face texels' ``C^f`` and camera pixels of one cubemap render -> ``info["check"]``."""
    t = time.perf_counter()
    eta = float(scene.boundary.eta)
    fp, fn = raw["face_pos"], raw["face_nrm"]
    rows, cols = np.nonzero(fp[..., 3] > 0.5)
    pick = _candidates(len(rows))
    r, c = rows[pick], cols[pick]
    centre = bounding_sphere(scene.mesh)[0]                  # each light's axis aims at it (rsm.light_view)
    axes = [twin_cubemap.light_axis(light.position, centre) for light in scene.lights]
    lb = raw["lb_pos"]
    ref, amb, slack = twin_cubemap.gather(kernel, fp[r, c, :3], fn[r, c, :3], lb[..., :3], raw["lb_nrm"][..., :3],
                                   lb[..., 3] > 0.5, scene.lights, views, axes, mat, eta, params.samples,
                                   params.frames, raw["disc_radius"], params.eps_g)
    keep = np.nonzero(~amb & ~np.any(slack > 0, axis=1))[0][:CHECK_POINTS]
    rel_g = compare(raw["accum"][r[keep], c[keep]], ref[keep], f"{scene.name}: {kernel} cubemap gather")
    gmask = raw["gpos"][..., 3] > 0.5
    prow, pcol = np.nonzero(gmask)
    pk = _candidates(len(prow))
    pr, pc = prow[pk], pcol[pk]
    lum, _, pamb = twin_cubemap.combine(raw["gpos"][pr, pc, :3], raw["gnrm"][pr, pc, :3], fp[..., 3] > 0.5, fn[..., 3],
                                        raw["accum"], raw["cube"], params.cube_size, raw["eps_c"], raw["eps_b"],
                                        scene.camera.origin, eta)
    pkeep = np.nonzero(~pamb)[0][:CHECK_POINTS]
    rel_c = compare(raw["sub_raw"][pr[pkeep], pc[pkeep], :3], lum[pkeep], f"{scene.name}: {kernel} cubemap combination")
    return {"points": int(len(keep) + len(pkeep)), "max_rel_diff": max(rel_g, rel_c), "tolerance": CHECK_RTOL,
            "ms": (time.perf_counter() - t) * 1e3,
            "twin_evaluations": int(len(pick) * len(scene.lights) * params.samples * params.frames)}
