"""Non-convex validation scenes for connections through several interfaces.

:func:`torus_hole`: skin_torus_dielectric's torus, camera and side light, whose light passes
through the near side of the ring to reach the far side (about a fifth of the connections
from medium vertices cross the boundary three times: ``benchmarks/mnee_chains.py``), with a
thin medium (sigma_t 1.5 / 2 / 3 per cm, albedo 0.9 / 0.85 / 0.8) so that the light through the
other part of the ring is a large share of the image.
"""

import dataclasses

import numpy as np

from harness.scene import Boundary, load_scene

TORUS_HOLE_MEDIUM = {"sigma_t": (1.5, 2.0, 3.0), "albedo": (0.9, 0.85, 0.8)}


def torus_hole(eta=1.4, size=None):
    """The torus lit through its hole behind a boundary of index ``eta`` (1: index-matched), ``size`` x ``size``."""
    base = load_scene("skin_torus_dielectric")
    m = base.medium
    st = np.broadcast_to(np.asarray(TORUS_HOLE_MEDIUM["sigma_t"], np.float32), m.sigma_t.shape).copy()
    al = np.broadcast_to(np.asarray(TORUS_HOLE_MEDIUM["albedo"], np.float32), m.albedo.shape).copy()
    scene = base.with_medium(sigma_t=st, albedo=al)
    if size is not None:
        scene = scene.with_resolution(size, size)
    boundary = Boundary("index-matched") if eta == 1.0 else Boundary("dielectric", float(eta), 0.0)
    return dataclasses.replace(scene, name="torus_hole", boundary=boundary)
