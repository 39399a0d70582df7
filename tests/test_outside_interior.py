"""``outside = interior`` (issue 28, Sec. 2): no light moves between two empty cells.

* the twin's step against the steady solver's sparse operator (two independent codings
  of the pair rule ``1 - empty[s] empty[d]``, :mod:`sslpv_gl.boundary`);
* the rule itself: light in an empty cell reaches only inside neighbours, and the
  vacuum lattice splits exactly into the ``interior`` lattice plus the paths that
  crossed between empty cells (both non-negative for non-negative band-0 light);
* the GL propagation against the twin (``gl`` marker), as ``test_gl_vs_twin_modes.py``, and a
  whole back-lit render's accumulation (K steps on GL, and ``steps = steady`` on the host).
"""

import numpy as np
import pytest

from sslpv_gl import boundary, steady, twin
from sslpv_gl.material import lpv_material

RTOL_GRID = 1e-4
N, DX = 10, 0.1


def _case(seed=7):
    rng = np.random.default_rng(seed)
    c = (np.arange(N) + 0.5) / N - 0.5
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    inside = x**2 + y**2 + z**2 < 0.35**2
    keep, emit = boundary.outside_masks(inside, "interior")
    mat = {"sigma_lpv": (rng.uniform(0, 5, (N, N, N, 3)) * keep).astype(np.float32),
           "sigma_s_prime": (rng.uniform(0, 1, (N, N, N, 3)) * keep).astype(np.float32),
           "g": rng.uniform(-0.5, 0.9, (N, N, N, 3)).astype(np.float32),
           "emit": emit.astype(np.float32),
           "empty": boundary.empty_mask(inside, "interior").astype(np.float32)}
    c0 = np.abs(rng.normal(0, 1, (N, N, N, 3, 4))).astype(np.float32)
    return inside, mat, c0


class TestTwin:
    def test_step_equals_sparse_operator(self):
        _, mat, c0 = _case()
        ops = steady.transfer_operator(mat["sigma_lpv"], mat["sigma_s_prime"], mat["g"], DX, empty=mat["empty"])
        prop, _ = twin.propagate(c0, mat["sigma_lpv"], mat["sigma_s_prime"], mat["g"], DX, 1, 0, empty=mat["empty"])
        for col in range(3):
            ref = (ops[col] @ c0[..., col, :].astype(np.float64).reshape(-1)).reshape(N, N, N, 4)
            np.testing.assert_allclose(prop[..., col, :], ref, rtol=1e-12, atol=1e-12)

    def test_empty_cells_exchange_with_inside_cells_only(self):
        inside, mat, _ = _case()
        c0 = np.zeros((N, N, N, 3, 4))
        c0[0, 0, 0, :, 0] = 1.0                      # a corner: empty, with empty neighbours only
        lit = np.argwhere(~inside & np.roll(inside, 1, axis=2))[0]   # an empty cell next to an inside one
        c0[tuple(lit) + (slice(None), 0)] = 1.0
        prop, _ = twin.propagate(c0, mat["sigma_lpv"], mat["sigma_s_prime"], mat["g"], DX, 1, 0, empty=mat["empty"])
        got = np.abs(prop[..., 0]).sum(axis=-1) > 0
        assert got.any()
        assert np.all(inside[got]), "light moved from an empty cell into an empty cell"
        vac, _ = twin.propagate(c0, mat["sigma_lpv"], mat["sigma_s_prime"], mat["g"], DX, 1, 0)
        assert np.any(np.abs(vac[~inside][..., 0]) > 0), "without the rule the empty cells receive light"

    def test_vacuum_is_interior_plus_bypass(self):
        """Paths that never cross between two empty cells are the interior lattice; the rest is >= 0 in c00."""
        _, mat, c0 = _case()
        c0[..., 1:] = 0.0
        mat["sigma_s_prime"][:] = np.where(mat["emit"] > 0, 1.0, 0.0)[..., :]
        mat["g"][:] = 0.0                            # isotropic: band 1 stays non-negative-free, c00 >= 0
        _, acc_i = twin.propagate(c0, mat["sigma_lpv"], mat["sigma_s_prime"], mat["g"], DX, 12, 0,
                                  empty=mat["empty"])
        _, acc_v = twin.propagate(c0, mat["sigma_lpv"], mat["sigma_s_prime"], mat["g"], DX, 12, 0)
        bypass = acc_v[..., 0].sum(axis=(0, 1, 2)) - acc_i[..., 0].sum(axis=(0, 1, 2))
        assert np.all(bypass > 0), bypass


