"""Baselines and small references: validation errors, the update command, and the
statistical check that guards a regenerated reference."""

import json
import shutil

import numpy as np
import pytest

from harness.regression import baselines
from harness.reference import committed
from harness.cli import main
from harness.errors import InputError


@pytest.fixture()
def sandbox(tmp_path, monkeypatch):
    """A copy of the committed baselines that a test may change."""
    root = tmp_path / "baselines"
    shutil.copytree(baselines.BASELINE_DIR, root)
    monkeypatch.setattr(baselines, "BASELINE_DIR", root)
    monkeypatch.setattr(baselines, "REF_DIR", root / "refs")
    monkeypatch.setattr(committed, "REF_DIR", root / "refs")   # where a sweep looks for them
    monkeypatch.setattr(baselines, "MATRIX_FILE", root / "accuracy_matrix.toml")
    return root


class TestValidation:
    def test_committed_baselines_are_valid(self):
        entries = baselines.all_baselines()
        assert len(entries) >= 8 and all(len(e) >= 4 for e in entries.values())

    def test_baseline_for_a_scene_that_no_longer_exists(self, sandbox):
        shutil.copy(sandbox / "thin_ring.json", sandbox / "gone_scene.json")
        data = json.loads((sandbox / "gone_scene.json").read_text())
        data["scene"] = "gone_scene"
        (sandbox / "gone_scene.json").write_text(json.dumps(data))
        with pytest.raises(InputError, match=r"gone_scene\.json: scene: scene 'gone_scene' no longer exists.*delete"):
            baselines.all_baselines()

    def test_baseline_from_a_different_scene_hash(self, sandbox):
        path = sandbox / "thin_ring.json"
        data = json.loads(path.read_text())
        data["entries"][0]["scene_hash"] = "0" * 64
        path.write_text(json.dumps(data))
        with pytest.raises(InputError, match=r"thin_ring\.json: .*scene_hash: baseline was made for scene hash "
                                             r"000000000000 but the scene now hashes to"):
            baselines.read_baseline("thin_ring")

    def test_missing_reference(self, sandbox):
        shutil.rmtree(sandbox / "refs" / "thin_ring")
        from harness.regression.accuracy import small_scene

        with pytest.raises(InputError, match=r"refs/thin_ring: reference: is missing; run `sslpv-harness baselines "
                                             r"regenerate-references --scenes thin_ring`"):
            baselines.committed_reference(small_scene("thin_ring"))

    def _entry(self, scene="thin_ring"):
        from sslpv_gl.params import SSLPVParams

        return baselines.find_entry(baselines.read_baseline(scene), [64, 64], SSLPVParams(N=16, steps=8).as_dict())

    def test_committed_images_exist_for_every_accuracy_case(self):
        from harness.regression.accuracy import cases, small_scene
        from harness.runs.params import config_label

        for scene, params, _ in cases():
            cam = small_scene(scene).camera                  # 64x64; a non-square scene keeps its aspect
            size = [cam.width, cam.height]
            e = baselines.find_entry(baselines.read_baseline(scene), size, params.as_dict())
            assert e is not None and e["image"] == baselines.image_name(scene, config_label(params), size)
            assert e["gl_renderer"] and (baselines.BASELINE_DIR / e["image"]).is_file()
        img, mask = baselines.committed_image("thin_ring", self._entry())
        assert img.shape == (64, 64, 3) and mask.dtype == bool and mask.any()

    def test_missing_committed_image(self, sandbox):
        e = self._entry()
        (sandbox / e["image"]).unlink()
        with pytest.raises(InputError, match=r"images/thin_ring/N16-K8-collision-64x64\.exr: file: the committed "
                                             r"SSLPV image of thin_ring N16-K8-collision is missing; run a `sweep "
                                             r"--size small` .*baselines update"):
            baselines.committed_image("thin_ring", e)

    def test_committed_image_of_the_wrong_size(self, sandbox):
        from harness.io.images import write_exr

        e = self._entry()
        write_exr(sandbox / e["image"], np.zeros((32, 32, 3)), extra={"mask": np.ones((32, 32))})
        with pytest.raises(InputError, match=r"N16-K8-collision-64x64\.exr: size: is 32x32, the baseline entry "
                                             r"is 64x64; run a `sweep --size small`"):
            baselines.committed_image("thin_ring", e)

    def test_reference_without_standard_error(self, sandbox):
        from harness.io.images import read_exr, write_exr
        from harness.regression.accuracy import case_reference, reference_se, small_scene

        path = sandbox / "refs" / "thin_ring" / "subsurface.exr"
        write_exr(path, read_exr(path)["rgb"])
        ref = case_reference(small_scene("thin_ring"))
        with pytest.raises(InputError, match=r"refs/thin_ring/subsurface\.exr: se: has no per-pixel standard error "
                                             r".*regenerate-references"):
            reference_se(ref)

    def test_update_with_no_store(self, capsys):
        assert main(["baselines", "update"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--store: store: is required" in err[0]

    def test_update_with_missing_store(self, tmp_path, capsys):
        assert main(["baselines", "update", "--store", str(tmp_path / "nope.sqlite")]) == 2
        assert "no results store at" in capsys.readouterr().err

    def test_update_whose_renders_are_gone(self, sandbox, tmp_path, capsys):
        from harness.regression.accuracy import small_scene
        from harness.store import Store
        from sslpv_gl.params import SSLPVParams

        store = tmp_path / "store.sqlite"
        with Store(store) as st:
            rid = st.start_run("sweep", {})
            st.record_config(rid, "thin_ring", small_scene("thin_ring").content_hash, SSLPVParams(N=16, steps=8)
                             .as_dict(), "ok", metrics=[], render_dir=str(tmp_path / "gone"),
                             reference_dir=str(sandbox / "refs" / "thin_ring"))
        before = (sandbox / "thin_ring.json").read_text()
        assert main(["baselines", "update", "--store", str(store)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "thin_ring N16-K8-collision.render_dir: the SSLPV image" in err[0] and "re-run" in err[0]
        assert (sandbox / "thin_ring.json").read_text() == before


def _store_with_a_changed_entry(sandbox, tmp_path):
    """A store whose latest run holds thin_ring N16-K8 with every value x 1.5 and a flat image:
    ``(store, params, old entry, image)``."""
    from harness.io.images import write_exr
    from harness.regression.accuracy import small_scene
    from harness.store import Store
    from sslpv_gl.params import SSLPVParams

    scene = small_scene("thin_ring")
    params = SSLPVParams(N=16, steps=8).as_dict()
    old = baselines.find_entry(baselines.read_baseline("thin_ring"), [64, 64], params)
    rows = [{"image": img, "metric": m, "value": v["value"] * 1.5, "noise_floor": v["noise_floor"],
             "per_channel": None, "params": {}}
            for img, ms in old["metrics"].items() for m, v in ms.items()]
    render = tmp_path / "render"
    render.mkdir()
    img = np.full((64, 64, 3), 0.25, np.float32)
    write_exr(render / "subsurface.exr", img, extra={"mask": np.ones((64, 64), np.float32)})
    store = tmp_path / "store.sqlite"
    with Store(store) as st:
        rid = st.start_run("accuracy", {}, gl_renderer="test GL")
        st.record_config(rid, "thin_ring", scene.content_hash, params, "ok", metrics=rows,
                         render_dir=str(render), reference_dir=str(sandbox / "refs" / "thin_ring"))
    return store, params, old, img


class TestUpdate:
    def test_show_with_a_store_prints_what_update_would_change_and_writes_nothing(self, sandbox, tmp_path, capsys):
        store, _, old, _ = _store_with_a_changed_entry(sandbox, tmp_path)
        files = {p: p.read_bytes() for p in sandbox.rglob("*") if p.is_file()}
        assert main(["baselines", "show", "--store", str(store)]) == 0
        out = capsys.readouterr().out
        assert "baseline update" in out and "N16-K8" in out and "before" in out
        assert main(["baselines", "show", "--store", str(store), "--json"]) == 0
        changes = [c for c in json.loads(capsys.readouterr().out)["changes"] if c["metric"] == "relmse"]
        assert changes[0]["before"] == pytest.approx(old["metrics"]["subsurface"]["relmse"]["value"])
        assert changes[0]["after"] == pytest.approx(1.5 * changes[0]["before"])
        assert {p: p.read_bytes() for p in sandbox.rglob("*") if p.is_file()} == files

    def test_update_shows_before_after_and_changes_only_that_entry(self, sandbox, tmp_path):
        before_files = {p.name: p.read_text() for p in sandbox.glob("*.json")}
        store, params, old, img = _store_with_a_changed_entry(sandbox, tmp_path)
        image_files = {p: p.read_bytes() for p in (sandbox / "images").rglob("*.exr")}
        res = baselines.update(store, scene="thin_ring")
        new = baselines.find_entry(baselines.read_baseline("thin_ring"), [64, 64], params)
        assert new["gl_renderer"] == "test GL" and res["images"] == [str(sandbox / new["image"])]
        assert np.array_equal(baselines.committed_image("thin_ring", new)[0], img)
        changed_images = {p for p, b in image_files.items() if p.read_bytes() != b}
        assert changed_images == {sandbox / new["image"]}      # only that case's image
        changed = [r for r in res["changes"] if r["metric"] == "relmse"]
        assert len(changed) == 1
        assert changed[0]["before"] == pytest.approx(old["metrics"]["subsurface"]["relmse"]["value"])
        assert changed[0]["after"] == pytest.approx(1.5 * changed[0]["before"])
        after_files = {p.name: p.read_text() for p in sandbox.glob("*.json")}
        assert {k for k in before_files if before_files[k] != after_files[k]} == {"thin_ring.json"}
        new_entries = baselines.read_baseline("thin_ring")
        assert len(new_entries) == len(json.loads(before_files["thin_ring.json"])["entries"])
        others = [e for e in new_entries if e["params"] != params]
        assert len(others) == len(new_entries) - 1
        assert all(e in json.loads(before_files["thin_ring.json"])["entries"] for e in others)
        assert "before" in baselines.format_changes(res["changes"])


class TestReferenceAgreement:
    def images(self, rng, sigma, shift=0.0):
        truth = rng.uniform(0.2, 1.0, size=(64, 64, 3))
        se = np.full_like(truth, sigma)
        a = {"rgb": truth + rng.normal(0, sigma, truth.shape), "se": se}
        b = {"rgb": truth + shift + rng.normal(0, sigma, truth.shape), "se": se}
        return a, b

    def test_independent_estimates_agree(self):
        rng = np.random.default_rng(1)
        rejections = sum(not baselines.reference_agreement(*self.images(rng, 0.02))["agree"] for _ in range(50))
        # Bonferroni at 1% family-wise: expect ~0.5 of 50; 3 or more would mean a broken test statistic.
        assert rejections <= 2

    def test_a_biased_pixel_is_caught(self):
        rng = np.random.default_rng(2)
        a, b = self.images(rng, 0.02)
        b["rgb"][10, 10, 0] += 0.02 * 8 * np.sqrt(2)  # 8 standard deviations of the difference
        res = baselines.reference_agreement(a, b)
        assert not res["agree"] and res["t_max"] > 7

    def test_estimated_errors_use_students_t(self):
        """With SEs estimated from K = 8 seeds, |t| = 5.9 is not significant over 12288 tests; with known
        errors (a z-test) it would be."""
        a = {"rgb": np.zeros((64, 64, 3)), "se": np.full((64, 64, 3), 0.1)}
        b = {"rgb": np.zeros((64, 64, 3)), "se": np.full((64, 64, 3), 0.1)}
        b["rgb"][5, 5, 0] = 5.9 * np.sqrt(0.02)
        assert baselines.reference_agreement(a, b, k_old=8, k_new=8)["agree"]
        assert not baselines.reference_agreement(a, b)["agree"]

    def test_a_global_bias_is_caught(self):
        res = baselines.reference_agreement(*self.images(np.random.default_rng(3), 0.02, shift=0.05))
        assert not res["agree"]

    def test_regenerate_refuses_a_disagreeing_reference(self, sandbox, monkeypatch):
        from harness.io.images import read_exr, write_exr
        from harness.reference import render as ref_render

        dest = sandbox / "refs" / "thin_ring"
        before = {p.name: p.read_bytes() for p in dest.iterdir()}

        def biased_render(scene, out, **kw):
            out.mkdir(parents=True, exist_ok=True)
            for f in dest.iterdir():
                shutil.copy(f, out / f.name)
            for part in ("subsurface", "full"):
                d = read_exr(dest / f"{part}.exr")
                write_exr(out / f"{part}.exr", d["rgb"] * 1.3 + 0.05, se=d["se"])
            return {}

        monkeypatch.setattr(ref_render, "render_reference", biased_render)
        monkeypatch.setattr(baselines, "REPO", sandbox.parent)
        with pytest.raises(InputError, match=r"disagrees with the committed one .*nothing was replaced"):
            baselines.regenerate_reference("thin_ring")
        assert {p.name: p.read_bytes() for p in dest.iterdir()} == before
