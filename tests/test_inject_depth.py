"""Injection at depth (an extension, ``inject_depth``; ``sslpv_gl.inject`` Eq. (J1)).

Each texel moves ``d`` reduced mean free paths ``1 / sigma_t'`` of its own cell's medium inwards along ``-n``.
Second routes: Eq. (J1) recomputed from the scene's own voxels where the LPV grid is the medium's (no
resampling), the twin's texel-by-texel move against a depth grid built by hand, the GLSL injection against
the twin on a heterogeneous medium, and on a homogeneous scene a whole render at depth 1 against the paper's
scene-unit ``inject_offset`` set to one reduced mean free path computed from the scene file's numbers.
"""

import numpy as np
import pytest

from harness.scene import load_scene
from sslpv_gl import twin
from sslpv_gl.inject import depth_offsets
from sslpv_gl.params import SSLPVParams


def _reduced_mfp(sigma_t, albedo, g):
    """Eq. (J1)'s length per voxel, from the medium's own numbers: the mean over colours of 1 / (sigma_t (1 - a g))."""
    return np.mean(1.0 / (np.asarray(sigma_t) * (1.0 - np.asarray(albedo) * np.asarray(g))), axis=-1)


def test_the_depth_is_each_cells_reduced_mean_free_path():
    """On jade_veins (heterogeneous, g = 0.2) at the medium's own 64^3 (box resampling is the identity): every cell's
    depth is the mean over colours of its own 1 / sigma_t', neither the reciprocal of the mean sigma_t' nor 1 / sigma_t
    (each differs by more than the tolerance, which is the float32 medium's rounding through the resampling)."""
    med = load_scene("jade_veins").medium
    N = np.asarray(med.sigma_t).shape[0]
    got = depth_offsets(med, N, 2.0)
    want = 2.0 * _reduced_mfp(med.sigma_t, med.albedo, med.g)
    np.testing.assert_allclose(got, want, rtol=1e-6)
    st, a, g = (np.asarray(x, np.float64) for x in (med.sigma_t, med.albedo, med.g))
    for other in (2.0 / np.mean(st * (1.0 - a * g), axis=-1), 2.0 * np.mean(1.0 / st, axis=-1)):
        assert np.abs(other / want - 1.0).max() > 1e-5
    assert got.shape == (N, N, N) and np.ptp(got) > 0.1 * got.mean()      # heterogeneous: the depth varies


def test_a_cell_without_medium_takes_the_mean_of_those_with_one():
    from types import SimpleNamespace

    st = np.full((4, 4, 4, 3), 5.0)
    st[0] = 0.0                                        # one empty z layer
    med = SimpleNamespace(sigma_t=st, albedo=np.full_like(st, 0.5), g=np.zeros_like(st))
    got = depth_offsets(med, 4, 1.0)
    np.testing.assert_allclose(got, 0.2, rtol=1e-12)
    assert np.isfinite(got).all()


class TestTwin:
    BMIN, BMAX, N = (0.0, 0.0, 0.0), (2.5, 2.5, 2.5), 5       # cells 0.5 wide

    def test_each_texel_moves_by_its_own_cells_depth(self):
        """Two texels on the plane z = 2.1 (cell z = 4), normal +z: the one over a cell of depth 0.7 lands in cell
        z = 2 (2.1 - 0.7 = 1.4), the one over a cell of depth 0 stays in z = 4; inject_offset adds to both."""
        light = np.array([1.25, 1.25, 5.0])
        depth = np.zeros((self.N,) * 3)
        depth[4, 2, 1] = 0.7                           # [z, y, x]: under the first texel only
        tex = np.array([[0.75, 1.25, 2.1, 0, 0, 1, 1, 1, 1, 1],
                        [1.75, 1.25, 2.1, 0, 0, 1, 1, 1, 1, 1]], dtype=float)
        g = twin.inject(tex, light, self.BMIN, self.BMAX, self.N, depth=depth)
        assert g[2, 2, 1, 0, 0] > 0 and g[4, 2, 3, 0, 0] > 0
        assert g[4, 2, 1, 0, 0] == 0 and g[2, 2, 3, 0, 0] == 0
        g = twin.inject(tex, light, self.BMIN, self.BMAX, self.N, offset=0.5, depth=depth)
        assert g[1, 2, 1, 0, 0] > 0 and g[3, 2, 3, 0, 0] > 0     # 2.1 - 1.2 = 0.9, 2.1 - 0.5 = 1.6

    def test_no_depth_is_the_paper(self):
        rng = np.random.default_rng(3)
        tex = np.c_[rng.uniform(0, 2.5, (50, 3)), rng.normal(size=(50, 3)), rng.uniform(0, 1, (50, 3)), np.ones(50)]
        light = np.array([1.0, 1.0, 6.0])
        a = twin.inject(tex, light, self.BMIN, self.BMAX, self.N)
        b = twin.inject(tex, light, self.BMIN, self.BMAX, self.N, depth=np.zeros((self.N,) * 3))
        np.testing.assert_array_equal(a, b)


