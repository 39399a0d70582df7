"""sslpv_gl.calibrated: the calibrated-mapping file, its budgets, and one line for every defect."""

from pathlib import Path

import pytest

from harness.errors import InputError
from sslpv_gl.calibrated import load_calibrated, parse_mapping

FAMILIES = ("literal", "collision", "diffusion")

SETTINGS = """[settings]
skip = 0
outside = "vacuum"
resample = "box"
lookup = "cell"
inject_size = 256
inject_offset = 0.0
precision = "fp32"
eta2 = false
"""

GOOD = """format = "sslpv-calibrated-mapping"
version = 2
family = "diffusion"
""" + SETTINGS + """[fit]
loss = "mean log relMSE"
[[budget]]
N = 32
steps = 8
sigma_scale = 1.5
radiance_scale = 0.8
[[budget]]
N = 32
steps = "steady"
sigma_scale = 1.1
radiance_scale = 0.9
sigma_scale_se = 0.01
"""


def write(tmp_path, text, name="cal.toml"):
    p = tmp_path / name
    p.write_bytes(text.encode("utf-8") if isinstance(text, str) else text)
    return p


def test_reads_budgets(tmp_path):
    cal = load_calibrated(write(tmp_path, GOOD), FAMILIES)
    assert cal.family == "diffusion" and len(cal.sha256) == 64
    b = cal.budget(32, "steady")
    assert (b.sigma_scale, b.radiance_scale, b.sigma_scale_se, b.radiance_scale_se) == (1.1, 0.9, 0.01, None)
    assert cal.budget(32, 8).sigma_scale == 1.5


def test_parse_mapping():
    assert parse_mapping("calibrated:a/b.toml") == "a/b.toml"
    assert parse_mapping("diffusion") is None


def test_hash_follows_content(tmp_path):
    a = load_calibrated(write(tmp_path, GOOD), FAMILIES)
    b = load_calibrated(write(tmp_path, GOOD.replace("1.5", "1.6")), FAMILIES)
    assert a.sha256 != b.sha256 and b.budget(32, 8).sigma_scale == 1.6


@pytest.mark.parametrize("text, field", [
    (GOOD.replace('family = "diffusion"', 'family = "magic"'), "family"),
    (GOOD.replace("version = 2", "version = 1"), "version"),
    (GOOD.replace(SETTINGS, ""), "settings"),
    (GOOD.replace("skip = 0\n", ""), "settings.skip"),
    (GOOD.replace("skip = 0", "skip = 0.5"), "settings.skip"),
    (GOOD.replace("eta2 = false", 'eta2 = "no"'), "settings.eta2"),
    (GOOD.replace("inject_offset = 0.0", "inject_offset = nan"), "settings.inject_offset"),
    (GOOD.replace("inject_offset = 0.0", "inject_offset = 0.0\ninject_depth = -1.0"), "settings.inject_depth"),
    (GOOD.replace("inject_offset = 0.0", "inject_offset = 0.0\ninject_depth = 17.0"), "settings.inject_depth"),
    (GOOD.replace("inject_offset = 0.0", "inject_offset = 0.0\nshade_depth = -0.5"), "settings.shade_depth"),
    (GOOD.replace("inject_offset = 0.0", "inject_offset = 0.0\nshade_depth = 4.5"), "settings.shade_depth"),
    (GOOD.replace("eta2 = false", "eta2 = false\nN = 32"), "settings.N"),
    (GOOD.replace('format = "sslpv-calibrated-mapping"', 'format = "other"'), "format"),
    (GOOD.replace("sigma_scale = 1.5", "sigma_scale = -1.0"), "budget[0].sigma_scale"),
    (GOOD.replace("sigma_scale = 1.5", 'sigma_scale = "big"'), "budget[0].sigma_scale"),
    (GOOD.replace("radiance_scale = 0.8", "radiance_scale = nan"), "budget[0].radiance_scale"),
    (GOOD.replace("N = 32\nsteps = 8", "N = 2\nsteps = 8"), "budget[0].N"),
    (GOOD.replace("steps = 8", 'steps = "forever"'), "budget[0].steps"),
    (GOOD.replace("steps = 8", 'steps = "steady"'), "budget[1]"),
    (GOOD.replace("sigma_scale_se = 0.01", "sigma_scale_se = -0.01"), "budget[1].sigma_scale_se"),
    (GOOD.replace("radiance_scale = 0.8", "radiance_scale = 0.8\ncolour = 1"), "budget[0].colour"),
    ("extra = 1\n" + GOOD, "extra"),
    ('format = "sslpv-calibrated-mapping"\nversion = 2\nfamily = "diffusion"\n' + SETTINGS, "budget"),
    ("this is = = not toml", "toml"),
    (b"\xff\xfe\x00binary", "toml"),
])
def test_bad_file_is_one_line(tmp_path, text, field):
    p = write(tmp_path, text)
    with pytest.raises(InputError) as exc:
        load_calibrated(p, FAMILIES)
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith(f"{p}: {field}:") and "; " in msg, msg


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        load_calibrated(tmp_path / "none.toml", FAMILIES)
    with pytest.raises(InputError, match="is not a file"):
        load_calibrated(tmp_path, FAMILIES)


