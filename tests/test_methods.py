"""The method interface (``harness.methods``): parameters per method, labels, the store's method column,
and the one-line refusals of bad input (unknown method, a parameter of another method, a rival on a scene it
cannot represent). No rendering except where a refusal needs the scene (about 10 s)."""

import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from dipole_gl.params import DipoleParams
from harness.errors import InputError
from harness.methods import METHOD_NAMES, config_label, get_method, parse_methods
from harness.methods.params import expand, params_from_cli, products
from harness.store import Store
from harness.store.schema import MIGRATIONS

REPO = Path(__file__).resolve().parent.parent


def cli(*args):
    return subprocess.run([sys.executable, "-m", "harness.cli", *args], capture_output=True, text=True, cwd=REPO,
                          timeout=300)


def one_line_error(proc, *fragments):
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    for f in fragments:
        assert f in lines[0], lines[0]
    assert "Traceback" not in proc.stderr
    return lines[0]


class TestRegistry:
    def test_names_and_defaults(self):
        assert METHOD_NAMES == ("sslpv", "dipole", "dirpole")
        assert parse_methods(None) == ["sslpv"] and parse_methods("dipole, sslpv,dipole") == ["dipole", "sslpv"]
        for name in METHOD_NAMES:
            m = get_method(name)
            assert m.name == name and m.stages and m.title
        with pytest.raises(InputError, match="unknown method 'dipol'; use one of: sslpv, dipole, dirpole"):
            parse_methods("dipol")

    def test_products_give_each_method_its_own_parameters(self):
        prods = products(["sslpv", "dipole"], {"grid": "16,32", "gather": "dense,vertex", "spacing": "1,0.5",
                                                "density": "0.5", "steps": None})
        assert prods == [{"method": "sslpv", "N": [16, 32]},
                         {"method": "dipole", "gather": ["dense"], "spacing": [1.0, 0.5]},
                         {"method": "dipole", "gather": ["vertex"], "density": [0.5]}]
        dense = expand("dipole", {k: v for k, v in prods[1].items() if k != "method"})
        assert [p.as_dict() for p in dense] == [{"gather": "dense", "spacing": 1.0, "shadow_size": 1024, "terms": "both"},
                                                {"gather": "dense", "spacing": 0.5, "shadow_size": 1024, "terms": "both"}]
        assert config_label("dipole", dense[1]) == "dipole-gather=dense-shadow_size=1024-spacing=0.5-terms=both"
        assert config_label("sslpv", {"N": 16, "steps": 8, "mapping": "collision"}) == "N16-K8-collision"

    @pytest.mark.parametrize("methods,values,match", [
        (["dipole"], {"grid": "16"}, "--grid: grid: is a parameter of sslpv, not of dipole; drop --grid or add sslpv"),
        (["sslpv"], {"spacing": "1"}, "--spacing: spacing: is a parameter of dipole and dirpole, not of sslpv"),
        (["dirpole"], {"gather": "dense", "range": "3"}, "--range: range: belongs to gather=vertex"),
        (["dipole"], {"gather": "splat"}, "--gather: gather: unknown gather 'splat'; use one of: dense, vertex, cubemap, "
                                        "hierarchical, atlas"),
        (["dipole"], {"spacing": "0"}, r"--spacing: spacing: must be a number in \[0.05, 10\], got 0.0"),
        (["dipole"], {"density": "x"}, "--density: density: 'x' is not a number"),
        (["dipole"], {"fit": "auto"}, "--fit: fit: unknown value 'auto'; use one of: refuse, coarsen"),
    ])
    def test_bad_parameters(self, methods, values, match):
        with pytest.raises(InputError, match=match):
            for prod in products(methods, values):
                expand(prod.pop("method"), prod)

    def test_render_takes_one_value(self):
        assert params_from_cli("dirpole", {"gather": "vertex", "range": "2"}).range == 2.0
        with pytest.raises(InputError, match="takes one value here"):
            params_from_cli("dipole", {"spacing": "1,2"})


