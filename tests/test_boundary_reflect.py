"""``boundary_reflect = rdr`` (issue 28, Sec. 3): R_dr(eta) of the light reaching the surface returns inside.

* ``R_dr`` by a second route (plain midpoint quadrature of ``2 int R(-mu) mu dmu``, no split at
  the critical angle), the mirror identity ``M_{+o} F_o = F_o M_{-o}`` that Eq. (R3) rests on;
* the twin's step against the steady solver's sparse operator (two codings of Eq. (R3));
* energy: in one step the flux that lands outside is exactly ``1 - R_dr`` of what crossed
  without the option, the rest stays inside, nothing is lost (no absorption); light entering
  from outside is untouched; a closed lattice (absorbing outside) still delivers all the
  injected flux to the outside, later;
* ``eta = 1`` is exactly the paper; bad input is one line;
* GL against the twin (``gl`` marker), and a whole dielectric render (K steps on GL, ``steady``
  on the host) against the twin.
"""

import numpy as np
import pytest

from harness.errors import InputError
from sslpv_gl import boundary, reflect, sh, steady, twin
from sslpv_gl.optics import fresnel_reflectance

RTOL_GRID = 1e-4
N, DX = 10, 0.1


def midpoint_rdr(eta, n=400_000):
    """Second route to (R1): ``2 int_0^1 R(-mu) mu dmu`` by the midpoint rule on a fine grid."""
    mu = (np.arange(n) + 0.5) / n
    return float(np.sum(2.0 * fresnel_reflectance(-mu, eta) * mu) / n)


def _case(seed=3, sigma=True):
    rng = np.random.default_rng(seed)
    c = (np.arange(N) + 0.5) / N - 0.5
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    inside = x**2 + y**2 + z**2 < 0.35**2
    ins = inside[..., None].astype(np.float64)
    mat = {"sigma_lpv": (rng.uniform(0, 5, (N, N, N, 3)) * ins * (1.0 if sigma else 0.0)),
           "sigma_s_prime": rng.uniform(0, 1, (N, N, N, 3)) * ins,
           "g": rng.uniform(-0.5, 0.9, (N, N, N, 3)),
           "emit": np.ones((N, N, N, 3))}
    c0 = np.abs(rng.normal(0, 1, (N, N, N, 3, 4)))
    return inside, mat, c0


def _flux(c, mask):
    """Band-0 sum per colour over the cells of ``mask``."""
    return c[mask][..., 0].sum(axis=0)


class TestReflectance:
    @pytest.mark.parametrize("eta", [1.1, 1.4, 1.6, 2.0, 3.0])
    def test_second_route(self, eta):
        assert reflect.reflectance("rdr", eta) == pytest.approx(midpoint_rdr(eta), abs=2e-6)

    def test_issue_value_and_none(self):
        assert reflect.reflectance("rdr", 1.6) == pytest.approx(0.651, abs=5e-4)   # issue 28's figure
        assert reflect.reflectance("none", 1.6) == 0.0
        assert reflect.reflectance("rdr", 1.0) == 0.0

    def test_mirror_identity(self):
        M = sh.propagation_matrices()
        for s, o in enumerate(sh.SOURCE_OFFSETS):
            opp = int(np.flatnonzero((sh.SOURCE_OFFSETS == -o).all(axis=1))[0])
            axis = int(np.flatnonzero(o)[0])
            F = reflect.mirror(np.eye(4), axis)      # F applied to each row's coefficients = diag
            np.testing.assert_allclose(M[s] @ F, F @ M[opp], atol=1e-12)
            assert F[0, 0] == 1.0                    # band 0, the flux, is kept


class TestTwin:
    @pytest.mark.parametrize("r", [0.0, 0.6])
    def test_step_equals_sparse_operator(self, r):
        inside, mat, c0 = _case()
        ops = steady.transfer_operator(mat["sigma_lpv"], mat["sigma_s_prime"], mat["g"], DX, r_dr=r, inside=inside)
        prop, _ = twin.propagate(c0, mat["sigma_lpv"], mat["sigma_s_prime"], mat["g"], DX, 1, 0, r_dr=r,
                                 inside=inside)
        for col in range(3):
            ref = (ops[col] @ c0[..., col, :].reshape(-1)).reshape(N, N, N, 4)
            np.testing.assert_allclose(prop[..., col, :], ref, rtol=1e-12, atol=1e-12)

    def test_steady_equals_iterated(self):
        inside, mat, c0 = _case()
        r = reflect.reflectance("rdr", 1.6)
        args = (c0, mat["sigma_lpv"], mat["sigma_s_prime"], mat["g"], DX)
        acc, info = steady.steady_state(*args, skip=2, r_dr=r, inside=inside)
        ref, k, left = steady.propagate_until(*args, tol=1e-11, max_steps=20000, skip=2, r_dr=r, inside=inside)
        assert left < 1e-11
        scale = float(np.abs(ref[..., 0]).max())
        assert float(np.abs(acc - ref).max()) <= 1e-7 * scale
        # power: the reflection changes the steady state far beyond that
        acc0, _ = steady.steady_state(*args, skip=2)
        assert float(np.abs(acc0 - acc).max()) > 1e-2 * scale


