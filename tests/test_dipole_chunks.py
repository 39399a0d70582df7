"""The gathers' chunks (``dipole_gl.budget``): GL against the NumPy twin where one invocation of the
unchunked gather would have run more than llvmpipe's 65,535 loop iterations.

llvmpipe ends an invocation's loops after 65,535 iterations in all and says nothing, so a gather
that is not chunked returns a partial sum there. Each configuration below is chosen so that the
unchunked invocation would exceed that limit (asserted from the cost model of ``dipole_gl.budget``),
and the points checked are those whose sum depends on the end of the loop: the dense gather's
exit points sit on lit samples from the last fifth of the sample list, the vertex gather's rows
list the nearest neighbours (the largest terms) last. Tolerance as in ``tests/test_dipole_gl.py``:
``max |GL - twin| <= 1e-4 max |twin|``.
"""

import numpy as np
import pytest

from harness.regression.accuracy import small_scene
from dipole_gl import budget, kernels, twin
from dipole_gl.medium import scene_material
from dipole_gl.params import DipoleParams
from dipole_gl.sampling import N_PHI, radial_nodes, surface_samples
from dipole_gl.vertex import VertexPrecomp
from tests.test_dipole_gl import close as _close

pytestmark = pytest.mark.gl

#: The apple sphere at its committed small size: 46,080 samples at spacing 1, 81,920 at 0.8.
SCENE = "apple_sphere"
SPACING = {"dipole": 0.8, "dirpole": 1.0}


def _lit(points, normals, light, cos_min=0.0):
    """Points that face ``light`` with ``cos > cos_min``."""
    to = np.asarray(light.position) - points
    return np.sum(to * normals, axis=1) > cos_min * np.linalg.norm(to, axis=1)


def _unchunked_iterations(kernel, n, n_lights, near=0):
    return n * budget.far_iterations_per_sample(kernel, n_lights) + near


@pytest.mark.parametrize("kernel", ["dipole", "dirpole"])
def test_dense_gather_past_the_loop_limit(dipole_renderer, kernel):
    """Six exit points on lit samples of the last fifth of the list, GL (chunked) against the twin.

    The points face the light at ``cos > 0.3``: at grazing light the float32 refraction of the
    directional dipole's near field is ill-conditioned (2e-3 at one point with ``cos`` near 0).
    """
    scene = small_scene(SCENE)
    mat = scene_material(scene)
    params = DipoleParams(spacing=SPACING[kernel])
    pos, nrm, area = surface_samples(scene.mesh, params.spacing * mat.mfp)
    L = len(scene.lights)
    near = budget.near_iterations(kernel, L, len(radial_nodes()[0]), N_PHI)
    assert _unchunked_iterations(kernel, len(pos), L, near) > budget.LLVMPIPE_LOOP_LIMIT
    tail = np.arange(int(0.8 * len(pos)), len(pos))
    tail = tail[_lit(pos[tail], nrm[tail], scene.lights[0], cos_min=0.3)]
    pick = np.random.default_rng(1).choice(tail, size=6, replace=False)
    xo, no = pos[pick][None], nrm[pick][None]                       # a 1 x 6 "image"
    gl, flux_gl = dipole_renderer.gather_at(scene, kernel, params, xo, no)
    flux, dirs = twin.irradiance(pos, nrm, area, scene.lights, scene.boundary.eta, flux_gl[..., 3])
    ref = twin.dense_gather(kernel, xo[0], no[0], scene.camera.origin, (pos, nrm), flux, dirs, mat,
                            scene.boundary.eta, params.spacing * mat.mfp, scene.lights, np.ones((6, L)))
    _close(gl[0], ref, f"{SCENE} {kernel} dense gather, {len(pos):,} samples")


def _long_rows(scene, mat, kernel, spacing, exits=4):
    """A hand-made precomputation: the dense samples as scattering vertices, ``exits`` lit exit vertices
    whose rows hold every other vertex, nearest last; the other rows empty."""
    pos, nrm, area = surface_samples(scene.mesh, spacing * mat.mfp)
    lit = np.nonzero(_lit(pos, nrm, scene.lights[0]))[0]
    first = np.random.default_rng(2).choice(lit, size=exits, replace=False)
    order = np.concatenate([first, np.setdiff1d(np.arange(len(pos)), first)])
    pos, nrm, area = pos[order], nrm[order], area[order]
    rows, factors = [], []
    for o in range(exits):
        j = np.delete(np.arange(len(pos)), o)
        j = j[np.argsort(-np.linalg.norm(pos[j] - pos[o], axis=1), kind="stable")]   # farthest first
        rows.append(j.astype(np.int32))
        if kernel == "dipole":
            m = twin.exit_coefficients(mat, pos[o:o + 1], nrm[o:o + 1], scene.boundary.eta)
            factors.append(kernels.rd_dipole(np.linalg.norm(pos[j] - pos[o], axis=1)[:, None], m) / np.pi)
    counts = [len(r) for r in rows] + [0] * (len(pos) - exits)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    fac = np.concatenate(factors).astype(np.float32) if factors else None
    return VertexPrecomp(pos, nrm, area, np.zeros((1, 3), np.int64), offsets, np.concatenate(rows), fac,
                         np.zeros((1, 3), np.int32), np.array([[1.0, 0.0, 0.0]]), np.inf, 0.0)


@pytest.mark.parametrize("kernel", ["dipole", "dirpole"])
def test_vertex_gather_past_the_loop_limit(dipole_renderer, kernel):
    """Four rows of 81,919 neighbours each (the apple sphere's samples at spacing 0.8), GL against the twin."""
    scene = small_scene(SCENE)
    mat = scene_material(scene)
    pre = _long_rows(scene, mat, kernel, 0.8)
    L = len(scene.lights)
    longest = int(np.diff(pre.offsets).max())
    assert _unchunked_iterations(kernel, longest, L) > budget.LLVMPIPE_LOOP_LIMIT
    b, flux_gl = dipole_renderer.vertex_b(scene, kernel, pre)
    flux, dirs = twin.irradiance(pre.positions, pre.normals, pre.areas, scene.lights, scene.boundary.eta,
                                 flux_gl[..., 3])
    exits = np.arange(4)
    ref = twin.vertex_gather(kernel, pre, flux, dirs, mat, scene.boundary.eta, vertices=exits)
    _close(b[exits], ref, f"{SCENE} {kernel} vertex gather, rows of {longest:,}")
    assert np.all(b[4:] == 0.0), "an empty row must sum to zero"


def test_chunks_cover_every_sample_once():
    """The pieces of ``budget.chunks`` tile ``range(count)`` exactly, and the dense chunk respects the budget."""
    for count, size in ((0, 7), (1, 7), (7, 7), (8, 7), (81_920, 59_952)):
        pieces = budget.chunks(count, size)
        covered = np.concatenate([np.arange(a, b) for a, b in pieces])
        assert covered.tolist() == list(range(count)) and all(b - a <= size for a, b in pieces)
    n_rad = len(radial_nodes()[0])
    for kernel in ("dipole", "dirpole"):
        for L in range(1, 9):
            size = budget.dense_chunk(kernel, L, n_rad, N_PHI)
            total = _unchunked_iterations(kernel, size, L, budget.near_iterations(kernel, L, n_rad, N_PHI))
            assert total <= budget.ITERATION_BUDGET < budget.LLVMPIPE_LOOP_LIMIT
            assert _unchunked_iterations(kernel, size + 1, L, budget.near_iterations(kernel, L, n_rad, N_PHI)) \
                > budget.ITERATION_BUDGET