class TestSizingRule:
    """``fit = coarsen`` (``dipole_gl.sizing``): the chosen setting fits the budget on marble_sphere, and on a
    scene where the default fits it is the default."""

    def test_dense_spacing(self):
        from dipole_gl.medium import scene_material
        from dipole_gl.sampling import MAX_FRAME_PAIRS, MAX_SAMPLES, sample_count
        from dipole_gl.sizing import dense_spacing
        from harness.regression.accuracy import small_scene

        for name, coarsened in (("marble_sphere", True), ("sphere_homogeneous", False)):
            scene = small_scene(name)
            mat = scene_material(scene)
            pixels = scene.camera.width * scene.camera.height
            default = DipoleParams().spacing
            used = dense_spacing(scene.mesh, mat.mfp, default, pixels)
            count = sample_count(scene.mesh, used * mat.mfp)
            assert count <= MAX_SAMPLES and pixels * count <= MAX_FRAME_PAIRS, (name, used, count)
            assert (used > default) == coarsened and (coarsened or used == default), (name, used)
            if coarsened:                          # just enough: 1 % finer does not fit
                assert pixels * sample_count(scene.mesh, 0.99 * used * mat.mfp) > MAX_FRAME_PAIRS, (name, used)

    def test_refusal_names_the_gathers_own_budget(self):
        """Where no spacing fits, the dense gather's line names its pixel-sample budget and the hierarchical
        gather's names the octree's samples alone (its cost does not grow as pixels x samples)."""
        from dipole_gl.medium import scene_material
        from dipole_gl.sampling import MAX_SAMPLES
        from dipole_gl.sizing import dense_spacing
        from harness.regression.accuracy import small_scene

        scene = small_scene("sphere_homogeneous")
        tiny = scene_material(scene).mfp * 1e-3           # 10 l' is then 1 % of a mean free path
        with pytest.raises(InputError) as dense:
            dense_spacing(scene.mesh, tiny, 1.0, 4096)
        assert "for 4,096 pixels" in str(dense.value) and "--gather hierarchical" in str(dense.value)
        with pytest.raises(InputError) as tree:
            dense_spacing(scene.mesh, tiny, 1.0)
        message = str(tree.value)
        assert f"over the {MAX_SAMPLES:,} samples the octree takes" in message and "pixels" not in message
        assert "--gather vertex or atlas" in message

    def test_vertex_density(self):
        from dipole_gl.medium import scene_material
        from dipole_gl.sizing import FIT_SHARE, estimated_pairs, mesh_area, vertex_density
        from dipole_gl.vertex import MAX_PAIRS
        from harness.regression.accuracy import small_scene

        for name, coarsened in (("marble_sphere", True), ("sphere_homogeneous", False)):
            scene = small_scene(name)
            mat = scene_material(scene)
            used = vertex_density(scene.mesh, mat.mfp, mat.diffusion_length, 0.5, 2.0)
            est = estimated_pairs(mesh_area(scene.mesh), mat.mfp, mat.diffusion_length, used, 2.0)
            assert est <= FIT_SHARE * MAX_PAIRS and (used < 0.5) == coarsened and (coarsened or used == 0.5), \
                (name, used, est)


class TestStore:
    def test_sslpv_keys_unchanged_and_methods_apart(self):
        p = {"N": 32, "steps": 16}
        assert Store.config_key("h", p) == Store.config_key("h", p, "sslpv")
        assert Store.config_key("h", p, "dipole") != Store.config_key("h", p)

    def test_a_v2_store_migrates_and_its_rows_are_sslpv(self, tmp_path):
        path = tmp_path / "old.sqlite"
        db = sqlite3.connect(path, isolation_level=None)
        db.execute("BEGIN")
        for i, mig in enumerate(MIGRATIONS[:2]):
            mig(db)
            db.execute(f"PRAGMA user_version = {i + 1}")
        db.execute("INSERT INTO runs (kind, started_at, date, versions_json, machine_json, config_json, status)"
                   " VALUES ('sweep', '2026-01-01T00:00:00+00:00', '2026-01-01', '{}', '{}', '{}', 'finished')")
        key = Store.config_key("h", {"N": 8, "steps": 4})
        db.execute("INSERT INTO configurations (run_id, scene, scene_hash, config_key, params_json, status, created_at)"
                   " VALUES (1, 'slab', 'h', ?, '{\"N\":8,\"steps\":4}', 'ok', '2026-01-01T00:00:00+00:00')", (key,))
        db.execute("COMMIT")
        db.close()
        with Store(path) as st:
            assert st.user_version == len(MIGRATIONS) >= 3
            (c,) = st.configs()
            assert c["method"] == "sslpv" and c["precompute"] is None and c["work"] is None
            assert st.done_keys(1) == {key}                      # a resumed SSLPV sweep skips it, as before
            st.record_config(1, "slab", "h", {"gather": "dense"}, "ok", method="dipole",
                             timings={"gather": 2.0, "total": 2.0}, stages=get_method("dipole").stages,
                             precompute={"sampling": {"ms": 1.0, "work": 10}}, work={"gather": 100})
            rows = {r["method"]: r for r in st.configs()}
            assert rows["dipole"]["work"] == {"gather": 100} and rows["dipole"]["timings"]["gather"] == 2.0
            with pytest.raises(InputError, match="unknown stage 'gather'"):
                st.record_config(1, "slab", "h", {"N": 9}, "ok", timings={"gather": 1.0})


