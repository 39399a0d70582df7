"""The GL renderer's outside modes, radiance scales and step modes agree with the NumPy twin.

* propagation with sink cells (``emit``, :mod:`sslpv_gl.boundary`) against ``twin.propagate``;
* whole renders under ``absorb``/``extrapolated``, the ``diffusion`` mapping's per-cell radiance
  scale and the calibration scales: the accumulation and the shaded image against the twin;
* ``render_steps`` bit-identical to ``render`` at every K; ``steps = auto`` stops where it says;
* ``steps = steady`` against the twin iterated to convergence.
Tolerances as in ``test_gl_vs_twin.py`` (fp32: 1e-4 of max|c00| for grids, 1e-5 of the image maximum
for shading away from cell faces).
"""

import numpy as np
import pytest

from harness.scene import load_scene
from sslpv_gl import boundary, bounded, steady, twin
from sslpv_gl.params import SSLPVParams

pytestmark = pytest.mark.gl

RTOL_GRID = 1e-4
SHADE_WORST = 1e-5


def _check_grid(gl, ref, label, rtol=RTOL_GRID):
    scale = float(np.abs(ref[..., 0]).max())
    err = float(np.abs(gl - ref).max())
    assert scale > 0.0, f"{label}: reference grid is empty"
    print(f"{label}: max|GL - twin| / max|c00| = {err / scale:.2e} (<= {rtol})")
    assert err <= rtol * scale, f"{label}: max|GL - twin| = {err:.3e} > {rtol} * {scale:.3e}"


def _twin_c0(renderer, scene, params):
    texels = renderer.rsm_texels(scene, params)
    med = scene.medium
    return sum(twin.inject(t, l.position, med.bbox_min, med.bbox_max, params.N, scene.boundary.eta,
                           params.inject_offset) for t, l in zip(texels, scene.lights))


def _dx(scene, N):
    med = scene.medium
    return float((np.asarray(med.bbox_max, float) - np.asarray(med.bbox_min, float))[0] / N)


class TestSinks:
    @pytest.mark.parametrize("mode", ["absorb", "extrapolated"])
    def test_propagation_with_sinks(self, gl_renderer, mode):
        N, dx = 10, 0.1
        rng = np.random.default_rng(7)
        c = (np.arange(N) + 0.5) / N - 0.5
        z, y, x = np.meshgrid(c, c, c, indexing="ij")
        inside = x**2 + y**2 + z**2 < 0.35**2
        _, emit = boundary.outside_masks(inside, mode, np.array([0.6, 1.2, 2.0]), bounded.partial_sink_offsets())
        if mode == "extrapolated":                   # partial sinks (Eq. (B4)): fractional emit through the GL path
            assert ((emit > 0) & (emit < 1)).any()
        mat = {"sigma_lpv": rng.uniform(0, 5, (N, N, N, 3)).astype(np.float32),
               "sigma_s_prime": rng.uniform(0, 1, (N, N, N, 3)).astype(np.float32),
               "g": rng.uniform(-0.5, 0.9, (N, N, N, 3)).astype(np.float32),
               "emit": emit.astype(np.float32)}
        c0 = np.abs(rng.normal(0, 1, (N, N, N, 3, 4))).astype(np.float32)
        prop, acc = gl_renderer.propagate(c0, mat, dx, 9, 2, "fp32")
        ref_prop, ref_acc = twin.propagate(c0, mat["sigma_lpv"], mat["sigma_s_prime"], mat["g"], dx, 9, 2,
                                           emit=mat["emit"])
        _check_grid(prop, ref_prop, f"prop {mode}")
        _check_grid(acc, ref_acc, f"accum {mode}")
        # power: without the sinks the grids differ far beyond the tolerance
        _, acc_vac = twin.propagate(c0, mat["sigma_lpv"], mat["sigma_s_prime"], mat["g"], dx, 9, 2)
        assert np.abs(acc_vac - ref_acc).max() > 100 * RTOL_GRID * np.abs(ref_acc[..., 0]).max()


CASES = [
    ("sphere_homogeneous", dict(mapping="diffusion", outside="absorb", skip=0)),
    ("jade_veins", dict(mapping="diffusion", outside="extrapolated", skip=0, lookup="trilinear")),
    ("layered_dielectric", dict(mapping="collision", outside="extrapolated", sigma_scale=1.7,
                                radiance_scale=0.6, eta2=True)),
]


