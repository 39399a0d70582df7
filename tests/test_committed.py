"""The committed small size (``harness.reference.committed``): a non-square scene keeps its aspect."""

import pytest

from harness.errors import InputError
from harness.reference.committed import find_committed_reference, sized_scene, small_scene, small_size
from harness.regression.accuracy import small_scene as accuracy_scene
from harness.runs.sweep import parse_size
from harness.scene import list_scenes, load_scene


@pytest.mark.parametrize("size,small", [((128, 128), [64, 64]), ((64, 64), [64, 64]), ((160, 96), [60, 36]),
                                        ((96, 160), [36, 60]), ((1280, 720), [64, 36]), ((100, 37), [64, 24])])
def test_small_size(size, small):
    assert small_size(*size) == small


def test_exact_aspect_where_possible():
    for w, h in ((160, 96), (1280, 720), (300, 200), (128, 96)):
        sw, sh = small_size(w, h)
        assert sw * h == sh * w and max(sw, sh) <= 64, (w, h, sw, sh)


def test_sized_scene():
    scene = load_scene("wide_slab")
    assert sized_scene(scene, None) is scene
    small = sized_scene(scene, "small")
    assert (small.camera.width, small.camera.height) == (60, 36)
    assert small.content_hash == small_scene(scene).content_hash == accuracy_scene("wide_slab").content_hash
    assert (sized_scene(scene, [32, 20]).camera.width, sized_scene(scene, [32, 20]).camera.height) == (32, 20)


def test_every_suite_scene_has_its_committed_reference():
    missing = [n for n in list_scenes() if find_committed_reference(small_scene(load_scene(n))) is None]
    assert not missing, f"no committed small reference for the current version of: {', '.join(missing)}"


def test_parse_size():
    assert parse_size("small") == "small" and parse_size("Small") == "small"
    assert parse_size("160x96") == [160, 96] and parse_size(None) is None
    with pytest.raises(InputError, match="or small"):
        parse_size("64")


def test_small_in_sweep_json_and_nightly_matrix(tmp_path):
    """``size = "small"`` is a valid size of a sweep.json and of a nightly matrix; other sizes keep their rules."""
    import json

    from harness.regression.nightly import load_matrix
    from harness.runs.sweep import SweepConfig

    cfg = SweepConfig(scenes=["wide_slab"], params={"N": [8]}, out=str(tmp_path / "o"), size="small")
    path = tmp_path / "sweep.json"
    path.write_text(cfg.to_json())
    assert json.loads(path.read_text())["size"] == "small" and SweepConfig.from_file(path).size == "small"
    path.write_text(cfg.to_json().replace('"small"', '"tiny"'))
    with pytest.raises(InputError, match="size"):
        SweepConfig.from_file(path)
    m = tmp_path / "m.toml"
    m.write_text('scenes = ["wide_slab"]\nsize = "small"\n[params]\ngrid = [8]\n')
    assert load_matrix(m)["size"] == "small"


def test_smooth_dielectric_references_are_exact_and_rendered_as_their_scene_says():
    """A suite scene behind a smooth dielectric keeps a committed reference whose ``reference.json`` says
    ``"exact": true`` (the exactness verdict, :mod:`harness.reference.losses`), rendered with the connections its
    scene names: ``max_crossings`` and ``sms_trials`` leave the content hash alone at their defaults, so a
    reference rendered before they existed (no ``max_crossings`` in its integrator: one crossing) would pass the
    hash check unnoticed."""
    import json

    checked = []
    for name in list_scenes():
        scene = load_scene(name)
        b = scene.boundary
        if b.kind != "dielectric" or b.roughness != 0.0:
            continue
        ref = find_committed_reference(small_scene(scene))
        meta = json.loads((ref / "reference.json").read_text())
        assert meta.get("exact") is True, f"{name}: {meta.get('exact_note', 'no exactness verdict recorded')}"
        integ = meta["integrator"]
        for d in (integ.values() if "type" not in integ else [integ]):
            assert int(d.get("max_crossings", 1)) == b.max_crossings, f"{name}: rendered with {d}"
            assert int(d.get("sms_trials", 0)) == b.sms_trials, f"{name}: rendered with {d}"
            if b.sms_trials:
                assert d.get("sms_chains") == b.sms_chains, f"{name}: rendered with {d}"
        checked.append(name)
    assert len(checked) >= 2, f"the suite's smooth-dielectric scenes: {checked}"