def _scene_with_albedo_zero(tmp_path):
    src = (REPO / "reference_scenes" / "absorbing_sphere" / "scene.toml").read_text()
    d = tmp_path / "black_sphere"
    d.mkdir()
    (d / "scene.toml").write_text(src.replace("value = [0.6, 0.6, 0.6]", "value = [0.0, 0.0, 0.0]"))
    return d


class TestBadInputOneLine:
    def test_unknown_method(self, tmp_path):
        one_line_error(cli("render", "thin_ring", "--method", "dipol", "--out", str(tmp_path / "r")),
                       "--method: method: unknown method 'dipol'")
        one_line_error(cli("sweep", "--method", "sslpv,atlas", "--out", str(tmp_path / "s")), "unknown method 'atlas'")
        assert not (tmp_path / "s").exists()

    def test_parameter_of_another_method(self, tmp_path):
        one_line_error(cli("render", "thin_ring", "--method", "dipole", "--grid", "16", "--out", str(tmp_path / "r")),
                       "--grid: grid: is a parameter of sslpv, not of dipole", "add sslpv to --method")
        one_line_error(cli("sweep", "--method", "dirpole", "--steps", "8", "--out", str(tmp_path / "s")),
                       "--steps: steps: is a parameter of sslpv, not of dirpole")
        assert not (tmp_path / "s").exists()

    def test_rival_on_a_scene_it_cannot_represent(self, tmp_path):
        scene = _scene_with_albedo_zero(tmp_path)
        line = one_line_error(cli("render", str(scene), "--method", "dipole", "--out", str(tmp_path / "r")),
                              "medium.albedo: method dipole needs a scattering medium", "albedo 0",
                              "--method sslpv")
        assert not (tmp_path / "r").exists(), line
        one_line_error(cli("sweep", "--scenes", str(scene), "--method", "dirpole", "--out", str(tmp_path / "s")),
                       "method dirpole needs a scattering medium")
        assert not (tmp_path / "s").exists()

    def test_unknown_fit(self, tmp_path):
        one_line_error(cli("render", "thin_ring", "--method", "dipole", "--fit", "shrink", "--out", str(tmp_path / "r")),
                       "error: --fit: fit: unknown value 'shrink'; use one of: refuse, coarsen")
        assert not (tmp_path / "r").exists()

    def test_nightly_matrix_of_another_method(self, tmp_path):
        from harness.regression.nightly import load_matrix

        m = tmp_path / "m.toml"
        m.write_text('scenes = ["thin_ring"]\n[params]\ngrid = [8]\nsteps = [4]\n'
                     '[[also]]\nmethod = "dipole"\ngather = ["vertex"]\ngrid = [8]\n')
        with pytest.raises(InputError, match=r"also\[0\]\.grid: is not a known field; use only: adaptive, atlas_size, "
                                             r"cube_size, density, disc_radius, eps_b, eps_c, eps_g, epsilon, fit, frames, "
                                             r"gather, light_size, link_level, links, method, range, samples, shadow_size, "
                                             r"spacing, terms"):
            load_matrix(m)
        m.write_text('scenes = ["thin_ring"]\n[params]\ngrid = [8]\n[[also]]\nmethod = "atlas"\ngather = ["x"]\n')
        with pytest.raises(InputError, match=r"also\[0\]\.method: unknown method 'atlas'"):
            load_matrix(m)


