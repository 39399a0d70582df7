"""The sweep on Dask distributed: a 2-worker LocalCluster, resuming, failures, bad input.

References come from the committed 64x64 ones (``baselines/refs``); nothing is
rendered with Mitsuba here.
"""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from harness.cli import main
from harness.errors import InputError
from harness.store import Store
from harness.runs.sweep import SweepConfig, run_sweep

pytestmark = [pytest.mark.gl, pytest.mark.slow]
REPO = Path(__file__).resolve().parent.parent
SCENES = ["thin_ring", "absorbing_sphere"]
PARAMS = {"N": [8, 16], "steps": [4, 8]}


def small_sweep(out, **kw):
    cfg = SweepConfig(scenes=SCENES, params=dict(PARAMS), out=str(out), size=[64, 64])
    return run_sweep(cfg, workers=2, progress=False, **kw)


def test_two_worker_sweep_stores_everything_and_reruns_from_its_config(tmp_path):
    summary = small_sweep(tmp_path / "s")
    assert summary["configurations"] == 8 and summary["ok"] == 8 and summary["failed"] == 0
    assert summary["gl_renderer"]
    with Store(summary["store"]) as st:
        configs = st.configs(run_id=summary["run_id"])
        run = st.run(summary["run_id"])
    assert len(configs) == 8 and run["status"] == "finished" and run["gl_renderer"]
    for c in configs:
        assert set(c["metrics"]) == {"subsurface", "full"}
        assert {"relmse", "energy_ratio", "flip", "si_relmse", "ciede2000_p95"} <= set(c["metrics"]["subsurface"])
        for m in c["metrics"]["subsurface"].values():
            assert m["noise_floor"] is not None
        assert {"rsm", "injection", "propagation", "shading"} <= set(c["timings"])
        # Since schema v2: steps used, the renderer's diagnostics, no calibration file; K=4 and K=8 of one
        # (scene, N) were one step group.
        assert c["steps_used"] == c["params"]["steps"] and c["diagnostics"]["steps_used"] == c["params"]["steps"]
        assert {"remaining_fraction", "outside_share", "injected_flux"} <= set(c["diagnostics"])
        assert c["calibration"] is None and c["shared"]["group_steps"] == [4, 8]
        assert (Path(c["render_dir"]) / "subsurface.exr").is_file()
    # Each configuration was measured against ITS scene's reference: the values equal an
    # in-process render measured against that scene's committed reference.
    from harness.regression.accuracy import load_case_reference, small_scene
    from harness.runs.worker import measure
    from sslpv_gl.params import SSLPVParams
    from sslpv_gl.renderer import SSLPVRenderer

    renderer = SSLPVRenderer()
    for c in configs:
        scene = small_scene(c["scene"])
        ref, floors = load_case_reference(scene)
        res = renderer.render(scene, SSLPVParams(**c["params"]))
        rows = measure({"subsurface": res.subsurface, "full": res.full}, ref, floors)
        for r in rows:
            stored = c["metrics"][r["image"]][r["metric"]]
            assert stored["value"] == pytest.approx(r["value"], rel=1e-6, abs=1e-9), (c["scene"], r["metric"])
            assert stored["noise_floor"] == pytest.approx(r["noise_floor"], rel=1e-9)
    # The configuration it wrote reproduces the sweep as a new run with identical values.
    again = main(["sweep", "--config", str(tmp_path / "s" / "sweep.json"), "--json"])
    assert again == 0
    with Store(summary["store"]) as st:
        runs = st.runs()
        assert len(runs) == 2 and runs[1]["config"] == runs[0]["config"]
        first = {c["config_key"]: c["metrics"] for c in st.configs(run_id=runs[0]["id"])}
        second = {c["config_key"]: c["metrics"] for c in st.configs(run_id=runs[1]["id"])}
    assert first == second


def test_failed_configuration_is_recorded_and_retried_on_resume(tmp_path, monkeypatch):
    monkeypatch.setenv("SSLPV_SWEEP_FAIL_CONFIG", "N16-K8-collision")
    first = small_sweep(tmp_path / "s")
    assert first["ok"] == 6 and first["failed"] == 2
    with Store(first["store"]) as st:
        failed = [c for c in st.configs() if c["status"] == "failed"]
    assert len(failed) == 2 and all("injected" in c["error"] for c in failed)
    monkeypatch.delenv("SSLPV_SWEEP_FAIL_CONFIG")
    second = small_sweep(tmp_path / "s")
    assert second["run_id"] == first["run_id"] and second["skipped_done"] == 6 and second["ok"] == 2
    with Store(first["store"]) as st:
        assert sorted(c["status"] for c in st.configs()) == ["ok"] * 8


