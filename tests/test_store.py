"""Tests of harness.store: schema and migrations, WAL, refusal of newer stores,
atomic record_config, resuming, two concurrent writers, CSV export."""

import csv
import json
import multiprocessing as mp
import os
import sqlite3

import numpy as np
import pytest

from harness.store import schema as store_mod
from harness.errors import InputError
from harness.store import IMAGES, Store, git_commit, schema_version, versions

METRIC_NAMES = ("rmse", "relmse", "flip")


def metric_rows(seed=0.0):
    return [{"image": img, "metric": name, "value": 0.1 * (i + 1) + seed, "noise_floor": 0.01 * (i + 1),
             "per_channel": (0.1, 0.2, 0.3 + seed), "params": {"eps": 0.01}}
            for img in IMAGES for i, name in enumerate(METRIC_NAMES)]


TIMINGS = {"rsm": 0.5, "injection": 0.25, "propagation": 2.0, "shading": 0.75, "total": 3.5}


def count(path, table):
    db = sqlite3.connect(path)
    try:
        return db.execute(f"SELECT COUNT(*) FROM {table}").fetchone()[0]
    finally:
        db.close()


@pytest.fixture
def store(tmp_path):
    with Store(tmp_path / "results.sqlite") as st:
        yield st


class TestSchema:
    def test_new_store_has_current_schema_and_tables(self, store):
        assert store.user_version == schema_version() >= 1
        names = {r["name"] for r in store._read("SELECT name FROM sqlite_master WHERE type='table'")}
        assert {"runs", "configurations", "metrics", "timings"} <= names

    def test_wal_mode_and_busy_timeout(self, store):
        assert store.journal_mode == "wal"
        assert store._read("PRAGMA busy_timeout")[0][0] >= 30_000

    def test_reopen_keeps_data(self, tmp_path):
        path = tmp_path / "r.sqlite"
        with Store(path) as st:
            run = st.start_run("sweep", {"a": 1})
        with Store(path) as st:
            assert [r["id"] for r in st.runs()] == [run]
            assert st.user_version == schema_version()

    def test_added_migration_upgrades_an_old_store(self, tmp_path, monkeypatch):
        path = tmp_path / "r.sqlite"
        with Store(path) as st:
            st.start_run("sweep", {})

        def migration_next(db):
            db.execute("ALTER TABLE runs ADD COLUMN note TEXT")

        current = schema_version()
        monkeypatch.setattr(store_mod, "MIGRATIONS", store_mod.MIGRATIONS + [migration_next])
        with Store(path) as st:
            assert st.user_version == current + 1
            assert "note" in st.runs()[0]

    def test_failed_migration_leaves_store_as_it_was(self, tmp_path, monkeypatch):
        path = tmp_path / "r.sqlite"
        with Store(path):
            pass

        def migration_next(db):
            db.execute("CREATE TABLE extra (x)")
            raise RuntimeError("boom")

        current = schema_version()
        monkeypatch.setattr(store_mod, "MIGRATIONS", store_mod.MIGRATIONS + [migration_next])
        with pytest.raises(RuntimeError, match="boom"):
            Store(path)
        monkeypatch.undo()
        with Store(path) as st:
            assert st.user_version == current
            assert not st._read("SELECT name FROM sqlite_master WHERE name = 'extra'")

    def test_store_of_migration_1_gains_the_v2_columns_and_keeps_its_rows(self, tmp_path, monkeypatch):
        """A store written by migration 1 only (the harness before steps_used/diagnostics/calibration)."""
        path = tmp_path / "old.sqlite"
        monkeypatch.setattr(store_mod, "MIGRATIONS", store_mod.MIGRATIONS[:1])
        with Store(path) as st:
            assert st.user_version == 1
            run = st.start_run("sweep", {})
            cols = {r["name"] for r in st._read("PRAGMA table_info(configurations)")}
            assert "steps_used" not in cols
            with st._write() as db:   # the row that harness would have written (migration-1 columns only)
                cid = db.execute("INSERT INTO configurations (run_id, scene, scene_hash, config_key, params_json,"
                                 " status, created_at) VALUES (?,?,?,?,?,?,?)",
                                 (run, "slab", "h", Store.config_key("h", {"grid": 32, "steps": 8}),
                                  '{"grid":32,"steps":8}', "ok", "2025-01-01T00:00:00+00:00")).lastrowid
                for stage, ms in TIMINGS.items():
                    db.execute("INSERT INTO timings VALUES (?,?,?)", (cid, stage, ms))
        monkeypatch.undo()
        with Store(path) as st:
            assert st.user_version == schema_version() >= 2
            cols = {r["name"] for r in st._read("PRAGMA table_info(configurations)")}
            assert {"steps_used", "diagnostics_json", "calibration_json", "shared_json"} <= cols
            (old,) = st.configs()
            assert old["params"] == {"grid": 32, "steps": 8} and old["timings"] == TIMINGS
            assert old["steps_used"] is None and old["diagnostics"] is None and old["calibration"] is None
            assert old["shared"] is None
            # ... and the migrated store takes the new fields.
            diag = {"steps_used": 16, "remaining_fraction": 0.25, "outside_share": 0.4,
                    "injected_flux": [1.0, 2.0, 3.0]}
            cal = {"path": "/cal/diffusion.toml", "sha256": "ab" * 32, "N": 32, "steps": 16}
            st.record_config(run, "slab", "h", {"grid": 32, "steps": 16}, "ok", steps_used=16, diagnostics=diag,
                             calibration=cal, shared={"stages": ["rsm", "injection"], "group_steps": [8, 16]})
            new = st.configs()[-1]
            assert (new["steps_used"], new["diagnostics"], new["calibration"]) == (16, diag, cal)
            assert new["shared"] == {"stages": ["rsm", "injection"], "group_steps": [8, 16]}

    def test_newer_schema_is_refused_and_untouched(self, tmp_path):
        path = tmp_path / "r.sqlite"
        with Store(path) as st:
            st.start_run("sweep", {})
        db = sqlite3.connect(path)
        db.execute(f"PRAGMA user_version = {schema_version() + 5}")
        db.execute("PRAGMA journal_mode = DELETE")  # so that everything is in the main file
        db.close()
        before = (path.read_bytes(), os.stat(path).st_mtime_ns)
        with pytest.raises(InputError) as err:
            Store(path)
        msg = str(err.value)
        assert f"schema: store schema v{schema_version() + 5} is newer than this harness (v{schema_version()})" in msg
        assert msg.endswith("; upgrade the harness") and "\n" not in msg
        assert (path.read_bytes(), os.stat(path).st_mtime_ns) == before

    def test_not_a_database_is_an_input_error(self, tmp_path):
        path = tmp_path / "junk.sqlite"
        path.write_bytes(b"this is not sqlite at all" * 100)
        with pytest.raises(InputError, match="junk.sqlite: file:"):
            Store(path)