class TestReportAndExport:
    def test_methods_view_table_and_export(self, tmp_path):
        """A run with SSLPV and two rivals: the scene page's methods view (table, images, plots), the index's
        methods table, and the export's method, work and per-stage columns (about 5 s)."""
        import csv

        import numpy as np

        from harness.io import images as imageio
        from harness.metrics import compare_images
        from harness.report import build_report

        h, w = 24, 32
        y, x = np.mgrid[0:h, 0:w]
        ref = (np.exp(-((x - 16) ** 2 + (y - 12) ** 2) / 60.0)[..., None] * np.array([1.0, 0.6, 0.3])).astype(np.float32)
        mask = (ref.mean(axis=-1) > 1e-3).astype(np.float32)
        rng = np.random.default_rng(3)
        half_a = np.clip(ref + rng.normal(0, 0.01, ref.shape), 0, None).astype(np.float32)
        half_b = np.clip(2 * ref - half_a, 0, None).astype(np.float32)
        rdir = tmp_path / "ref"
        imageio.write_exr(rdir / "subsurface.exr", ref, extra={"mask": mask})
        imageio.write_exr(rdir / "full.exr", ref)
        store_path = tmp_path / "s.sqlite"
        configs = [("sslpv", {"N": 16, "steps": 8, "mapping": "collision"}, 0.5, 3.0),
                   ("sslpv", {"N": 32, "steps": 32, "mapping": "collision"}, 0.9, 9.0),
                   ("dipole", {"gather": "dense", "spacing": 1.0}, 0.95, 40.0),
                   ("dirpole", {"gather": "vertex", "range": 4.0, "density": 1.0}, 1.4, 2.0)]
        with Store(store_path) as st:
            run = st.start_run("sweep", {})
            for i, (method, params, scale, ms) in enumerate(configs):
                d = tmp_path / f"r{i}"
                imageio.write_exr(d / "subsurface.exr", scale * ref)
                imageio.write_exr(d / "full.exr", scale * ref)
                rows = [{**r, "image": img} for img in ("subsurface", "full")
                        for r in compare_images(scale * ref, ref, mask > 0.5, half_a, half_b)]
                stage = {"sslpv": "shading", "dipole": "gather", "dirpole": "shading"}[method]
                st.record_config(run, "blob", "h", params, "ok", metrics=rows, timings={stage: ms, "total": ms},
                                 render_dir=d, reference_dir=rdir, method=method, stages=get_method(method).stages,
                                 work={stage: 1000 * (i + 1)}, precompute={"material": {"ms": 5.0, "work": 64}})
            st.finish_run(run, "finished")
            n = st.export(tmp_path / "out.csv")
        info = build_report(store_path, tmp_path / "site", cost_budget_ms=10.0, flip_maps=False)
        page = info["scene_pages"]["blob"].read_text()
        assert 'id="methods"' in page and "methods_subsurface_relmse_vs_cost.png" in page
        for m in ("sslpv", "dipole", "dirpole"):
            assert f"{m}: best" in page
        assert (tmp_path / "site" / "scenes" / "blob" / "plots" / "methods_subsurface_flip_vs_cost.png").is_file()
        index = (tmp_path / "site" / "index.html").read_text()
        assert "Methods: the best configuration of each under the cost budget" in index
        assert "(none within 10 ms; the cheapest is shown)" in index          # the dense dipole costs 40 ms
        with open(tmp_path / "out.csv") as fh:
            rows = list(csv.DictReader(fh))
        assert n == len(rows) and {r["method"] for r in rows} == {"sslpv", "dipole", "dirpole"}
        assert {"ms_gather", "ms_shading", "work_json", "precompute_json"} <= set(rows[0])


@pytest.mark.gl
def test_rival_sweep_at_size_small_renders_each_scene_at_its_committed_size(tmp_path):
    """``sweep --size small`` with a rival: wide_slab's rival renders at its committed 60x36, against the
    committed reference (the rival's worker was once handed the string "small" as a size). One cheap vertex
    gather on one worker (about 15 s, most of it the Dask cluster)."""
    from harness.io import images as imageio
    from harness.runs.sweep import SweepConfig, run_sweep

    cfg = SweepConfig(scenes=["wide_slab"], params=[{"method": "dipole", "gather": ["vertex"], "density": [0.25],
                                                     "range": [1.0]}], out=str(tmp_path / "s"), size="small")
    summary = run_sweep(cfg, workers=1, progress=False)
    with Store(summary["store"]) as st:
        rows = st.configs(run_id=summary["run_id"])
    assert [(r["method"], r["status"], r.get("error")) for r in rows] == [("dipole", "ok", None)]
    sub = imageio.read_exr(Path(rows[0]["render_dir"]) / "subsurface.exr")["rgb"]
    assert sub.shape[:2] == (36, 60), sub.shape
    assert rows[0]["metrics"]["subsurface"]["relmse"]["value"] > 0
