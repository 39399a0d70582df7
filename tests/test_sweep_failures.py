"""Failures around a sweep (issue 13): a new store created by several processes at once, a second
sweep into a folder in use, workers that all die, leftovers of a killed report, and the heap
corruption that pymeshlab caused at worker exit."""

import json
import multiprocessing as mp
import os
import signal
import sqlite3
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from harness.io.atomic import atomic_dir
from harness.io.outputs import SWEEP_MARKER, TMP_TAG, temp_name
from harness.store import Store

REPO = Path(__file__).resolve().parent.parent


# --------------------------------------------------------------------------- a new store, many processes

def _writer(path, i, barrier, q):
    try:
        barrier.wait()
        with Store(path) as st:
            rid = st.start_run("sweep", {"writer": i})
            for k in range(50):
                st.record_config(rid, "s", "h", {"N": k, "writer": i}, "ok", timings={"total": 1.0})
            st.finish_run(rid, "finished")
        q.put((i, "ok"))
    except Exception as exc:  # reported, and the test fails on it
        q.put((i, f"{type(exc).__name__}: {exc}"))


def test_new_store_created_by_four_processes_loses_nothing_in_20_trials(tmp_path):
    ctx = mp.get_context("fork")
    for trial in range(20):
        path = tmp_path / f"t{trial}" / "store.sqlite"
        barrier, q = ctx.Barrier(4), ctx.Queue()
        procs = [ctx.Process(target=_writer, args=(path, i, barrier, q)) for i in range(4)]
        for p in procs:
            p.start()
        for p in procs:
            p.join(60)
        results = sorted(q.get(timeout=5) for _ in procs)
        assert results == [(i, "ok") for i in range(4)], (trial, results)
        with Store(path) as st:
            assert len(st.runs()) == 4 and len(st.configs()) == 200, trial


def test_switch_to_wal_waits_for_a_creator_instead_of_failing(tmp_path):
    """The deterministic form of the race: while another connection creates the file (still in
    rollback mode, inside a write transaction), SQLite's switch to WAL fails at once with
    'database is locked' instead of waiting; the store retries it until the busy timeout."""
    path = tmp_path / "store.sqlite"
    creator = sqlite3.connect(path, isolation_level=None)
    creator.execute("BEGIN IMMEDIATE")
    creator.execute("CREATE TABLE scratch (x)")
    out = {}

    def open_store():
        try:
            with Store(path) as st:
                out["version"] = st.user_version
        except Exception as exc:
            out["error"] = f"{type(exc).__name__}: {exc}"

    t = threading.Thread(target=open_store)
    t.start()
    time.sleep(0.5)
    creator.execute("ROLLBACK")
    creator.close()
    t.join(30)
    assert out == {"version": Store(path).user_version}, out


# --------------------------------------------------------------------------- leftovers of a killed run

def test_atomic_outputs_remove_their_own_leftovers_only(tmp_path):
    out = tmp_path / "site"
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()                                          # a pid that no longer runs
    ours_dead = Path(str(temp_name(out)).replace(f".{os.getpid()}.", f".{dead.pid}."))
    ours_alive = Path(str(temp_name(out)).replace(f".{os.getpid()}.", f".{os.getppid()}."))
    someone = tmp_path / ".site.backup-of-mine"
    other_target = Path(str(temp_name(tmp_path / "other")).replace(f".{os.getpid()}.", f".{dead.pid}."))
    for d in (ours_dead, ours_alive, someone, other_target):
        d.mkdir()
        (d / "big.bin").write_bytes(b"x" * 1000)
    with atomic_dir(out) as tmp:                          # what build_report writes the site with
        (tmp / "index.html").write_text("ok")
    names = sorted(p.name for p in tmp_path.iterdir())
    assert ours_dead.name not in names                    # a killed report's, this host's: removed
    assert {ours_alive.name, someone.name, other_target.name, "site"} <= set(names)
    assert TMP_TAG in ours_dead.name


# --------------------------------------------------------------------------- heap corruption at exit