class TestRuns:
    def test_start_and_finish(self, store):
        run = store.start_run("nightly", {"scenes": ["slab"]}, gl_renderer="llvmpipe", out_dir="/tmp/x",
                              git_commit="abc123")
        r = store.run(run)
        assert (r["kind"], r["status"], r["gl_renderer"], r["git_commit"]) == ("nightly", "running", "llvmpipe",
                                                                                "abc123")
        assert r["config"] == {"scenes": ["slab"]} and r["date"] == r["started_at"][:10]
        assert set(r["versions"]) >= {"mitsuba", "drjit", "moderngl", "numpy", "harness"}
        assert set(r["machine"]) >= {"hostname", "cpu_count", "platform"}
        store.finish_run(run, "finished")
        r = store.run(run)
        assert r["status"] == "finished" and r["finished_at"] is not None and r["gl_renderer"] == "llvmpipe"
        store.finish_run(run, "finished", gl_renderer="NVIDIA H100")
        assert store.run(run)["gl_renderer"] == "NVIDIA H100"

    def test_finish_unknown_run(self, store):
        with pytest.raises(InputError, match="run 99 does not exist"):
            store.finish_run(99, "ok")

    def test_helpers(self, tmp_path):
        assert versions()["numpy"] == np.__version__
        assert git_commit(tmp_path) is None  # not a repository
        sha = git_commit()
        assert sha is None or len(sha) == 40


