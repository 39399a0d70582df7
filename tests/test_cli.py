"""The command line's behaviour around its commands: a bare call, ``--version``, sub-commands,
``--out`` as a folder, the order ``compare`` prints in, and the one-line errors of a misspelt scene."""

import json

import numpy as np
import pytest

from harness.cli import main
from harness.cli.main import DESCRIPTION, version
from harness.store import Store


def _one_error_line(capsys):
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1 and err[0].startswith("error: "), err
    return err[0]


class TestUsage:
    def test_bare_call_prints_the_usage(self, capsys):
        assert main([]) == 2
        captured = capsys.readouterr()
        assert captured.out == ""
        assert captured.err.startswith("usage: sslpv-harness") and "baselines" in captured.err
        assert DESCRIPTION in " ".join(captured.err.split()) and "``" not in captured.err

    def test_bare_command_with_sub_commands_prints_its_usage(self, capsys):
        assert main(["baselines"]) == 2
        err = capsys.readouterr().err
        assert err.startswith("usage: sslpv-harness baselines")
        assert all(a in err for a in ("update", "show", "regenerate-references"))

    def test_version(self, capsys):
        with pytest.raises(SystemExit) as exc:
            main(["--version"])
        assert exc.value.code == 0
        assert capsys.readouterr().out.strip() == f"sslpv-harness {version()}"

    @pytest.mark.parametrize("argv,needle", [
        (["rendr", "thin_ring"], "sslpv-harness: command: unknown command 'rendr'; did you mean render?"),
        (["baselines", "shw"], "sslpv-harness baselines: command: unknown command 'shw'; did you mean show?"),
    ])
    def test_misspelt_command_offers_the_closest(self, capsys, argv, needle):
        assert main(argv) == 2
        assert needle in _one_error_line(capsys)

    def test_sub_command_options_are_its_own(self, capsys):
        """``--into`` belongs to regenerate-references only; update refuses it, naming itself."""
        assert main(["baselines", "update", "--store", "s.sqlite", "--into", "x"]) == 2
        assert "--into: into: is not an option of `sslpv-harness baselines update`" in _one_error_line(capsys)


class TestFlags:
    @pytest.mark.parametrize("flags,values", [([], None), (["--eta2"], [True]), (["--no-eta2"], [False]),
                                              (["--eta2", "--no-eta2"], [True, False])])
    def test_sweep_takes_a_boolean_as_flags(self, tmp_path, flags, values):
        """A sweep's boolean is ``--eta2`` and/or ``--no-eta2``; both sweep both values."""
        from harness.cli.main import build_parser
        from harness.runs.sweep import config_from_args

        args = build_parser().parse_args(["sweep", "--out", str(tmp_path / "s"), "--scenes", "thin_ring", *flags])
        assert config_from_args(args).params.get("eta2") == values

    def test_render_takes_a_flag_not_a_word(self, tmp_path, capsys, monkeypatch):
        monkeypatch.chdir(tmp_path)
        assert main(["render", "thin_ring", "--out", "o", "--eta2", "true"]) == 2
        assert "'true' is not expected here; a flag such as --eta2 takes no value" in _one_error_line(capsys)


class TestScenes:
    def test_misspelt_scene_names_the_path_once_and_the_closest_scene(self, tmp_path, capsys, monkeypatch):
        monkeypatch.chdir(tmp_path)
        assert main(["render", "thn_ring", "--out", "o"]) == 2
        line = _one_error_line(capsys)
        assert line.count("scene.toml") == 1 and "did you mean thin_ring?" in line, line
        assert not (tmp_path / "o").exists()

    def test_scenes_validates_one_scene_positionally(self, capsys):
        assert main(["scenes", "thin_ring", "--json"]) == 0
        rows = json.loads(capsys.readouterr().out)["scenes"]
        assert [r["name"] for r in rows] == ["thin_ring"]