class TestModesEndToEnd:
    @pytest.mark.parametrize("name,kw", CASES)
    def test_accumulation_and_shading(self, gl_renderer, name, kw):
        scene = load_scene(name).with_resolution(48, 48)
        params = SSLPVParams(N=16, steps=10, rsm_size=256, inject_size=64, **kw)
        res = gl_renderer.render(scene, params, diagnostics=True)
        accum = gl_renderer.read_accumulation(params)
        mat = gl_renderer.lpv_material(scene, params)
        c0 = _twin_c0(gl_renderer, scene, params)
        ref_prop, ref = twin.propagate(c0, mat["sigma_lpv"], mat["sigma_s_prime"], mat["g"], _dx(scene, params.N),
                                       params.steps, params.skip, emit=mat["emit"])
        _check_grid(accum, ref, f"{name} {kw}: accumulation")
        # the diagnostics (read back as band-0 coefficients only) against the twin's whole grids
        d = res.diagnostics
        flux = np.sqrt(4 * np.pi) * np.abs(c0[..., 0].astype(np.float64)).sum(axis=(0, 1, 2))
        assert d["injected_flux"] == pytest.approx(flux.tolist(), rel=1e-4)
        acc0 = np.abs(ref[..., 0].astype(np.float64))
        assert d["outside_share"] == pytest.approx(acc0[~mat["inside"]].sum() / acc0.sum(), abs=1e-4)
        assert d["remaining_fraction"] == pytest.approx(steady.remaining_fraction(ref_prop, c0), rel=1e-4)
        # shading: the twin applies the per-cell scale times the global calibration scale
        m = res.mask
        view = np.asarray(scene.camera.origin) - res.position[m]
        view /= np.linalg.norm(view, axis=1, keepdims=True)
        bmin, bmax = scene.medium.bbox_min, scene.medium.bbox_max
        scale = np.asarray(mat["radiance_scale"], np.float64) * params.radiance_scale
        ref_img = twin.shade_points(accum, bmin, bmax, res.position[m], res.normal[m], params.lookup,
                                    scene.boundary.eta, view, eta2=params.eta2, radiance_scale=scale)
        err = np.abs(res.subsurface[m] - ref_img).max(axis=1) / np.abs(ref_img).max()
        u = (res.position[m] - np.asarray(bmin)) / ((np.asarray(bmax) - np.asarray(bmin)) / params.N)
        keep = np.abs(u - np.round(u)).min(axis=1) > 1e-4 if params.lookup == "cell" else np.ones(len(err), bool)
        worst = float(err[keep].max())
        print(f"{name} {kw}: shading worst {worst:.2e} of max")
        tol = SHADE_WORST if ("llvmpipe" in gl_renderer.gl_renderer or params.lookup == "cell") else 1e-2
        assert worst <= tol
        # power: shading without the radiance scale is off by far more than the tolerance
        plain = twin.shade_points(accum, bmin, bmax, res.position[m], res.normal[m], params.lookup,
                                  scene.boundary.eta, view, eta2=params.eta2)
        assert np.abs(plain - ref_img).max() > 100 * tol * np.abs(ref_img).max()
        d = res.diagnostics
        assert d["steps_used"] == 10 and 0.0 <= d["outside_share"] <= 1.0 and d["remaining_fraction"] > 0.0


class TestStepModes:
    @pytest.mark.parametrize("kw", [dict(), dict(mapping="diffusion", outside="absorb", skip=0),
                                    dict(lookup="trilinear", precision="fp16")])
    def test_render_steps_bit_identical(self, gl_renderer, kw):
        scene = load_scene("two_lights").with_resolution(32, 32)
        params = SSLPVParams(N=16, rsm_size=256, inject_size=64, **kw)
        ks = [k for k in (0, 1, 2, 5, 12) if k >= params.skip]    # K < skip is refused, alone or grouped
        group = gl_renderer.render_steps(scene, params, ks)
        assert [r.steps_used for r in group] == ks
        for k, r in zip(ks, group):
            alone = gl_renderer.render(scene, params.replace(steps=k))
            assert np.array_equal(r.full, alone.full) and np.array_equal(r.subsurface, alone.subsurface), k
        # propagation timings grow with K: each is the time of the steps up to it
        props = [r.timings_ms["propagation"] for r in group]
        assert props == sorted(props)

    def test_render_steps_refuses_modes(self, gl_renderer):
        from harness.errors import InputError

        scene = load_scene("two_lights").with_resolution(32, 32)
        with pytest.raises(InputError, match="snapshots need step counts"):
            gl_renderer.render_steps(scene, SSLPVParams(N=8), [8, "auto"])

    def test_auto_stops_at_convergence(self, gl_renderer):
        scene = load_scene("sphere_homogeneous").with_resolution(32, 32)
        params = SSLPVParams(N=16, steps="auto", converge_tol=1e-2, rsm_size=256, inject_size=64,
                             outside="absorb")
        res = gl_renderer.render(scene, params)
        k = res.steps_used
        assert k >= 16 and k % 8 == 0 and res.diagnostics["remaining_fraction"] < 1e-2
        # the check one chunk earlier had not converged yet, and K steps alone give the same image
        earlier = gl_renderer.render(scene, params.replace(steps=k - 8), diagnostics=True)
        assert earlier.diagnostics["remaining_fraction"] >= 1e-2
        alone = gl_renderer.render(scene, params.replace(steps=k))
        assert np.array_equal(alone.subsurface, res.subsurface)

    def test_auto_cap(self, gl_renderer):
        scene = load_scene("absorbing_sphere").with_resolution(32, 32)
        res = gl_renderer.render(scene, SSLPVParams(N=16, steps="auto", converge_tol=1e-9, max_steps=12,
                                                    rsm_size=256, inject_size=64))
        assert res.steps_used == 12 and any("not converged" in w for w in res.warnings)

    @pytest.mark.parametrize("kw", [dict(outside="absorb"), dict(mapping="diffusion", outside="extrapolated", skip=0)])
    def test_steady_matches_iterated_twin(self, gl_renderer, kw):
        scene = load_scene("absorbing_sphere").with_resolution(32, 32)
        params = SSLPVParams(N=16, steps="steady", rsm_size=256, inject_size=64, **kw)
        res = gl_renderer.render(scene, params)
        assert res.steps_used is None and res.diagnostics["outside_share"] < 1.0
        accum = gl_renderer.read_accumulation(params)
        mat = gl_renderer.lpv_material(scene, params)
        c0 = _twin_c0(gl_renderer, scene, params)
        _, ref = twin.propagate(c0, mat["sigma_lpv"], mat["sigma_s_prime"], mat["g"], _dx(scene, params.N),
                                1200, params.skip, emit=mat["emit"])
        _check_grid(accum, ref, f"steady {kw}")