class TestConfigKey:
    def test_stable_under_order_types_and_containers(self):
        a = Store.config_key("h", {"grid": 32, "steps": 8, "res": [1, 2]})
        b = Store.config_key("h", {"steps": np.int64(8), "res": (1.0, 2), "grid": 32.0})
        assert a == b

    def test_changes_with_scene_and_params(self):
        k = Store.config_key("h", {"grid": 32})
        assert k != Store.config_key("h2", {"grid": 32})
        assert k != Store.config_key("h", {"grid": 64})
        assert k != Store.config_key("h", {"grid": 32, "steps": 8})


class TestRecordConfig:
    def test_round_trip(self, store):
        run = store.start_run("sweep", {})
        cid = store.record_config(run, "slab", "h1", {"grid": 32, "steps": 8, "mapping": "a"}, "ok",
                                  metrics=metric_rows(), timings=TIMINGS, render_dir="/r", reference_dir="/ref")
        (c,) = store.configs(run)
        assert c["id"] == cid and c["params"] == {"grid": 32, "steps": 8, "mapping": "a"}
        assert c["timings"] == TIMINGS and c["cost_ms"] == 3.5
        assert c["metrics"]["subsurface"]["relmse"] == {"value": 0.2, "noise_floor": 0.02,
                                                        "per_channel": [0.1, 0.2, 0.3], "params": {"eps": 0.01}}
        rows = store.results(run)
        assert len(rows) == len(IMAGES) * len(METRIC_NAMES)
        assert {(r["image"], r["metric"]) for r in rows} == {(i, m) for i in IMAGES for m in METRIC_NAMES}

    def test_steps_used_diagnostics_calibration_round_trip(self, store):
        run = store.start_run("sweep", {})
        diag = {"steps_used": None, "remaining_fraction": None, "outside_share": 0.125,
                "injected_flux": [0.5, 0.25, 1 / 3]}
        cal = {"path": "/c/m.toml", "sha256": "0f" * 32, "N": 32, "steps": "steady"}
        store.record_config(run, "slab", "h", {"grid": 32, "steps": "steady"}, "ok", metrics=metric_rows(),
                            steps_used=None, diagnostics=diag, calibration=cal)
        store.record_config(run, "slab", "h", {"grid": 32, "steps": 8}, "ok", steps_used=8)
        a, b = store.configs(run)
        assert (a["steps_used"], a["diagnostics"], a["calibration"], a["shared"]) == (None, diag, cal, None)
        assert (b["steps_used"], b["diagnostics"], b["calibration"]) == (8, None, None)
        rows = store.results(run)
        assert all(r["diagnostics"] == diag and r["calibration"] == cal for r in rows if r["config_id"] == a["id"])
        assert [r["steps_used"] for r in rows if r["config_id"] == b["id"]] == [8]

    @pytest.mark.parametrize("kw,field", [
        ({"steps_used": -1}, "steps_used"), ({"steps_used": 2.5}, "steps_used"), ({"steps_used": True}, "steps_used"),
        ({"diagnostics": [1, 2]}, "diagnostics"), ({"diagnostics": {"outside_share": float("nan")}}, "diagnostics"),
        ({"calibration": {"path": "/x"}}, "calibration"), ({"shared": "rsm"}, "shared"),
    ])
    def test_bad_new_fields_write_nothing(self, store, kw, field):
        run = store.start_run("sweep", {})
        with pytest.raises(InputError, match=f"config slab: {field}:"):
            store.record_config(run, "slab", "h", {"grid": 32}, "ok", metrics=metric_rows(), **kw)
        assert count(store.path, "configurations") == count(store.path, "metrics") == 0

    def test_cost_falls_back_to_sum_of_stages(self, store):
        run = store.start_run("sweep", {})
        store.record_config(run, "slab", "h", {"g": 1}, "ok", timings={"rsm": 1.0, "shading": 2.0})
        assert store.configs()[0]["cost_ms"] == 3.0

    @pytest.mark.parametrize("bad", [
        {"value": "not a number"}, {"value": float("nan")}, {"value": None}, {"noise_floor": float("inf")},
        {"image": "diffuse"}, {"per_channel": (1.0, float("nan"), 0.0)},
    ])
    def test_failure_mid_insert_writes_nothing(self, store, bad):
        run = store.start_run("sweep", {})
        rows = metric_rows()
        rows[4] = {**rows[4], **bad}  # a few rows (and the config row) are in before this one
        with pytest.raises(InputError):
            store.record_config(run, "slab", "h", {"grid": 32}, "ok", metrics=rows, timings=TIMINGS)
        for table in ("configurations", "metrics", "timings"):
            assert count(store.path, table) == 0, table
        # The store still works, and the same key can be recorded afterwards.
        store.record_config(run, "slab", "h", {"grid": 32}, "ok", metrics=metric_rows(), timings=TIMINGS)
        assert count(store.path, "metrics") == len(metric_rows())

    def test_bad_timing_rolls_back(self, store):
        run = store.start_run("sweep", {})
        with pytest.raises(InputError, match="unknown stage 'gpu'"):
            store.record_config(run, "slab", "h", {}, "ok", metrics=metric_rows(), timings={"rsm": 1, "gpu": 2})
        assert count(store.path, "configurations") == count(store.path, "metrics") == 0

    def test_duplicate_metric_rolls_back(self, store):
        run = store.start_run("sweep", {})
        rows = metric_rows()
        with pytest.raises(InputError, match="given twice"):
            store.record_config(run, "slab", "h", {}, "ok", metrics=rows + rows[:1])
        assert count(store.path, "configurations") == 0

    def test_bad_status_and_unknown_run(self, store):
        with pytest.raises(InputError, match="status"):
            store.record_config(1, "slab", "h", {}, "done")
        with pytest.raises(InputError, match="run 7 does not exist"):
            store.record_config(7, "slab", "h", {}, "ok")

    def test_failed_config_then_retry(self, store):
        run = store.start_run("sweep", {})
        store.record_config(run, "slab", "h", {"grid": 8}, "failed", error="GL context lost")
        (row,) = store.results(run)
        assert row["status"] == "failed" and row["error"] == "GL context lost" and row["metric"] is None
        store.record_config(run, "slab", "h", {"grid": 8}, "ok", metrics=metric_rows())  # retry replaces it
        assert {c["status"] for c in store.configs(run)} == {"ok"}
        with pytest.raises(InputError, match="already recorded"):
            store.record_config(run, "slab", "h", {"grid": 8}, "ok", metrics=metric_rows())