class TestEnergy:
    R = 0.651

    def _step(self, c0, inside, mat, r):
        prop, _ = twin.propagate(c0, mat["sigma_lpv"], mat["sigma_s_prime"], mat["g"], DX, 1, 0, r_dr=r,
                                 inside=inside)
        return prop

    def test_outgoing_flux_is_one_minus_rdr(self):
        """Light inside only, no absorption: outside gets (1 - R) of the paper's, inside keeps the rest."""
        inside, mat, c0 = _case(sigma=False)
        c0 = c0 * inside[..., None, None]
        p0 = self._step(c0, inside, mat, 0.0)
        pr = self._step(c0, inside, mat, self.R)
        out0, outr = _flux(p0, ~inside), _flux(pr, ~inside)
        assert np.all(out0 > 0)
        np.testing.assert_allclose(outr, (1.0 - self.R) * out0, rtol=1e-12)
        np.testing.assert_allclose(_flux(pr, inside), _flux(p0, inside) + self.R * out0, rtol=1e-12)
        np.testing.assert_allclose(_flux(pr, np.ones_like(inside)), _flux(c0, np.ones_like(inside)), rtol=1e-12)

    def test_entering_light_is_untouched(self):
        """Light outside only: what enters the medium is the paper's (the entry transmittance is Eq. 1's)."""
        inside, mat, c0 = _case(sigma=False)
        c0 = c0 * (~inside)[..., None, None]
        np.testing.assert_array_equal(self._step(c0, inside, mat, 0.0)[inside], self._step(c0, inside, mat, self.R)[inside])

    def test_closed_lattice_delivers_everything(self):
        """outside = absorb, no absorption: every injected bit of flux ends in an outside sink, with or without R."""
        inside, mat, c0 = _case(sigma=False)
        c0 = c0 * inside[..., None, None]
        c0[..., 1:] = 0.0
        mat["sigma_s_prime"] = np.where(inside[..., None], 1.0, 0.0) * np.ones(3)
        _, emit = boundary.outside_masks(inside, "absorb")
        total = _flux(c0, np.ones_like(inside))
        steps = []
        for r in (0.0, self.R):
            acc, k, left = steady.propagate_until(c0, mat["sigma_lpv"], mat["sigma_s_prime"], mat["g"], DX,
                                                  tol=1e-12, max_steps=20000, skip=0, emit=emit, r_dr=r,
                                                  inside=inside)
            assert left < 1e-12
            np.testing.assert_allclose(_flux(acc, ~inside), total, rtol=1e-9)
            steps.append(k)
        assert steps[1] > steps[0], f"the reflected light must take longer to leave: {steps}"


class TestNoOp:
    def test_index_matched_is_the_paper(self):
        inside, mat, c0 = _case()
        r = reflect.reflectance("rdr", 1.0)
        a = twin.propagate(c0, mat["sigma_lpv"], mat["sigma_s_prime"], mat["g"], DX, 6, 2, r_dr=r, inside=inside)
        b = twin.propagate(c0, mat["sigma_lpv"], mat["sigma_s_prime"], mat["g"], DX, 6, 2)
        for x, y in zip(a, b):
            np.testing.assert_array_equal(x, y)


class TestInput:
    def test_default_is_the_paper(self):
        from sslpv_gl.params import SSLPVParams

        assert SSLPVParams().boundary_reflect == "none"

    @pytest.mark.parametrize("outside", ["material", "extrapolated"])
    def test_unsupported_outside_is_one_line(self, outside):
        from sslpv_gl.params import SSLPVParams

        with pytest.raises(InputError) as e:
            SSLPVParams(boundary_reflect="rdr", outside=outside)
        assert "\n" not in str(e.value) and "outside" in str(e.value)

    def test_unknown_value(self):
        from sslpv_gl.params import SSLPVParams

        with pytest.raises(InputError):
            SSLPVParams(boundary_reflect="mirror")

    @pytest.mark.parametrize("eta", [0.8, 3.5])
    def test_eta_outside_range_is_one_line(self, eta):
        with pytest.raises(InputError) as e:
            reflect.check("rdr", "vacuum", eta)
        assert "\n" not in str(e.value) and "eta" in str(e.value)
        reflect.check("none", "vacuum", eta)         # the paper takes any eta

    def test_calibrated_file_without_it_refuses_rdr(self, tmp_path):
        from sslpv_gl.params import SSLPVParams

        cal = "baselines/calibrated/collision/calibrated.toml"
        SSLPVParams(mapping=f"calibrated:{cal}")
        with pytest.raises(InputError) as e:
            SSLPVParams(mapping=f"calibrated:{cal}", boundary_reflect="rdr")
        assert "boundary_reflect" in str(e.value)


