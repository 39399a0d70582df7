"""harness.methods.extension_outside: the outside treatment an SSLPV extension renders with when none is given.

The committed choice (written by ``sslpv-harness study --docs``) applies to a configuration that turns on an
extension and gives no ``outside``: never to the published method, never over an explicit setting or a
calibrated file's, and where the configuration refuses it, the next treatment of the file it accepts that beat
the paper's.
"""

import json

import pytest

from harness.errors import InputError
from harness.methods import extension_outside as eo
from harness.methods.sslpv import SSLPVMethod
from sslpv_gl.params import SSLPVParams


def _choice(tmp_path, outside="extrapolated", by_mode=None, **extra):
    by_mode = {"extrapolated": 0.9, "interior": 0.95, "absorb": 1.3} if by_mode is None else by_mode
    path = tmp_path / "outside.json"
    path.write_text(json.dumps({"format": eo.FORMAT, "version": 1, "outside": outside, "by_mode": by_mode,
                                "median_ratio": by_mode.get(outside, 1.0), "command": "sslpv-harness study --docs",
                                "commit": "0" * 40} | extra))
    return path


def _apply(fields, path):
    return eo.with_extension_outside(fields, SSLPVParams, path)


class TestWhichConfigurations:
    def test_an_extension_without_outside_gets_the_choice(self, tmp_path):
        path = _choice(tmp_path)
        assert _apply({"phase_scaling": "delta-eddington"}, path)["outside"] == "extrapolated"
        assert _apply({"eta2": True}, path)["outside"] == "extrapolated"
        assert _apply({"inject_offset": 0.1}, path)["outside"] == "extrapolated"

    def test_the_published_method_keeps_the_papers(self, tmp_path):
        path = _choice(tmp_path)
        for fields in ({}, {"mapping": "collision", "N": 32, "steps": 8}, {"phase_scaling": "none", "eta2": False}):
            assert "outside" not in _apply(fields, path)

    def test_an_explicit_outside_is_never_changed(self, tmp_path):
        path = _choice(tmp_path)
        assert _apply({"phase_scaling": "delta-eddington", "outside": "vacuum"}, path)["outside"] == "vacuum"

    def test_a_calibrated_mapping_keeps_its_files_settings(self, tmp_path):
        path = _choice(tmp_path)
        m = "calibrated:baselines/calibrated/collision_delta_eddington/calibrated.toml"
        assert "outside" not in _apply({"mapping": m, "phase_scaling": "delta-eddington"}, path)
        assert SSLPVMethod().make_params(mapping=m, N=32, steps=8).outside == "vacuum"

    def test_no_file_leaves_the_papers(self, tmp_path):
        assert "outside" not in _apply({"phase_scaling": "delta-eddington"}, tmp_path / "none.json")

    def test_the_paper_chosen_leaves_the_papers(self, tmp_path):
        path = _choice(tmp_path, outside="vacuum", by_mode={"extrapolated": 1.1, "absorb": 2.0})
        assert "outside" not in _apply({"phase_scaling": "delta-eddington"}, path)


class TestARefusedChoice:
    def test_rdr_takes_the_next_it_accepts(self, tmp_path):
        """``boundary_reflect = rdr`` refuses ``extrapolated``: ``interior`` (0.95 < 1) is the next."""
        path = _choice(tmp_path)
        assert _apply({"boundary_reflect": "rdr"}, path)["outside"] == "interior"

    def test_transport_takes_the_next_it_accepts(self, tmp_path):
        path = _choice(tmp_path)
        assert _apply({"mapping": "transport"}, path)["outside"] == "interior"

    def test_none_better_than_the_paper_leaves_the_refusal(self, tmp_path):
        """Only ``extrapolated`` beat the paper: ``transport`` gets nothing and is refused in one line, as before."""
        path = _choice(tmp_path, by_mode={"extrapolated": 0.9, "interior": 1.2, "absorb": 1.3})
        assert "outside" not in _apply({"mapping": "transport"}, path)
        assert "outside" not in _apply({"boundary_reflect": "rdr"}, path)
        with pytest.raises(InputError, match="outside"):
            SSLPVParams(**_apply({"mapping": "transport"}, path))


class TestTheMethod:
    def test_make_params_applies_the_committed_file(self, tmp_path, monkeypatch):
        monkeypatch.setattr(eo, "CHOICE", _choice(tmp_path))
        m = SSLPVMethod()
        p = m.make_params(mapping="collision", N=32, steps=8, phase_scaling="delta-eddington")
        assert p.outside == "extrapolated"
        assert "outside=extrapolated" in m.label(p)    # the label names it, as any non-default setting
        assert m.make_params(mapping="collision", N=32, steps=8).outside == "vacuum"

    def test_the_command_line_and_a_sweeps_products(self, tmp_path, monkeypatch):
        """``render``'s flags and a sweep's lists reach it: only the settings given count as given."""
        from harness.methods.params import expand, params_from_cli

        monkeypatch.setattr(eo, "CHOICE", _choice(tmp_path))
        assert params_from_cli("sslpv", {"phase_scaling": "delta-eddington"}).outside == "extrapolated"
        assert params_from_cli("sslpv", {"phase_scaling": "delta-eddington", "outside": "absorb"}).outside == "absorb"
        assert params_from_cli("sslpv", {"steps": "8"}).outside == "vacuum"
        got = expand("sslpv", {"phase_scaling": ["none", "delta-eddington"], "boundary_reflect": ["none", "rdr"]})
        assert [p.outside for p in got] == ["vacuum", "interior", "extrapolated", "interior"]


class TestTheFile:
    @pytest.mark.parametrize("content, field", [
        ("{not json", "file"),
        (json.dumps({"format": "other"}), "format"),
        (json.dumps({"format": eo.FORMAT, "outside": "extrapolated", "by_mode": {"leaky": 0.5}}), "by_mode"),
        (json.dumps({"format": eo.FORMAT, "outside": "extrapolated", "by_mode": {"absorb": "low"}}), "by_mode"),
        (json.dumps({"format": eo.FORMAT, "outside": "leaky", "by_mode": {"absorb": 0.5}}), "outside"),
    ])
    def test_a_bad_file_is_one_line(self, tmp_path, content, field):
        path = tmp_path / "outside.json"
        path.write_text(content)
        with pytest.raises(InputError) as exc:
            _apply({"phase_scaling": "delta-eddington"}, path)
        assert exc.value.field == field and "sslpv-harness study --docs" in str(exc.value)

    def test_write_then_read(self, tmp_path):
        choice = {"outside": "interior", "median_ratio": 0.8, "by_mode": {"interior": 0.8, "absorb": 1.5},
                  "scenes": {"interior": 34, "absorb": 34}}
        path = eo.write_choice(choice, {"command": "c", "commit": "abc", "study_sha256": "s", "created": "t"},
                               tmp_path / "sub" / "outside.json")
        back = eo.committed_choice(path)
        assert back["outside"] == "interior" and back["by_mode"] == choice["by_mode"] and back["commit"] == "abc"
        assert eo.write_choice(None, {}, tmp_path / "none.json") is None and not (tmp_path / "none.json").exists()

    def test_the_committed_file_is_the_docs_choice(self):
        """The committed choice names the treatment ``docs/results.md`` names, from the same study."""
        choice = eo.committed_choice()
        assert choice is not None, "no committed choice: run sslpv-harness study --docs"
        text = (eo.paths.REPO / "docs" / "results.md").read_text()
        assert f"Outside treatment for the extensions, by that measure: **{choice['outside']}**" in text
        assert f"at commit `{choice['commit']}`" in text
