"""Propagation limited to the cells light can have reached (``sslpv_gl.propagate.region``, issue 14).

A step gathers from the six axial neighbours only, so after ``k`` steps nothing is more
than ``k`` cells from the injected grid's non-zero support, and every cell beyond holds
exactly 0. The region-limited propagation must therefore give the SAME floats as the
whole-grid one (``np.array_equal``, not a tolerance: a region one cell short leaves out
only the front of the light, which after a few steps may lie below a relative
tolerance), and the twin agrees with both.
"""

import numpy as np
import pytest

from sslpv_gl import propagate as P
from sslpv_gl import twin
from sslpv_gl.grids import LOCAL_SIZE, read_grid, read_layers, support, write_grid
from sslpv_gl.params import SSLPVParams

from .test_gl_vs_twin import _check_grid, _random_material


class TestRegion:
    def test_dilates_clamps_and_aligns(self):
        lo, hi = P.region((np.array([20, 9, 3]), np.array([22, 40, 60])), 3, 64)
        assert list(hi) == [25, 43, 63]                              # + 3, clamped to N - 1
        assert list(lo) == [16, 0, 0]                                # - 3, rounded down to the work group, >= 0
        assert all(v % LOCAL_SIZE == 0 for v in lo)

    def test_none_is_the_whole_grid(self):
        lo, hi = P.region(None, 5, 16)
        assert list(lo) == [0, 0, 0] and list(hi) == [15, 15, 15]

    def test_contains_every_cell_within_k(self):
        """Brute force: every cell within L1 (hence L-inf) distance k of a support cell lies in the region."""
        N = 24
        rng = np.random.default_rng(3)
        cells = rng.integers(4, 18, (5, 3))
        sup = (cells.min(axis=0), cells.max(axis=0))
        for k in (1, 2, 7):
            lo, hi = P.region(sup, k, N)
            grid = np.stack(np.meshgrid(*[np.arange(N)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
            dist = np.abs(grid[:, None, :] - cells[None]).sum(axis=-1).min(axis=1)
            reach = grid[dist <= k]
            assert np.all(reach >= lo) and np.all(reach <= hi), k


@pytest.mark.gl
class TestSupport:
    def test_bounds_of_nonzero_cells(self, gl_renderer):
        N = 16
        c = np.zeros((N, N, N, 3, 4), np.float32)
        c[2, 5, 11, 1, 3] = -1e-30                 # [z, y, x]: a band-1 coefficient of one colour counts
        c[9, 7, 4, 0, 0] = 2.0
        with gl_renderer.ctx:
            grid = gl_renderer._grid(N, "fp32")
            write_grid(grid.prop_a, c, "fp32")
            lo, hi = support(read_layers(grid.prop_a, "fp32"))
            write_grid(grid.prop_a, np.zeros_like(c), "fp32")
            empty = support(read_layers(grid.prop_a, "fp32"))
        assert list(lo) == [4, 5, 2] and list(hi) == [11, 7, 9]     # (x, y, z)
        assert empty is None


def _propagate(gl_renderer, c0, mat, dx, steps, skip, bounds):
    with gl_renderer.ctx:
        grid = gl_renderer._grid(c0.shape[0], "fp32")
        P.upload_material(grid, mat, dx)
        write_grid(grid.prop_a, c0, "fp32")
        final, _ = gl_renderer._propagate(grid, steps, skip, bounds=bounds)
        return read_grid(final, "fp32"), read_grid(grid.accum, "fp32")


@pytest.mark.gl
class TestRegionPropagation:
    @pytest.mark.parametrize("steps,skip", [(1, 0), (2, 0), (3, 2), (9, 2)])
    @pytest.mark.parametrize("where", ["middle", "corner"])
    def test_same_floats_as_the_whole_grid(self, gl_renderer, steps, skip, where):
        N, dx = 24, 0.05
        rng = np.random.default_rng(10 * steps + skip)
        mat = _random_material(rng, N, dx, "collision")
        # dirty both ping-pong grids and the accumulation first: the region-limited run must not
        # read what an earlier propagation left beyond its region
        _propagate(gl_renderer, rng.normal(0.0, 1.0, (N, N, N, 3, 4)).astype(np.float32), mat, dx, 3, 0, None)
        c0 = np.zeros((N, N, N, 3, 4), np.float32)
        box = (slice(9, 13), slice(10, 12), slice(11, 14)) if where == "middle" else \
            (slice(0, 3), slice(N - 2, N), slice(N - 4, N))
        c0[box] = rng.normal(0.0, 1.0, c0[box].shape)
        c0[box + (slice(None), 0)] = np.abs(c0[box + (slice(None), 0)]) + 0.5
        with gl_renderer.ctx:
            grid = gl_renderer._grid(N, "fp32")
            write_grid(grid.prop_a, c0, "fp32")
            bounds = support(read_layers(grid.prop_a, "fp32"))
        full = _propagate(gl_renderer, c0, mat, dx, steps, skip, None)
        part = _propagate(gl_renderer, c0, mat, dx, steps, skip, bounds)
        assert np.array_equal(part[0], full[0]), "propagation grid differs from the whole-grid step"
        assert np.array_equal(part[1], full[1]), "accumulation differs from the whole-grid step"
        ref_prop, ref_acc = twin.propagate(c0, mat["sigma_lpv"], mat["sigma_s_prime"], mat["g"], dx, steps, skip)
        _check_grid(part[0], ref_prop, f"region prop K={steps} {where}")
        if steps > skip:
            _check_grid(part[1], ref_acc, f"region accum K={steps} {where}")

    def test_render_unchanged(self, gl_renderer, monkeypatch):
        """A whole render (one light, so the support is a part of the grid) gives the same images either way."""
        from harness.scene import load_scene
        from sslpv_gl import renderer as R

        scene = load_scene("backlit_slab").with_resolution(32, 32)
        params = SSLPVParams(N=32, steps=12, rsm_size=256, inject_size=64)
        seen = []
        real = R.support
        monkeypatch.setattr(R, "support", lambda layers: seen.append(real(layers)) or seen[-1])
        part = gl_renderer.render(scene, params)
        lo, hi = seen[0]
        assert np.prod(hi - lo + 1) < 32 ** 3 // 2, "the injected light fills the grid: the test needs a part"
        monkeypatch.setattr(R, "support", lambda layers: None)
        full = gl_renderer.render(scene, params)
        assert np.array_equal(part.full, full.full) and np.array_equal(part.subsurface, full.subsurface)
        assert part.subsurface[part.mask].max() > 0.0
