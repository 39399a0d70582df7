"""The shading's read below the surface (an extension, ``shade_depth``; ``sslpv_gl.shade`` Eq. (S1)).

Each shaded point reads the accumulation grid ``d`` cells inwards along ``-n``. Second routes: the twin's read
against the cell index computed by hand for points on a plane; on an axis-aligned face, the twin at depth 1
against the paper's read of the grid shifted by one cell (``np.roll``, no point moved); the GLSL shading against
the twin on a whole render; and the effect the docs claim, measured against the committed reference.
"""

import re

import numpy as np
import pytest

from harness.scene import load_scene
from sslpv_gl import twin
from sslpv_gl.params import SSLPVParams

SHADE_WORST = 1e-5          # as tests/test_gl_vs_twin.py: max |GL - twin| / max |twin| of the shading


class TestTwin:
    BMIN, BMAX, N = (0.0, 0.0, 0.0), (2.5, 2.5, 2.5), 5       # cells 0.5 wide

    def _grid(self):
        rng = np.random.default_rng(3)
        acc = np.zeros((self.N,) * 3 + (3, 4))
        acc[..., 0] = rng.uniform(1.0, 2.0, (self.N,) * 3 + (3,))       # band 0 only: the read is the cell's c00
        return acc

    def test_the_read_is_d_cells_inwards(self):
        """Points on the plane z = 2.1 (cell z = 4) with normal +z read cell z = 4 at depth 0, z = 3 at depth 1
        (2.1 - 0.5 = 1.6) and z = 1 at depth 2.5 (2.1 - 1.25 = 0.85); a tilted normal moves x too."""
        acc = self._grid()
        pts = np.array([[0.75, 1.25, 2.1], [1.75, 0.25, 2.1]])
        up = np.array([[0.0, 0.0, 1.0]] * 2)
        for d, z in ((0.0, 4), (1.0, 3), (2.5, 1)):
            got = twin.shade_points(acc, self.BMIN, self.BMAX, pts, up, shade_depth=d)
            want = twin.shade_points(acc[[z] * self.N], self.BMIN, self.BMAX, pts, up)      # every layer = layer z
            np.testing.assert_array_equal(got, want)
        tilt = np.array([[0.6, 0.0, 0.8]])
        p = np.array([[1.2, 1.25, 2.1]])               # cell x = 2; at depth 1: (1.2 - 0.3, ., 2.1 - 0.4) -> x 1, z 3
        got = twin.shade_points(acc, self.BMIN, self.BMAX, p, tilt, shade_depth=1.0)
        moved = twin.shade_points(acc, self.BMIN, self.BMAX, np.array([[0.9, 1.25, 1.7]]), tilt)
        np.testing.assert_allclose(got, moved, rtol=1e-12)
        assert not np.allclose(got, twin.shade_points(acc, self.BMIN, self.BMAX, p, tilt))

    def test_an_axis_aligned_face_at_depth_1_is_the_grid_shifted_by_one_cell(self):
        """Second route without moving points: under a face of normal +z, the read at depth 1 is the paper's read
        of the grid whose layer z holds layer z - 1 (np.roll), cell and trilinear lookups alike."""
        acc = self._grid()
        acc[..., 1:] = np.random.default_rng(4).normal(0.0, 0.3, acc[..., 1:].shape)   # band 1 too
        rng = np.random.default_rng(5)
        pts = np.column_stack([rng.uniform(0.3, 2.2, 50), rng.uniform(0.3, 2.2, 50), np.full(50, 1.9)])
        up = np.tile([0.0, 0.0, 1.0], (50, 1))
        for lookup in ("cell", "trilinear"):
            got = twin.shade_points(acc, self.BMIN, self.BMAX, pts, up, lookup, shade_depth=1.0)
            want = twin.shade_points(np.roll(acc, 1, axis=0), self.BMIN, self.BMAX, pts, up, lookup)
            np.testing.assert_allclose(got, want, rtol=1e-12, err_msg=lookup)

    def test_no_depth_is_the_paper(self):
        acc = self._grid()
        pts, nrm = np.array([[1.3, 0.4, 2.2]]), np.array([[0.0, 0.6, 0.8]])
        np.testing.assert_array_equal(twin.shade_points(acc, self.BMIN, self.BMAX, pts, nrm, shade_depth=0.0),
                                      twin.shade_points(acc, self.BMIN, self.BMAX, pts, nrm))