class TestCompare:
    def test_prints_in_the_order_of_its_arguments(self, tmp_path, capsys):
        from harness.io.images import write_exr

        rng = np.random.default_rng(0)
        ref, test = tmp_path / "ref.exr", tmp_path / "test.exr"
        write_exr(ref, rng.uniform(0.1, 1.0, (32, 32, 3)).astype(np.float32))
        write_exr(test, rng.uniform(0.1, 1.0, (32, 32, 3)).astype(np.float32))
        assert main(["compare", str(ref), str(test)]) == 0
        lines = capsys.readouterr().out.splitlines()
        assert lines[0] == f"ref  {ref}" and lines[1] == f"test {test}"
        assert main(["compare", str(ref), str(test), "--json"]) == 0
        result = json.loads(capsys.readouterr().out)
        assert list(result)[:2] == ["ref", "test"] and result["ref"] == str(ref)


    def test_images_too_small_for_a_metric_are_one_line(self, tmp_path, capsys):
        from harness.io.images import write_exr

        for name in ("ref.exr", "test.exr"):
            write_exr(tmp_path / name, np.full((8, 8, 3), 0.5, np.float32))
        assert main(["compare", str(tmp_path / "ref.exr"), str(tmp_path / "test.exr")]) == 2
        line = _one_error_line(capsys)
        assert "test.exr: metrics: ssim: images of 8x8 are smaller than the 11x11 window" in line, line


class TestExport:
    @pytest.fixture
    def store(self, tmp_path):
        path = tmp_path / "store.sqlite"
        with Store(path) as st:
            rid = st.start_run("sweep", {"scenes": ["thin_ring", "slab"]})
            for scene, h in (("thin_ring", "a"), ("slab", "b")):
                st.record_config(rid, scene, h * 64, {"N": 8, "steps": 4}, "ok", timings={"total": 1.0},
                                 metrics=[{"image": "subsurface", "metric": "relmse", "value": 0.1,
                                           "noise_floor": 0.01}])
            st.finish_run(rid, "finished")
        return path

    def test_out_is_a_folder(self, tmp_path, store, capsys):
        out = tmp_path / "table"
        assert main(["export", str(store), "--out", str(out), "--json"]) == 0
        result = json.loads(capsys.readouterr().out)
        assert result["file"] == str(out / "results.csv") and result["rows"] == 2
        assert len((out / "results.csv").read_text().splitlines()) == 3

    def test_scenes_selects_several(self, tmp_path, store, capsys):
        assert main(["export", str(store), "--out", str(tmp_path / "t"), "--scenes", "slab", "--json"]) == 0
        assert json.loads(capsys.readouterr().out)["rows"] == 1
        assert main(["export", str(store), "--out", str(tmp_path / "u"), "--scenes", "slab,thin_ring",
                     "--json"]) == 0
        assert json.loads(capsys.readouterr().out)["rows"] == 2

    def test_a_file_name_is_refused_with_the_folder_form(self, tmp_path, store, capsys, monkeypatch):
        monkeypatch.chdir(tmp_path)
        assert main(["export", str(store), "--out", "x.parquet"]) == 2
        line = _one_error_line(capsys)
        assert "--out: out: 'x.parquet' names a file, but --out is a folder; write --out . --format parquet" in line
        assert not (tmp_path / "x.parquet").exists()


class TestBaselinesShow:
    def test_table(self, capsys):
        assert main(["baselines", "show", "--scenes", "thin_ring"]) == 0
        out = capsys.readouterr().out
        assert "committed baselines" in out and "thin_ring" in out and "relmse" in out
        assert not out.lstrip().startswith("{")

    def test_json(self, capsys):
        assert main(["baselines", "show", "--scenes", "thin_ring", "--json"]) == 0
        entries = json.loads(capsys.readouterr().out)
        assert list(entries) == ["thin_ring"] and entries["thin_ring"][0]["config"]

    def test_misspelt_scene(self, capsys):
        assert main(["baselines", "show", "--scenes", "thin_rign"]) == 2
        assert "--scenes: scenes: unknown scene 'thin_rign'; did you mean thin_ring?" in _one_error_line(capsys)