class TestResume:
    def test_done_keys(self, store):
        run = store.start_run("sweep", {})
        other = store.start_run("sweep", {})
        p_ok, p_fail = {"grid": 16, "steps": 8}, {"grid": 16, "steps": 16}
        store.record_config(run, "slab", "h", p_ok, "ok", metrics=metric_rows())
        store.record_config(run, "slab", "h", p_fail, "failed", error="x")
        store.record_config(other, "slab", "h", {"grid": 99}, "ok")
        assert store.done_keys(run) == {Store.config_key("h", p_ok)}
        assert store.done_keys(run, include_failed=True) == {Store.config_key("h", p) for p in (p_ok, p_fail)}
        # A sweep resumes by skipping the done keys.
        grid = [{"grid": 16, "steps": s} for s in (8, 16, 32)]
        todo = [p for p in grid if Store.config_key("h", p) not in store.done_keys(run)]
        assert todo == grid[1:]


class TestHistory:
    def test_metric_over_runs(self, store):
        params = {"grid": 32, "steps": 16}
        for i, h in enumerate(("h1", "h1", "h2")):
            run = store.start_run("nightly", {})
            store.record_config(run, "slab", h, params, "ok", metrics=metric_rows(seed=i))
        store.record_config(store.start_run("nightly", {}), "slab", "h2", params, "failed", error="x")
        by_key = store.metric_history("slab", Store.config_key("h1", params), "relmse", "subsurface")
        assert [r["value"] for r in by_key] == pytest.approx([0.2, 1.2])
        by_params = store.metric_history("slab", params, "relmse", "subsurface")
        assert [r["value"] for r in by_params][:3] == pytest.approx([0.2, 1.2, 2.2])
        assert by_params[3]["status"] == "failed" and by_params[3]["value"] is None
        assert store.metric_history("other", params, "relmse") == []