def test_missing_budget_names_the_ones_there_are(tmp_path):
    cal = load_calibrated(write(tmp_path, GOOD), FAMILIES)
    with pytest.raises(InputError, match=r"no parameter set for N=16 steps=8.*N=32 steps=8, N=32 steps=steady"):
        cal.budget(16, 8)


class TestSettings:
    """A calibrated file holds only for the renderer settings it was fitted with."""

    def test_params_with_the_fitted_settings_resolve(self, tmp_path):
        from sslpv_gl.params import SSLPVParams

        p = write(tmp_path, GOOD)
        r = SSLPVParams(N=32, steps=8, skip=0, mapping=f"calibrated:{p}").resolved()
        assert (r.family, r.sigma_scale, r.radiance_scale) == ("diffusion", 1.5, 0.8)
        assert r.calibration["sha256"] == load_calibrated(p, FAMILIES).sha256

    @pytest.mark.parametrize("change, flag", [({"skip": 2}, "--skip"), ({"outside": "absorb"}, "--outside"),
                                              ({"eta2": True}, "--eta2"), ({"inject_size": 128}, "--inject-size")])
    def test_other_settings_are_refused_in_one_line(self, tmp_path, change, flag):
        from sslpv_gl.params import SSLPVParams

        p = write(tmp_path, GOOD)
        kw = dict(dict(N=32, steps=8, skip=0, mapping=f"calibrated:{p}"), **change)
        with pytest.raises(InputError) as exc:
            SSLPVParams(**kw)
        msg = str(exc.value)
        assert "\n" not in msg and msg.startswith(f"{flag}: ") and "was calibrated with" in msg and "pass " + flag in msg


class TestTheFilesSettings:
    """``--mapping calibrated:PATH`` alone renders with the settings the file was fitted with; a setting given
    explicitly with another value is refused in one line."""

    ABSORB = GOOD.replace('outside = "vacuum"', 'outside = "absorb"').replace("skip = 0", "skip = 1")

    def test_a_setting_not_given_is_the_files(self, tmp_path):
        from harness.methods import get_method

        p = write(tmp_path, self.ABSORB)
        params = get_method("sslpv").make_params(N=32, steps=8, mapping=f"calibrated:{p}")
        assert (params.outside, params.skip) == ("absorb", 1)
        assert params.resolved().sigma_scale == 1.5

    def test_a_plain_mapping_keeps_the_defaults(self, tmp_path):
        from harness.methods import get_method
        from sslpv_gl.params import SSLPVParams

        params = get_method("sslpv").make_params(N=32, steps=8, mapping="collision")
        assert params == SSLPVParams(N=32, steps=8, mapping="collision")

    def test_a_setting_given_with_another_value_is_refused(self, tmp_path):
        from harness.methods import get_method

        p = write(tmp_path, self.ABSORB)
        with pytest.raises(InputError) as exc:
            get_method("sslpv").make_params(N=32, steps=8, mapping=f"calibrated:{p}", outside="vacuum")
        msg = str(exc.value)
        assert "\n" not in msg and msg.startswith("--outside: ") and "pass --outside absorb" in msg
        assert get_method("sslpv").make_params(N=32, steps=8, mapping=f"calibrated:{p}", outside="absorb").skip == 1

    def test_a_sweep_product_gives_each_mapping_its_own(self, tmp_path):
        from harness.runs.params import expand

        p = write(tmp_path, self.ABSORB)
        got = expand({"mapping": ["collision", f"calibrated:{p}"], "N": [32], "steps": [8]})
        assert [(q.mapping.split(":")[0], q.outside, q.skip) for q in got] == [("collision", "vacuum", 2),
                                                                             ("calibrated", "absorb", 1)]