class TestGL:
    @pytest.mark.parametrize("name,kw", [
        ("marble_sphere", dict(outside="interior", shade_depth=1.0)),
        ("bunny_dielectric", dict(outside="vacuum", shade_depth=1.5, lookup="trilinear")),
    ])
    def test_glsl_against_the_twin(self, gl_renderer, name, kw):
        """shade.frag reads at x - d dx n as the twin does, on a sphere and on the scanned bunny (dielectric:
        Fresnel too), within the shading tolerance of tests/test_gl_vs_twin.py; the paper's read (d = 0) of the
        same grid differs by more than 100 times that."""
        scene = load_scene(name).with_resolution(48, 48)
        params = SSLPVParams(N=16, steps=10, rsm_size=256, inject_size=64, mapping="collision", **kw)
        res = gl_renderer.render(scene, params)
        accum = gl_renderer.read_accumulation(params)
        m = res.mask
        view = np.asarray(scene.camera.origin) - res.position[m]
        view /= np.linalg.norm(view, axis=1, keepdims=True)
        bmin, bmax = scene.medium.bbox_min, scene.medium.bbox_max
        args = (accum, bmin, bmax, res.position[m], res.normal[m], params.lookup, scene.boundary.eta, view)
        ref = twin.shade_points(*args, shade_depth=params.shade_depth)
        err = np.abs(res.subsurface[m] - ref).max(axis=1) / np.abs(ref).max()
        if params.lookup == "cell":           # a read point on a cell face may round either way: leave those out
            dx = (np.asarray(bmax) - np.asarray(bmin)) / params.N
            q = res.position[m] - params.shade_depth * dx[0] * res.normal[m]
            u = (q - np.asarray(bmin)) / dx
            err = err[np.abs(u - np.round(u)).min(axis=1) > 1e-4]
        assert float(err.max()) <= SHADE_WORST
        paper = twin.shade_points(*args)
        assert np.abs(paper - ref).max() > 100 * SHADE_WORST * np.abs(ref).max()

    def test_one_cell_deep_removes_the_speckle_of_outside_interior(self, gl_renderer):
        """The docs' claim (sslpv_gl.shade, docs/diffusion_mapping.md): under outside = interior, a surface point
        that reads its own, mostly empty, cell gives a shape error that reading one cell deep removes. On
        marble_sphere at N = 32, K = 32 against the committed reference, the scale-invariant relMSE falls by more
        than a factor 4; under vacuum the read changes it by less than 30 %."""
        from harness.metrics import compute
        from harness.regression.accuracy import case_reference, small_scene

        scene = small_scene("marble_sphere")
        ref = case_reference(scene)

        def si(**kw):
            res = gl_renderer.render(scene, SSLPVParams(N=32, steps=32, mapping="collision", **kw))
            return compute("si_relmse", res.subsurface, ref["subsurface"], ref["mask"]).value

        surface, deep = si(outside="interior"), si(outside="interior", shade_depth=1.0)
        print(f"interior: si_relmse {surface:.4f} at the surface, {deep:.4f} one cell deep")
        assert deep < surface / 4
        vac, vac_deep = si(outside="vacuum"), si(outside="vacuum", shade_depth=1.0)
        assert abs(vac_deep / vac - 1.0) < 0.3

    def test_the_trilinear_read_removes_the_steps_between_cells(self, gl_renderer):
        """The docs' claim (docs/diffusion_mapping.md Sec. 8): read one cell deep under outside = interior with the
        injection one reduced mean free path deep, the cell lookup shades each cell's footprint with one value, and
        the steps between cells are most of the image's shape error: on jade_veins (heterogeneous) at N = 32 in the
        steady state, against the committed reference, the trilinear lookup lowers the scale-invariant relMSE by
        more than a factor 3. Under the paper's vacuum, whose surface cells also hold the light around the object, it
        changes it by less than 30 %."""
        from harness.metrics import compute
        from harness.regression.accuracy import case_reference, small_scene

        scene = small_scene("jade_veins")
        ref = case_reference(scene)

        def si(**kw):
            res = gl_renderer.render(scene, SSLPVParams(N=32, steps="steady", mapping="collision", **kw))
            return compute("si_relmse", res.subsurface, ref["subsurface"], ref["mask"]).value

        deep = dict(outside="interior", inject_depth=1.0, shade_depth=1.0)
        cell, tri = si(**deep), si(lookup="trilinear", **deep)
        print(f"interior, both depths: si_relmse {cell:.4f} by cell, {tri:.4f} trilinear")
        assert tri < cell / 3
        vac, vac_tri = si(outside="vacuum"), si(outside="vacuum", lookup="trilinear")
        assert abs(vac_tri / vac - 1.0) < 0.3


#: The two depths' refusals: (field, flag, out-of-range values, the range as the line says it).
DEPTHS = [("shade_depth", "--shade-depth", [-0.5, 4.5, float("nan"), True, "1"], "[0, 4]"),
          ("inject_depth", "--inject-depth", [-0.5, 17.0, float("nan"), True], "[0, 16]")]


class TestRefusals:
    """shade_depth and inject_depth (tests/test_inject_depth.py) are refused alike: out of range, on the command line,
    and against a calibration fitted at 0."""

    @pytest.mark.parametrize("field,flag,values,span", DEPTHS)
    def test_out_of_range(self, field, flag, values, span):
        from harness.errors import InputError

        for value in values:
            with pytest.raises(InputError, match=re.escape(f"{flag}: {field}: must be a number in {span}")):
                SSLPVParams(**{field: value})

    @pytest.mark.parametrize("field,flag,values,span", DEPTHS)
    def test_the_command_line_refuses_in_one_line(self, tmp_path, capsys, monkeypatch, field, flag, values, span):
        from tests.test_bad_input import one_line_runner

        cli = one_line_runner(tmp_path, capsys, monkeypatch)
        cli(["render", "thin_ring", "--out", str(tmp_path / "o"), "--steps", "8", flag, "-1"],
            f"error: {flag}: {field}: ", f"must be a number in {span}")

    @pytest.mark.parametrize("field,flag,values,span", DEPTHS)
    def test_a_calibration_fitted_at_0_refuses_a_depth(self, tmp_path, capsys, monkeypatch, field, flag, values, span):
        from tests.test_bad_input import one_line_runner

        import harness.paths as hp

        cli = one_line_runner(tmp_path, capsys, monkeypatch)
        monkeypatch.chdir(hp.REPO)
        cli(["render", "thin_ring", "--out", str(tmp_path / "o"), "--steps", "32", flag, "1",
             "--mapping", "calibrated:baselines/calibrated/collision/calibrated.toml"],
            f"error: {flag}: {field}: ", f"was calibrated with {field}=0.0")
