"""A calibration's scan through the result cache (``harness.calibration.scan``): served bit for bit, keyed on
everything a render depends on, never shared with a sweep's entries, and a bad entry rendered again.

The unit tests use a counting stand-in for the renderer (its image a function of the parameters); the
end-to-end test runs ``sslpv-harness calibrate`` twice on the GL renderer and checks that the second
run renders nothing and writes the same calibration.
"""

import json
from types import SimpleNamespace

import numpy as np
import pytest

from harness.calibration.scan import Scanner
from harness.cli import main
from harness.runs.cache import ResultCache, open_cache, result_key
from sslpv_gl.params import SSLPVParams

H, W = 4, 5


class Counting:
    """Renders an image that depends on (sigma_scale, steps, outside); counts its GL calls."""

    gl_renderer = "counting stand-in"

    def __init__(self):
        self.calls = 0

    def _image(self, p, k):
        v = p.sigma_scale * (1.0 + (0.0 if k == "steady" else 1.0 / k)) * (2.0 if p.outside == "absorb" else 1.0)
        img = np.full((H, W, 3), v, np.float32) + np.arange(H * W * 3, dtype=np.float32).reshape(H, W, 3) * 1e-3
        return SimpleNamespace(subsurface=img, full=img * 1.5, mask=np.ones((H, W), bool), gl_renderer=self.gl_renderer,
                               steps_used=None if k == "steady" else k, diagnostics={}, warnings=[], timings_ms={})

    def render(self, scene, params):
        self.calls += 1
        return self._image(params, params.steps)

    def render_steps(self, scene, params, steps):
        self.calls += 1
        return [self._image(params, k) for k in steps]


def _ref():
    m = np.ones((H, W), bool)
    r = np.ones((H, W, 3))
    return {"mask": m, "subsurface": r, "half_a": r, "half_b": r}


SCENES = {"a": SimpleNamespace(content_hash="hash-a"), "b": SimpleNamespace(content_hash="hash-b")}
BUDGETS = [(8, 4), (8, 8), (8, "steady")]


def _scan(renderer, cache, base=None, s_values=(0.5, 2.0)):
    sc = Scanner(renderer, SCENES, {n: _ref() for n in SCENES}, base or SSLPVParams(mapping="collision"), BUDGETS,
                 cache=cache)
    for n in SCENES:
        for s in s_values:
            sc.render(n, s)
    return sc


def test_a_second_scan_is_served_bit_for_bit(tmp_path):
    cache = ResultCache(tmp_path / "c")
    first = _scan(Counting(), cache)
    assert first.renders == 2 * 2 * 2 and first.served == 0          # scenes x s x (grouped ints, steady)
    again = Counting()
    second = _scan(again, cache)
    assert again.calls == 0 and second.served == 2 * 2 * 3
    assert first.images.keys() == second.images.keys()
    for key, img in first.images.items():
        assert np.array_equal(img, second.images[key]), key
    for key, smp in first.samples.items():
        assert smp.u == second.samples[key].u


@pytest.mark.parametrize("change", ["sigma_scale", "setting", "scene", "renderer"])
def test_anything_a_render_depends_on_is_in_the_key(tmp_path, change):
    cache = ResultCache(tmp_path / "c")
    _scan(Counting(), cache)
    r = Counting()
    if change == "sigma_scale":
        _scan(r, cache, s_values=(0.5, 3.0))
        assert r.calls == 2 * 2                                       # only s = 3 is new
        return
    if change == "setting":
        _scan(r, cache, base=SSLPVParams(mapping="collision", outside="absorb"))
    elif change == "scene":
        SCENES["a"].content_hash = "hash-a2"
        try:
            _scan(r, cache)
        finally:
            SCENES["a"].content_hash = "hash-a"
        assert r.calls == 2 * 2                                       # scene a alone is rendered again
        return
    else:
        r.gl_renderer = "another GPU"
        _scan(r, cache)
    assert r.calls == 2 * 2 * 2


def test_a_scan_entry_is_never_a_sweeps(tmp_path):
    """The same configuration keys apart in a sweep (a worker's result with its timings) and in a scan."""
    sc = _scan(Counting(), None)
    p = SSLPVParams(mapping="collision").replace(N=8, steps=4, sigma_scale=0.5)
    assert sc._key("a", 8, 4, 0.5) != result_key("sslpv", "hash-a", p.as_dict(), None, Counting.gl_renderer)


def test_without_a_cache_everything_is_rendered(tmp_path):
    r = Counting()
    _scan(r, None)
    _scan(r, None)
    assert r.calls == 2 * 2 * 2 * 2
    assert open_cache(False, "calibrate") is None and open_cache(None, "calibrate") is None


def test_a_bad_entry_is_rendered_again_with_one_line(tmp_path):
    lines = []
    cache = ResultCache(tmp_path / "c", log=lines.append)
    _scan(Counting(), cache)
    key = _scan(Counting(), None)._key("a", 8, 4, 0.5)
    (cache.entry(key) / "images.npz").write_bytes(b"not an npz")
    r = Counting()
    sc = _scan(r, cache)
    assert r.calls == 1 and len(lines) == 1 and "do not match their recorded hash" in lines[0], lines
    assert np.array_equal(sc.image((8, 4), "a", 0.5), _scan(Counting(), None).image((8, 4), "a", 0.5))


@pytest.mark.gl
def test_calibrate_twice_renders_once(tmp_path, capsys):
    """``sslpv-harness calibrate`` run again renders nothing and writes the same calibration; ``--no-cache`` renders
    everything again, to the same figures (the cache is exact)."""
    args = ["calibrate", "--family", "collision", "--scenes", "sphere_homogeneous,thin_ring", "--grid", "8",
            "--steps", "4,steady", "--points", "5", "--no-progress", "--json"]

    def run(out, *extra):
        assert main(args + ["--out", str(tmp_path / out), *extra]) == 0
        summary = json.loads(capsys.readouterr().out)
        return summary, json.loads((tmp_path / out / "calibration.json").read_text())

    s1, c1 = run("one")
    s2, c2 = run("two")
    s3, c3 = run("three", "--no-cache")
    assert s1["renders"] > 0 and s1["served_from_cache"] == 0
    assert s2["renders"] == 0 and s2["served_from_cache"] > 0
    assert s3["renders"] == s1["renders"] and s3["served_from_cache"] == 0
    def body(out):                                    # the fitted budgets (the [fit] table names the time)
        return (tmp_path / out / "calibrated.toml").read_text().split("[[budget]]", 1)[1]

    assert body("one") == body("two") == body("three")
    for c in (c2, c3):
        assert c["results"] == c1["results"]