def test_a_relative_path_is_found_from_the_repository(tmp_path, monkeypatch):
    """Matrices name committed mappings relative to the repository; that works from any folder."""
    import shutil

    from sslpv_gl.calibrated import _REPO, resolve_path

    folder = _REPO / "test-artifacts" / "calibrated-resolve"
    folder.mkdir(parents=True, exist_ok=True)
    try:
        (folder / "c.toml").write_text(GOOD)
        monkeypatch.chdir(tmp_path)
        rel = "test-artifacts/calibrated-resolve/c.toml"
        assert resolve_path(rel) == folder / "c.toml"
        assert load_calibrated(rel, FAMILIES).path == str(folder / "c.toml")
        (tmp_path / "test-artifacts" / "calibrated-resolve").mkdir(parents=True)
        (tmp_path / rel).write_text(GOOD.replace("1.5", "1.7"))      # the current folder's comes first
        assert load_calibrated(rel, FAMILIES).budget(32, 8).sigma_scale == 1.7
        assert resolve_path("no/such.toml") == Path("no/such.toml")
    finally:
        shutil.rmtree(folder)


class TestTheFilesSettingsCommandLine:
    """Through ``sslpv-harness render`` with the committed calibrations fitted over extensions."""

    @pytest.fixture
    def cli(self, tmp_path, capsys, monkeypatch):
        from tests.test_bad_input import one_line_runner

        return one_line_runner(tmp_path, capsys, monkeypatch)

    @pytest.mark.parametrize("folder, flags, needle", [
        ("collision_absorb", ["--outside", "vacuum"], "--outside: outside: "),
        ("collision_delta_eddington", ["--phase-scaling", "none"], "--phase-scaling: phase_scaling: "),
        ("transport", ["--skip", "0"], "--skip: skip: "),
    ])
    def test_an_explicit_setting_of_another_extension_is_one_line(self, cli, folder, flags, needle):
        cli(["render", "thin_ring", "--out", "o", "--steps", "8", "--mapping",
             f"calibrated:baselines/calibrated/{folder}/calibrated.toml", *flags], needle, "was calibrated with")

    @pytest.mark.gl
    def test_the_mapping_alone_renders_as_with_the_files_flags(self, tmp_path, capsys):
        """The committed ``collision_absorb`` calibration: ``--mapping`` alone gives the image of ``--mapping`` with
        ``--outside absorb`` given, bit for bit, and records ``outside = absorb``; the plain family without the flag
        (``vacuum``) renders another image."""
        import json

        import numpy as np

        from harness.cli import main
        from harness.io.images import read_exr

        m = "calibrated:baselines/calibrated/collision_absorb/calibrated.toml"
        runs = {"alone": ["--mapping", m], "flag": ["--mapping", m, "--outside", "absorb"],
                "vacuum": ["--mapping", "collision", "--sigma-scale", "1", "--outside", "vacuum"]}
        imgs = {}
        for name, extra in runs.items():
            assert main(["render", "thin_ring", "--size", "small", "--steps", "8", "--out", str(tmp_path / name),
                         *extra]) == 0
            imgs[name] = read_exr(tmp_path / name / "subsurface.exr")["rgb"]
        capsys.readouterr()
        assert json.loads((tmp_path / "alone" / "render.json").read_text())["params"]["outside"] == "absorb"
        assert np.array_equal(imgs["alone"], imgs["flag"])
        assert not np.array_equal(imgs["alone"], imgs["vacuum"])
