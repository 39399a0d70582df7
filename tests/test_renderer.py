"""End-to-end GL SSLPV renders, parameter validation and the context-failure path."""

import json

import numpy as np
import pytest

from harness.errors import InputError
from harness.scene import load_scene
from sslpv_gl.params import SSLPVParams

SMALL = dict(N=16, steps=8, rsm_size=256, inject_size=64)


@pytest.fixture(scope="module")
def renderer():
    from sslpv_gl.context import GLContextError
    from sslpv_gl.renderer import SSLPVRenderer

    try:
        return SSLPVRenderer()
    except GLContextError as exc:
        pytest.skip(str(exc))


@pytest.fixture(scope="module")
def scenes():
    return {name: load_scene(name).with_resolution(64, 64) for name in ("absorbing_sphere", "layered_dielectric")}


@pytest.mark.gl
class TestRender:
    @pytest.mark.parametrize("name", ["absorbing_sphere", "layered_dielectric"])
    def test_end_to_end(self, renderer, scenes, name):
        res = renderer.render(scenes[name], SSLPVParams(**SMALL))
        for img in (res.full, res.subsurface):
            assert img.shape == (64, 64, 3) and img.dtype == np.float32
            assert np.all(np.isfinite(img))
        assert res.mask.shape == (64, 64) and res.mask.dtype == bool and res.mask.any()
        peak = res.subsurface.max()
        assert peak > 0.0
        # two-band SH can ring slightly negative; it must stay tiny
        assert res.subsurface.min() >= -1e-3 * peak, f"min {res.subsurface.min()} vs peak {peak}"
        assert np.all(res.full[~res.mask] == 0.0)
        for stage in ("rsm", "injection", "propagation", "shading"):
            assert res.timings_ms[stage] > 0.0 and np.isfinite(res.timings_ms[stage]), stage
        assert res.gl_renderer
        assert res.warnings == [], res.warnings

    def test_index_matched_full_is_subsurface(self, renderer, scenes):
        res = renderer.render(scenes["absorbing_sphere"], SSLPVParams(**SMALL))
        np.testing.assert_array_equal(res.full, res.subsurface)

    def test_dielectric_adds_reflection(self, renderer, scenes):
        res = renderer.render(scenes["layered_dielectric"], SSLPVParams(**SMALL))
        refl = res.full - res.subsurface
        assert refl.min() >= 0.0
        assert refl.max() > 0.0

    def test_fp16_runs_and_is_close(self, renderer, scenes):
        a = renderer.render(scenes["absorbing_sphere"], SSLPVParams(**SMALL))
        b = renderer.render(scenes["absorbing_sphere"], SSLPVParams(**SMALL, precision="fp16"))
        assert np.all(np.isfinite(b.full))
        assert np.abs(b.full - a.full).max() <= 1e-2 * a.full.max()

    def test_trilinear_lookup_runs(self, renderer, scenes):
        res = renderer.render(scenes["absorbing_sphere"], SSLPVParams(**SMALL, lookup="trilinear"))
        assert np.all(np.isfinite(res.full)) and res.full.max() > 0.0

    def test_deterministic(self, renderer, scenes):
        p = SSLPVParams(**SMALL)
        a = renderer.render(scenes["layered_dielectric"], p)
        b = renderer.render(scenes["layered_dielectric"], p)
        np.testing.assert_array_equal(a.full, b.full)

    def test_run_render_writes_folder(self, renderer, tmp_path):
        from harness.imageio import read_exr
        from sslpv_gl.render_cmd import run_render

        out = tmp_path / "r"
        info = run_render("absorbing_sphere", out, SSLPVParams(**SMALL), as_json=True, renderer=renderer)
        assert {p.name for p in out.iterdir()} == {"full.exr", "subsurface.exr", "preview.png", "render.json"}
        meta = json.loads((out / "render.json").read_text())
        assert meta["params"]["N"] == 16 and meta["content_hash"] == info["content_hash"]
        assert set(meta["timings_ms"]) >= {"rsm", "injection", "propagation", "shading"}
        sub = read_exr(out / "subsurface.exr")
        assert "mask" in sub and sub["mask"].shape == (meta["height"], meta["width"])


class TestParams:
    @pytest.mark.parametrize("kwargs,needle", [
        ({"N": 0}, "N"), ({"N": 300}, "N"), ({"steps": -1}, "steps"), ({"mapping": "bogus"}, "mapping"),
        ({"lookup": "nearest"}, "lookup"), ({"precision": "fp64"}, "precision"), ({"resample": "x"}, "resample"),
    ])
    def test_bad_values_one_line(self, kwargs, needle):
        with pytest.raises(InputError) as err:
            SSLPVParams(**kwargs)
        msg = str(err.value)
        assert "\n" not in msg and needle in msg

    def test_unknown_choice_lists_allowed(self):
        with pytest.raises(InputError, match="literal") as err:
            SSLPVParams(mapping="bogus")
        assert "collision" in str(err.value)

    def test_defaults_are_the_papers(self):
        p = SSLPVParams()
        assert (p.N, p.steps, p.skip, p.rsm_size, p.inject_size) == (32, 32, 2, 1024, 256)
        assert all(SSLPVParams.doc(name) for name in p.as_dict())


class TestContext:
    def test_egl_failure_is_one_line(self, monkeypatch):
        import moderngl

        from sslpv_gl.context import GLContextError, create_context

        def boom(*a, **k):
            raise Exception("eglGetDisplay failed\nsecond line")

        monkeypatch.setattr(moderngl, "create_standalone_context", boom)
        with pytest.raises(GLContextError) as err:
            create_context()
        msg = str(err.value)
        assert msg.startswith("cannot create an EGL OpenGL context (eglGetDisplay failed)")
        assert "\n" not in msg

    def test_old_gl_is_named(self, monkeypatch):
        import moderngl

        from sslpv_gl.context import GLContextError, create_context

        class Old:
            version_code = 330

            def release(self):
                pass

        def fake(*a, require=None, **k):
            if require:
                raise Exception("requested OpenGL 4.3, got 3.3")
            return Old()

        monkeypatch.setattr(moderngl, "create_standalone_context", fake)
        with pytest.raises(GLContextError, match=r"^OpenGL 4.3 is required, got 3.3$"):
            create_context()

    def test_is_environment_problem(self):
        from harness.errors import EnvironmentProblem
        from sslpv_gl.context import GLContextError

        assert issubclass(GLContextError, EnvironmentProblem)