@pytest.mark.gl
class TestGL:
    def test_glsl_against_the_twin_on_a_heterogeneous_medium(self, gl_renderer):
        """GLSL injection (inject.vert reads u_depth in the texel's cell) against the twin with depth_offsets, on
        jade_veins at N = 16, random texels inside the box; max |GL - twin| <= 1e-4 max |c00| as for the rest of the
        injection (tests/test_gl_vs_twin.py)."""
        scene = load_scene("jade_veins")
        med = scene.medium
        rng = np.random.default_rng(11)
        M = 4000
        lo, hi = np.asarray(med.bbox_min), np.asarray(med.bbox_max)
        pos = rng.uniform(lo, hi, (M, 3))
        nrm = rng.normal(size=(M, 3))
        nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
        light = np.array(scene.lights[0].position)
        nrm[np.sum(nrm * (light - pos), axis=1) < 0] *= -1
        tex = np.zeros((M, 10), dtype=np.float32)
        tex[:, 0:3], tex[:, 3:6] = pos, nrm
        tex[:, 6:9] = rng.uniform(0.0, 1e-3, (M, 3))
        tex[:, 9] = 1.0
        params = SSLPVParams(N=16, inject_depth=1.5)
        gl = gl_renderer.inject([tex], [light], scene, params)
        ref = twin.inject(tex, light, med.bbox_min, med.bbox_max, 16, scene.boundary.eta,
                          depth=depth_offsets(med, 16, 1.5))
        flat = twin.inject(tex, light, med.bbox_min, med.bbox_max, 16, scene.boundary.eta)
        scale = float(np.abs(ref[..., 0]).max())
        assert float(np.abs(gl - ref).max()) <= 1e-4 * scale
        assert float(np.abs(flat - ref).max()) > 0.1 * scale          # the depth moved light

    def test_a_homogeneous_medium_at_depth_1_is_the_offset_of_one_reduced_mean_free_path(self, gl_renderer):
        """backlit_sphere (sigma_t 5.5 / 6 / 6.5, albedo 0.995 / 0.99 / 0.98, g = 0.3): a render at inject_depth = 1
        is the render at inject_offset = the mean over colours of 1 / (sigma_t (1 - a g)), from the scene file's
        numbers; and not the paper's render."""
        scene = load_scene("backlit_sphere")
        ell = float(np.mean(1.0 / (np.array([5.5, 6.0, 6.5]) * (1.0 - np.array([0.995, 0.99, 0.98]) * 0.3))))
        base = SSLPVParams(N=16, steps=8, mapping="collision", outside="interior")
        a = gl_renderer.render(scene, base.replace(inject_depth=1.0)).subsurface
        b = gl_renderer.render(scene, base.replace(inject_offset=np.float32(ell).item())).subsurface
        c = gl_renderer.render(scene, base).subsurface
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-7 * float(b.max()))
        assert float(np.abs(a - c).max()) > 0.05 * float(c.max())


# The one-line refusals of inject_depth are with shade_depth's, in tests/test_shade_depth.py::TestRefusals.