def test_killed_sweep_resumes_without_redoing_or_losing(tmp_path):
    """Kill a sweep at a known point, then resume it: nothing is rendered twice, nothing is lost.

    The worker of one step group (wide_slab, N = 16: K = 4, 8, 16) is held before it renders
    (``SSLPV_SWEEP_PAUSE_CONFIG``), so the sweep cannot finish: once the other nine
    configurations are recorded it is killed like a crash. The resumed sweep must render
    exactly those three. The sweep runs at ``--size small``, so wide_slab is 60x36.
    """
    out = tmp_path / "s"
    cmd = [sys.executable, "-m", "harness.cli", "sweep", "--scenes", "thin_ring,wide_slab", "--grid", "8,16",
           "--steps", "4,8,16", "--size", "small", "--workers", "2", "--out", str(out), "--no-progress", "--json"]
    env = dict(os.environ, SSLPV_SWEEP_PAUSE_CONFIG="wide_slab:N16-K8-collision")
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True,
                            env=env)
    store = out / "store.sqlite"
    deadline = time.time() + 240
    done = set()
    try:
        while time.time() < deadline and len(done) < 9 and proc.poll() is None:
            time.sleep(0.5)
            if store.exists():
                with Store(store) as st:
                    done = st.done_keys(st.runs()[-1]["id"]) if st.runs() else set()
        assert proc.poll() is None, f"the paused sweep ended on its own: {proc.communicate()[1][-2000:]}"
        assert len(done) == 9, f"the sweep recorded {len(done)} of the 9 unpaused configurations within 240 s"
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # a crash: no chance to clean up
        proc.wait()
    with Store(store) as st:
        before = st.configs(run_id=st.runs()[-1]["id"])
    missing = {("wide_slab", 16, k) for k in (4, 8, 16)}
    assert len(before) == 9 and not {(c["scene"], c["params"]["N"], c["params"]["steps"]) for c in before} & missing
    rerun = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=300)
    assert rerun.returncode == 0, rerun.stderr
    summary = json.loads(rerun.stdout)
    assert summary["skipped_done"] == 9 and summary["ok"] == 3 and summary["failed"] == 0
    with Store(store) as st:
        configs = st.configs()
    keys = [c["config_key"] for c in configs]
    assert len(keys) == 12 and len(set(keys)) == 12
    assert {(c["scene"], c["params"]["N"], c["params"]["steps"]) for c in configs} >= missing
    wide = next(c for c in configs if c["scene"] == "wide_slab")
    assert Path(wide["reference_dir"]).name == "wide_slab"          # the committed 60x36 reference


class TestBadInput:
    def run_cli(self, tmp_path, *extra):
        code = subprocess.run([sys.executable, "-m", "harness.cli", "sweep", "--out", str(tmp_path / "o"),
                               "--no-progress", *extra], cwd=REPO, capture_output=True, text=True, timeout=120)
        lines = code.stderr.strip().splitlines()
        return code.returncode, lines

    @pytest.mark.parametrize("args,pattern", [
        (["--scenes", "no_such_scene"], "unknown scene 'no_such_scene'"),
        (["--scenes", "thin_ring,"], "empty scene name"),
        (["--scenes", "thin_ring", "--grid", "16,,32"], "empty value"),
        (["--scenes", "thin_ring", "--grid", "sixteen"], "not an integer"),
        (["--scenes", "thin_ring", "--mapping", "magic"], "unknown mapping 'magic'"),
        (["--scenes", "thin_ring", "--grid", "1000"], "N: must be an integer in"),
        (["--scenes", "thin_ring", "--size", "64"], "not WIDTHxHEIGHT"),
        (["--scenes", "thin_ring", "--size", "64x64", "--scheduler", "tcp://127.0.0.1:9"], "cannot reach Dask scheduler"),
    ])
    def test_one_line_and_nothing_written(self, tmp_path, args, pattern):
        code, lines = self.run_cli(tmp_path, *args)
        assert code == 2, lines
        assert len(lines) == 1 and pattern in lines[0], lines
        assert not (tmp_path / "o" / "store.sqlite").exists()

    def test_reference_with_nan_is_refused_before_the_store(self, tmp_path, monkeypatch):
        import numpy as np

        from harness.runs import references
        from harness.io.images import write_exr

        ref = tmp_path / "ref"
        ref.mkdir()
        img = np.ones((64, 64, 3), np.float32)
        img[3, 4, 1] = np.nan
        for name in ("subsurface", "full", "half_a", "half_b"):
            write_exr(ref / f"{name}.exr", img, se=np.zeros_like(img), extra={"mask": np.ones((64, 64))})
        monkeypatch.setattr(references, "reference_dir", lambda scene, target=None: ref)
        with pytest.raises(InputError, match=r"subsurface\.exr: rgb: contains 1 NaN"):
            small_sweep(tmp_path / "s")
        assert not (tmp_path / "s" / "store.sqlite").exists()


def test_existing_scheduler(tmp_path):
    """--scheduler ADDRESS: the same sweep on a cluster that the sweep did not start (and must not stop)."""
    from dask.distributed import Client, LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None,
                      silence_logs=50) as cluster:
        cfg = SweepConfig(scenes=["thin_ring"], params={"N": [8], "steps": [4, 8]}, out=str(tmp_path / "s"),
                          size=[64, 64])
        summary = run_sweep(cfg, scheduler=cluster.scheduler_address, progress=False)
        assert summary["ok"] == 2
        with Client(cluster.scheduler_address, timeout="10s") as client:
            assert len(client.scheduler_info()["workers"]) == 1   # still up after the sweep
