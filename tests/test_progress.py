"""harness.progress: timestamped lines in a log, a bar on a terminal, nothing when off."""

import io
import re

import pytest

from harness.progress import Progress, format_duration, progress_mode

LINE = re.compile(r"^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ (?P<text>.*)$")


class Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def lines(buf):
    out = []
    for raw in buf.getvalue().splitlines():
        m = LINE.match(raw)
        assert m, f"not a timestamped line: {raw!r}"
        out.append(m["text"])
    return out


class TestMode:
    def test_log_file_gets_lines(self, monkeypatch):
        monkeypatch.delenv("SSLPV_PROGRESS", raising=False)
        assert progress_mode(io.StringIO()) == "lines"

    def test_environment_overrides(self, monkeypatch):
        monkeypatch.setenv("SSLPV_PROGRESS", "off")
        assert progress_mode(io.StringIO()) == "off"

    def test_disabled(self):
        assert progress_mode(io.StringIO(), enabled=False) == "off"


class TestLines:
    def test_first_last_and_throttled(self, monkeypatch):
        monkeypatch.setenv("SSLPV_PROGRESS", "lines")
        buf, clock = io.StringIO(), Clock()
        with Progress("sweep", total=4, stream=buf, every_s=5, clock=clock) as p:
            clock.t = 1.0
            p.advance(detail="a")                   # throttled: 1 s after the first line
            clock.t = 10.0
            p.advance(failed=1, detail="b")         # 10 s: written
            clock.t = 11.0
            p.advance(detail="c")                   # throttled
            clock.t = 20.0
            p.advance(detail="d")                   # the last: always written
        got = lines(buf)
        assert got[0] == "sweep: 0/4 configurations (0.0 %), elapsed 0:00:00, ETA ?"
        assert got[1] == "sweep: 2/4 configurations (50.0 %), 1 failed, elapsed 0:00:10, ETA 0:00:10; b"
        assert got[2] == "sweep: 4/4 configurations (100.0 %), 1 failed, elapsed 0:00:20, ETA 0:00:00; d"
        assert len(got) == 3                        # nothing repeated at exit

    def test_exit_writes_a_held_back_state(self, monkeypatch):
        monkeypatch.setenv("SSLPV_PROGRESS", "lines")
        buf, clock = io.StringIO(), Clock()
        with Progress("ref", total=10, unit="seeds", stream=buf, clock=clock) as p:
            clock.t = 1.0
            p.advance(3)
        assert lines(buf)[-1].startswith("ref: 3/10 seeds (30.0 %)")

    def test_caller_eta_and_log(self, monkeypatch):
        monkeypatch.setenv("SSLPV_PROGRESS", "lines")
        buf, clock = io.StringIO(), Clock()
        with Progress("reference x", total=None, unit="spp", stream=buf, clock=clock) as p:
            p.log("predicted 4,667 spp")
            clock.t = 30.0
            p.update(done=128, detail="median rel. SE 7.1 % (target 5 %)", eta_s=90.0)
        got = lines(buf)
        assert got[1] == "reference x: predicted 4,667 spp"
        assert got[2] == "reference x: 128 spp, elapsed 0:00:30, ETA 0:01:30; median rel. SE 7.1 % (target 5 %)"

    def test_off_prints_nothing(self):
        buf = io.StringIO()
        with Progress("sweep", total=2, stream=buf, enabled=False) as p:
            p.advance()
            p.log("x")
        assert buf.getvalue() == ""

    def test_closed_stream_does_not_raise(self, monkeypatch):
        monkeypatch.setenv("SSLPV_PROGRESS", "lines")
        buf = io.StringIO()
        p = Progress("sweep", total=2, stream=buf)
        buf.close()
        with p:
            p.advance(2)


def test_bar_mode_renders(monkeypatch):
    monkeypatch.setenv("SSLPV_PROGRESS", "bar")
    buf = io.StringIO()
    with Progress("sweep", total=2, stream=buf) as p:
        p.advance(detail="one")
        p.log("note")
        p.advance(detail="two")
    text = buf.getvalue()
    assert "sweep" in text and "2/2" in text and "note" in text


@pytest.mark.parametrize("s, text", [(0, "0:00:00"), (59.6, "0:01:00"), (3725, "1:02:05"), (None, "?"),
                                     (float("nan"), "?"), (-1, "?")])
def test_format_duration(s, text):
    assert format_duration(s) == text


@pytest.mark.parametrize("argv, target", [
    (["reference", "sphere_homogeneous", "--json"], ("harness.runs.references", "run_reference_cmd")),
    (["sweep", "--scenes", "thin_ring", "--grid", "8", "--steps", "4", "--out", "x", "--json"],
     ("harness.runs.sweep", "run_sweep")),
    (["calibrate", "--family", "diffusion", "--out", "x", "--json"], ("harness.calibration.run", "run_calibrate")),
])
def test_json_never_silences_progress(monkeypatch, argv, target):
    """``--json`` puts the result on stdout; progress still goes to stderr (only ``--no-progress`` stops it)."""
    import importlib

    from harness.cli import main

    seen = {}
    monkeypatch.setattr(importlib.import_module(target[0]), target[1],
                        lambda *a, **k: seen.update(k) or {"status": "finished"})
    main(argv)
    assert seen.get("progress") is True, seen
    seen.clear()
    main(argv + ["--no-progress"])
    assert seen.get("progress") is False, seen