class TestMaterial:
    def test_lpv_material_gives_the_empty_mask_for_interior_only(self):
        from types import SimpleNamespace

        inside, _, _ = _case()
        med = SimpleNamespace(bbox_min=[0, 0, 0], bbox_max=[1, 1, 1], sigma_t=np.full((4, 4, 4, 3), 5.0, np.float32),
                              albedo=np.full((4, 4, 4, 3), 0.9, np.float32), g=np.zeros((4, 4, 4, 3), np.float32))
        m = lpv_material(med, inside, N, "collision", outside="interior")
        np.testing.assert_array_equal(m["empty"][..., 0], (~inside).astype(np.float32))
        np.testing.assert_array_equal(m["emit"], 1.0)
        assert np.all(m["sigma_lpv"][~inside] == 0)
        assert "empty" not in lpv_material(med, inside, N, "collision", outside="vacuum")


@pytest.mark.gl
class TestGL:
    def test_propagation_matches_twin(self, gl_renderer):
        _, mat, c0 = _case()
        prop, acc = gl_renderer.propagate(c0, mat, DX, 9, 2, "fp32")
        ref_prop, ref_acc = twin.propagate(c0, mat["sigma_lpv"], mat["sigma_s_prime"], mat["g"], DX, 9, 2,
                                           emit=mat["emit"], empty=mat["empty"])
        for gl, ref, label in ((prop, ref_prop, "prop"), (acc, ref_acc, "accum")):
            scale = float(np.abs(ref[..., 0]).max())
            err = float(np.abs(gl - ref).max())
            print(f"interior {label}: max|GL - twin| / max|c00| = {err / scale:.2e} (<= {RTOL_GRID})")
            assert err <= RTOL_GRID * scale
        # power: without the rule the grids differ far beyond the tolerance
        _, acc_vac = twin.propagate(c0, mat["sigma_lpv"], mat["sigma_s_prime"], mat["g"], DX, 9, 2)
        assert np.abs(acc_vac - ref_acc).max() > 100 * RTOL_GRID * np.abs(ref_acc[..., 0]).max()

    @pytest.mark.parametrize("steps", [10, "steady"])
    def test_render_accumulation_matches_twin(self, gl_renderer, steps):
        """A whole back-lit render under interior (and the diffusion mapping): GL, or the host's steady solve,
        against the twin's accumulation (steady: the twin iterated until the grid is empty)."""
        from harness.scene import load_scene
        from sslpv_gl.params import SSLPVParams

        scene = load_scene("backlit_slab").with_resolution(32, 32)
        params = SSLPVParams(N=16, steps=steps, mapping="diffusion", outside="interior", skip=0, rsm_size=256,
                             inject_size=64)
        gl_renderer.render(scene, params)
        accum = gl_renderer.read_accumulation(params)
        mat = gl_renderer.lpv_material(scene, params)
        assert "empty" in mat
        texels = gl_renderer.rsm_texels(scene, params)
        med = scene.medium
        c0 = sum(twin.inject(t, light.position, med.bbox_min, med.bbox_max, params.N, scene.boundary.eta)
                 for t, light in zip(texels, scene.lights))
        dx = float((np.asarray(med.bbox_max, float) - np.asarray(med.bbox_min, float))[0] / params.N)
        if steps == "steady":
            ref, k, left = steady.propagate_until(c0, mat["sigma_lpv"], mat["sigma_s_prime"], mat["g"], dx, tol=1e-7,
                                                  max_steps=20000, skip=0, emit=mat["emit"], empty=mat["empty"])
            assert left < 1e-7, (k, left)
        else:
            _, ref = twin.propagate(c0, mat["sigma_lpv"], mat["sigma_s_prime"], mat["g"], dx, steps, 0,
                                    emit=mat["emit"], empty=mat["empty"])
        scale = float(np.abs(ref[..., 0]).max())
        err = float(np.abs(accum - ref).max())
        print(f"interior render K={steps}: max|GL - twin| / max|c00| = {err / scale:.2e}")
        assert err <= (1e-4 if steps != "steady" else 1e-5) * scale