PLUGIN_SCRIPT = """
import threading, sys
sys.path.insert(0, {repo!r})
if {fixed}:
    from harness.runs.sweep import ReleaseGL
    ReleaseGL().setup(None)            # what every sweep worker runs on its main thread
def task():
    from harness.scene import load_scene
    load_scene("thin_ring")            # what the first task did on Dask's executor thread
t = threading.Thread(target=task); t.start(); t.join()
"""


def test_scene_loaded_on_a_worker_thread_exits_cleanly():
    """pymeshlab first imported off the main thread corrupted the heap at exit (glibc's
    'malloc_consolidate(): unaligned fastbin chunk detected', SIGABRT) in about 4 of 5 runs; the
    worker plugin imports it on the main thread first."""
    for _ in range(3):
        proc = subprocess.run([sys.executable, "-c", PLUGIN_SCRIPT.format(repo=str(REPO), fixed=True)],
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0 and "malloc" not in proc.stderr, (proc.returncode, proc.stderr[-400:])


# --------------------------------------------------------------------------- workers that die, a busy folder

def sweep_cmd(out):
    return [sys.executable, "-m", "harness.cli", "sweep", "--scenes", "thin_ring", "--grid", "8", "--steps", "4,8",
            "--size", "64x64", "--workers", "2", "--out", str(out), "--json"]


@pytest.mark.gl
@pytest.mark.slow
def test_workers_that_all_die_exit_nonzero_a_second_sweep_is_refused_and_a_rerun_completes(tmp_path):
    out = tmp_path / "s"
    env = dict(os.environ, PYTHONPATH=str(REPO), SSLPV_PROGRESS="lines", SSLPV_SWEEP_KILL_WORKERS="1",
               SSLPV_SWEEP_MAX_RESUBMITS="1")
    first = subprocess.Popen(sweep_cmd(out), cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True, start_new_session=True)
    try:
        deadline = time.time() + 120
        while time.time() < deadline and not (out / SWEEP_MARKER).is_file():
            time.sleep(0.2)
        # A second sweep into the folder in use: refused with one line, the first one's files untouched.
        second = subprocess.run(sweep_cmd(out), cwd=REPO, env=dict(env, SSLPV_SWEEP_KILL_WORKERS="0"),
                                capture_output=True, text=True, timeout=300)
        assert first.poll() is None, "the first sweep ended before the second one could be refused"
        lines = second.stderr.strip().splitlines()
        assert second.returncode == 2 and len(lines) == 1, second.stderr
        assert f"error: {out}: output: is in use by another sweep (pid {first.pid}" in lines[0], lines[0]
        stdout, stderr = first.communicate(timeout=300)
    finally:
        if first.poll() is None:
            os.killpg(first.pid, signal.SIGKILL)
    # Every task killed its worker: the run is incomplete, the exit status says so, and so does stderr.
    summary = json.loads(stdout)
    assert first.returncode == 1 and summary["status"] == "incomplete" and summary["ok"] == 0, stderr
    errors = [line for line in stderr.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1 and "is incomplete" in errors[0] and "run the same command again" in errors[0], stderr
    assert "scattering it again" in stderr                 # the lost reference was scattered again once
    assert "malloc" not in stderr and "Traceback" not in stderr, stderr
    # The same command again, with workers that live, completes the run; nothing is duplicated.
    rerun = subprocess.run(sweep_cmd(out), cwd=REPO, env=dict(env, SSLPV_SWEEP_KILL_WORKERS="0"),
                           capture_output=True, text=True, timeout=300)
    assert rerun.returncode == 0, rerun.stderr
    again = json.loads(rerun.stdout)
    assert again["run_id"] == summary["run_id"] and again["status"] == "finished" and again["ok"] == 2
    assert "malloc" not in rerun.stderr, rerun.stderr
    with Store(out / "store.sqlite") as st:
        rows = st.configs(run_id=summary["run_id"])
    assert sorted(c["status"] for c in rows) == ["ok", "ok"] and len({c["config_key"] for c in rows}) == 2