def _writer(path, worker, n, barrier):
    with Store(path) as st:
        run = st.start_run("sweep", {"worker": worker})
        barrier.wait()  # both writers hammer the file at the same time
        for i in range(n):
            st.record_config(run, f"scene{worker}", "h", {"i": i, "worker": worker}, "ok",
                             metrics=metric_rows(i * 1e-3), timings=TIMINGS)
        st.finish_run(run, "ok")


class TestConcurrency:
    def test_two_processes_lose_nothing(self, tmp_path):
        path, n = tmp_path / "shared.sqlite", 200
        Store(path).close()
        ctx = mp.get_context("spawn")
        barrier = ctx.Barrier(2)
        procs = [ctx.Process(target=_writer, args=(path, w, n, barrier)) for w in range(2)]
        for p in procs:
            p.start()
        for p in procs:
            p.join(timeout=300)
        assert [p.exitcode for p in procs] == [0, 0]
        with Store(path) as st:
            runs = st.runs()
            assert len(runs) == 2 and {r["status"] for r in runs} == {"ok"}
            for r in runs:
                assert r["n_configs"] == n and len(st.done_keys(r["id"])) == n
        assert count(path, "metrics") == 2 * n * len(metric_rows())
        assert count(path, "timings") == 2 * n * len(TIMINGS)


DIAG = {"steps_used": 8, "remaining_fraction": 0.3, "outside_share": 0.1, "injected_flux": [1.5, 2.0, 0.1]}
CAL = {"path": "/c/m.toml", "sha256": "ab" * 32, "N": 32, "steps": 8}
SHARED = {"stages": ["rsm", "injection", "host_material"], "group_steps": [4, 8]}


class TestExport:
    def test_csv_round_trip(self, store, tmp_path):
        run = store.start_run("sweep", {})
        store.record_config(run, "slab", "h", {"grid": 32, "steps": 8, "mapping": "paper"}, "ok",
                            metrics=metric_rows(1 / 3), timings=TIMINGS, render_dir="/renders/a", steps_used=8,
                            diagnostics=DIAG, calibration=CAL, shared=SHARED)
        store.record_config(run, "slab", "h", {"grid": 64, "steps": 8}, "failed", error="oom, really")
        out = tmp_path / "out" / "results.csv"
        n = store.export(out)
        with open(out, newline="") as fh:
            rows = list(csv.DictReader(fh))
        expected = store.results()
        assert n == len(rows) == len(expected)
        for got, exp in zip(rows, expected):
            assert int(got["config_id"]) == exp["config_id"] and got["scene"] == exp["scene"]
            assert json.loads(got["params_json"]) == exp["params"]
            assert got["status"] == exp["status"] and (got["error"] or None) == exp["error"]
            if exp["metric"] is None:
                assert got["metric"] == got["value"] == ""
                assert got["param.mapping"] == ""
                continue
            assert (got["image"], got["metric"]) == (exp["image"], exp["metric"])
            assert float(got["value"]) == exp["value"]  # exact: floats are written with repr
            assert float(got["noise_floor"]) == exp["noise_floor"]
            assert json.loads(got["per_channel_json"]) == exp["per_channel"]
            assert float(got["ms_total"]) == exp["ms_total"] == 3.5
            assert json.loads(got["param.grid"]) == 32 and json.loads(got["param.mapping"]) == "paper"
            assert int(got["steps_used"]) == 8 and json.loads(got["diagnostics_json"]) == DIAG
            assert json.loads(got["calibration_json"]) == CAL and json.loads(got["shared_json"]) == SHARED

    def test_parquet_needs_pyarrow(self, store, tmp_path):
        try:
            import pyarrow  # noqa: F401
        except ImportError:  # the venv has no pyarrow: the error must say how to get it
            with pytest.raises(InputError, match="install pyarrow"):
                store.export(tmp_path / "r.parquet")
        else:
            store.export(tmp_path / "r.parquet")
            assert (tmp_path / "r.parquet").stat().st_size > 0

    def test_unknown_extension(self, store, tmp_path):
        with pytest.raises(InputError, match="export to .csv or .parquet"):
            store.export(tmp_path / "r.xlsx")