@pytest.mark.gl
class TestGL:
    @pytest.mark.parametrize("outside", reflect.SUPPORTED_OUTSIDE)
    def test_propagation_matches_twin(self, gl_renderer, outside):
        inside, mat, c0 = _case()
        r = reflect.reflectance("rdr", 1.6)
        m = {k: v.astype(np.float32) for k, v in mat.items()}
        m["emit"] = boundary.outside_masks(inside, outside)[1].astype(np.float32)
        empty = boundary.empty_mask(inside, outside)
        if empty is not None:
            m["empty"] = empty.astype(np.float32)
        m.update(r_dr=r, inside=inside)
        prop, acc = gl_renderer.propagate(c0.astype(np.float32), m, DX, 9, 2, "fp32")
        ref_prop, ref_acc = twin.propagate(c0, m["sigma_lpv"], m["sigma_s_prime"], m["g"], DX, 9, 2, r_dr=r,
                                           inside=inside, emit=m["emit"], empty=m.get("empty"))
        for gl, ref, label in ((prop, ref_prop, "prop"), (acc, ref_acc, "accum")):
            scale = float(np.abs(ref[..., 0]).max())
            err = float(np.abs(gl - ref).max())
            print(f"rdr, outside {outside}, {label}: max|GL - twin| / max|c00| = {err / scale:.2e} (<= {RTOL_GRID})")
            assert err <= RTOL_GRID * scale
        _, acc0 = twin.propagate(c0, m["sigma_lpv"], m["sigma_s_prime"], m["g"], DX, 9, 2, emit=m["emit"],
                                 empty=m.get("empty"))
        assert np.abs(acc0 - ref_acc).max() > 100 * RTOL_GRID * np.abs(ref_acc[..., 0]).max()

    @pytest.mark.parametrize("steps", [10, "steady"])
    def test_render_accumulation_matches_twin(self, gl_renderer, steps):
        """A dielectric scene (eta 1.6) rendered with rdr: GL, or the host's steady solve, against the twin."""
        from harness.scene import load_scene
        from sslpv_gl.params import SSLPVParams

        scene = load_scene("jade_backlit_dielectric").with_resolution(32, 32)
        params = SSLPVParams(N=16, steps=steps, mapping="diffusion", boundary_reflect="rdr", skip=0, rsm_size=256,
                             inject_size=64)
        gl_renderer.render(scene, params)
        accum = gl_renderer.read_accumulation(params)
        mat = gl_renderer.lpv_material(scene, params)
        assert mat["r_dr"] == pytest.approx(0.651, abs=5e-4)
        texels = gl_renderer.rsm_texels(scene, params)
        med = scene.medium
        c0 = sum(twin.inject(t, light.position, med.bbox_min, med.bbox_max, params.N, scene.boundary.eta)
                 for t, light in zip(texels, scene.lights))
        dx = float((np.asarray(med.bbox_max, float) - np.asarray(med.bbox_min, float))[0] / params.N)
        kw = dict(emit=mat["emit"], r_dr=mat["r_dr"], inside=mat["inside"])
        if steps == "steady":
            ref, k, left = steady.propagate_until(c0, mat["sigma_lpv"], mat["sigma_s_prime"], mat["g"], dx, tol=1e-7,
                                                  max_steps=20000, skip=0, **kw)
            assert left < 1e-7, (k, left)
        else:
            _, ref = twin.propagate(c0, mat["sigma_lpv"], mat["sigma_s_prime"], mat["g"], dx, steps, 0, **kw)
        scale = float(np.abs(ref[..., 0]).max())
        err = float(np.abs(accum - ref).max())
        print(f"rdr render K={steps}: max|GL - twin| / max|c00| = {err / scale:.2e}")
        assert err <= (1e-4 if steps != "steady" else 1e-5) * scale

    def test_index_matched_render_is_bit_identical(self, gl_renderer):
        from harness.scene import load_scene
        from sslpv_gl.params import SSLPVParams

        scene = load_scene("sphere_homogeneous").with_resolution(32, 32)
        params = SSLPVParams(N=16, steps=8, rsm_size=256, inject_size=64)
        a = gl_renderer.render(scene, params).subsurface
        b = gl_renderer.render(scene, params.replace(boundary_reflect="rdr")).subsurface
        np.testing.assert_array_equal(a, b)

    def test_dielectric_render_changes(self, gl_renderer):
        """On a dielectric scene the option changes the image (and the material cache tells the two apart)."""
        from harness.scene import load_scene
        from sslpv_gl.params import SSLPVParams

        scene = load_scene("skin_torus_dielectric").with_resolution(32, 32)
        params = SSLPVParams(N=16, steps=8, rsm_size=256, inject_size=64)
        a = gl_renderer.render(scene, params).subsurface
        b = gl_renderer.render(scene, params.replace(boundary_reflect="rdr")).subsurface
        c = gl_renderer.render(scene, params).subsurface
        np.testing.assert_array_equal(a, c)
        assert float(np.abs(a - b).max()) > 1e-3 * float(a.max())
