"""References on Dask, their progress and time cap, the colour passes and Russian roulette, the cost model.

Tiny images (16x16) and few samples: what is checked is the scheduling and the bookkeeping
(bit-identical to the serial renderer, a dead worker's job re-run and merged once, the time
cap, the one-line refusals), not the images' accuracy, which ``test_reference_validation``
checks.
"""

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from harness.errors import EnvironmentProblem, InputError
from harness.scene import load_scene

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def mi():
    from harness.reference import mitsuba_scene as ms

    return ms.use_variant()


def _tiny(name="sphere_homogeneous", size=16):
    return load_scene(name).with_resolution(size, size)


def _exrs_equal(a, b):
    from harness.io.images import read_exr

    names = sorted(p.name for p in Path(a).glob("*.exr"))
    assert names == sorted(p.name for p in Path(b).glob("*.exr")) and names
    for n in names:
        x, y = read_exr(Path(a) / n), read_exr(Path(b) / n)
        assert set(x) == set(y), n
        for k in x:
            assert np.array_equal(x[k], y[k]), f"{n}:{k} differs between serial and cluster"


# --------------------------------------------------------------------------- Dask

@pytest.mark.slow
def test_cluster_reference_is_bit_identical_to_serial_and_survives_a_dead_worker(mi, tmp_path, monkeypatch):
    """Same seeds, same Dr.Jit thread count: the 2-worker cluster writes the serial renderer's EXRs
    bit for bit, although the worker that first ran (full, seed 1, chunk 1) was killed mid-render:
    its job ran again elsewhere and was merged once. Chunks of 4 spp (the plan is made on the
    client) give each seed several jobs per step, which the two workers finish in any order."""
    from dask.distributed import Client, LocalCluster

    from harness.reference import plan
    from harness.reference.render import render_reference

    monkeypatch.setattr(plan, "MAX_LANES", 4 * 16 * 16)

    scene = _tiny()
    kw = dict(target_rel_se=0.1, K=4, threads=1, steps=3)
    serial = render_reference(scene, tmp_path / "serial", **kw)
    assert serial["pilot"] is not None and len(serial["rounds"]) >= 2  # pilot, then steps
    marker = tmp_path / "died"
    env = {"SSLPV_REFERENCE_DIE_ONCE": f"full:1:1:{marker}"}
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                      silence_logs=50, env=env) as cluster, Client(cluster) as client:
        dist = render_reference(scene, tmp_path / "cluster", client=client, **kw)
    assert marker.is_file(), "the fault injection did not kill a worker"
    _exrs_equal(tmp_path / "serial", tmp_path / "cluster")
    for key in ("spp_per_seed", "spp_total", "median_rel_se_subsurface", "jobs"):
        assert serial[key] == dist[key], key
    assert [r["spp_per_seed"] for r in serial["rounds"]] == [r["spp_per_seed"] for r in dist["rounds"]]
    # The processes that returned results: the two first workers, and the one the nanny started in
    # place of the killed one when it got a job before the end (it depends on the timing).
    assert dist["executor"].startswith("a Dask cluster of 2") and 2 <= len(dist["workers"]) <= 3, dist["workers"]
    assert serial["executor"] == "serial" and serial["threads"] == dist["threads"] == 1


def test_step_plan_does_not_depend_on_measured_times(mi, tmp_path, monkeypatch):
    """The default step plan (``steps=None``, as the ``reference`` command renders) comes from sample
    counts only: a machine 10^4 times slower, or a cluster of 64 slots, renders the same chunks, so
    the same seeds give the same image. (A plan sized from the predicted wall time split a step into
    other chunks, other Mitsuba seeds: a cluster's reference differed from the serial one.)"""
    from harness.reference import render
    from harness.reference.render import render_reference

    scene = _tiny()
    kw = dict(target_rel_se=0.06, K=2, threads=1)
    fast = render_reference(scene, tmp_path / "fast", **kw)
    real_measure = render.ReferencePlan._measure_cost

    def slow(self):
        real_measure(self)
        if self.cost is not None:
            self.cost *= 1e4
    monkeypatch.setattr(render.ReferencePlan, "_measure_cost", slow)
    monkeypatch.setattr(render.SerialExecutor, "slots", 64)
    slow_meta = render_reference(scene, tmp_path / "slow", **kw)
    assert [r["spp_per_seed"] for r in fast["rounds"]] == [r["spp_per_seed"] for r in slow_meta["rounds"]]
    _exrs_equal(tmp_path / "fast", tmp_path / "slow")


class _FakeClient:
    def __init__(self, probes):
        self.probes = probes

    def scheduler_info(self):
        return {"workers": {a: {"nthreads": 1} for a in self.probes}}

    def run(self, fn, *args, on_error="raise"):
        return dict(self.probes)


def test_check_workers_names_the_worker_and_what_it_lacks():
    from harness.reference.distributed import check_workers

    ok = {"host": "a", "pid": 1, "missing": None, "mitsuba": "3.9.1"}
    no_llvm = {"host": "b", "pid": 2, "missing": "no libLLVM >= 16 for Mitsuba's llvm_ad_rgb (install ...)"}
    with pytest.raises(EnvironmentProblem, match=r"^Dask worker tcp://10\.0\.0\.2:7 \(host b\): no libLLVM >= 16"):
        check_workers(_FakeClient({"tcp://10.0.0.1:7": ok, "tcp://10.0.0.2:7": no_llvm}))
    with pytest.raises(EnvironmentProblem, match=r"tcp://10\.0\.0\.3:7: cannot run the harness \(ModuleNotFoundError"):
        check_workers(_FakeClient({"tcp://10.0.0.3:7": ModuleNotFoundError("No module named 'harness'")}))
    with pytest.raises(EnvironmentProblem, match="no workers"):
        check_workers(_FakeClient({}))
    assert check_workers(_FakeClient({"tcp://10.0.0.1:7": ok}))


@pytest.mark.slow
def test_worker_without_mitsuba_is_named_in_one_line(tmp_path):
    """A real worker whose Python cannot import Mitsuba: `reference --scheduler` exits 3 naming it."""
    from dask.distributed import LocalCluster

    shadow = tmp_path / "shadow" / "mitsuba"
    shadow.mkdir(parents=True)
    (shadow / "__init__.py").write_text("raise ImportError('not installed on this worker')\n")
    preload = tmp_path / "hide_mitsuba.py"
    preload.write_text(textwrap.dedent(f"""
        import sys
        def dask_setup(worker):
            sys.path.insert(0, {str(shadow.parent)!r})
            sys.modules.pop("mitsuba", None)
    """))
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None, silence_logs=50,
                      preload=[str(preload)]) as cluster:
        proc = subprocess.run([sys.executable, "-m", "harness.cli", "reference", "thin_ring", "--size", "16x16",
                               "--scheduler", cluster.scheduler_address, "--no-progress"],
                              cwd=REPO, capture_output=True, text=True, timeout=120,
                              env=dict(os.environ, SSLPV_CACHE=str(tmp_path / "cache")))
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 3, proc.stderr
    assert len(lines) == 1 and lines[0].startswith("error: Dask worker tcp://"), lines
    assert "Mitsuba 3 is not importable (ImportError: not installed on this worker)" in lines[0]


# --------------------------------------------------------------------------- bad input, one line each

@pytest.mark.parametrize("value", ["0", "-3", "nan", "inf", "soon"])
def test_max_minutes_must_be_a_positive_time(value, capsys):
    from harness.cli.main import main

    code = main(["reference", "thin_ring", "--max-minutes", value, "--serial"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert err[0].startswith("error: --max-minutes: max-minutes: must be a finite time > 0"), err


@pytest.mark.slow
def test_unreachable_scheduler_is_one_line(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "harness.cli", "reference", "thin_ring", "--scheduler",
                           "tcp://127.0.0.1:9", "--no-progress"], cwd=REPO, capture_output=True, text=True,
                          timeout=120, env=dict(os.environ, SSLPV_CACHE=str(tmp_path / "cache")))
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert "cannot reach Dask scheduler 'tcp://127.0.0.1:9'" in lines[0]


# --------------------------------------------------------------------------- time cap, progress, refusal

@pytest.mark.slow
def test_time_cap_records_the_noise_reached_and_a_sweep_refuses_it(mi, tmp_path, monkeypatch):
    """An unreachable target under a 4 s cap: the pilot and a first step render, the result says
    what it reached and why it stopped, the progress lines show the prediction and the noise, and
    the sweep's reference lookup refuses the folder in one line."""
    from harness.reference import cache
    from harness.reference.render import render_reference
    from harness.runs import sweep

    monkeypatch.setenv("SSLPV_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("SSLPV_PROGRESS", "lines")
    scene = _tiny()
    folder = cache.cache_path(scene)
    meta = render_reference(scene, folder, target_rel_se=0.002, K=4, max_seconds=4.0, progress=True)
    assert meta["capped_by"] == "max_seconds" and meta["target_met"] is False
    assert meta["median_rel_se_subsurface"] > 0.002 and meta["spp_per_seed"] >= 1
    assert meta["rounds"][-1]["median_rel_se_subsurface"] == meta["median_rel_se_subsurface"]
    # The cap cut the plan short: far fewer samples than the pilot planned, every seed alike.
    assert meta["spp_per_seed"] < meta["pilot"]["first_spp_per_seed"]
    with pytest.raises(InputError, match=r"target_met: the reference reached [0-9.]+% median relative SE, its "
                                         r"target is 0\.20% \(stopped by max_seconds\); SSLPV is not judged"):
        sweep.reference_dir(scene)


def test_progress_lines_show_prediction_noise_and_eta(mi, tmp_path, monkeypatch, capsys):
    from harness.reference.render import render_reference

    monkeypatch.setenv("SSLPV_PROGRESS", "lines")
    meta = render_reference(_tiny(size=12), tmp_path / "r", target_rel_se=0.2, K=2, progress=True)
    err = capsys.readouterr().err
    assert "reference sphere_homogeneous: pilot measured" in err and "predicted 2 seeds x" in err
    # The cost model speaks before anything renders; the pilot's first round corrects it, in the log and
    # in reference.json, before the pilot's second round.
    model_at, early_at, full_at = (err.index(s) for s in ("the cost model predicts", "pilot, first round (4 of 16",
                                                          ": pilot measured"))
    assert model_at < early_at < full_at
    early = meta["pilot"]["early"]
    assert early["spp"] == 4 and early["first_spp_per_seed"] >= 1 and 0 < early["elapsed_seconds"]
    # The cost model's prediction, made before rendering, is set beside the pilot's, which replaces it.
    assert "the cost model predicted" in err and "the pilot's prediction replaces it (x" in err
    assert "in this process" in err and "median rel. SE" in err and "ETA" in err
    assert "done: median rel. SE" in err
    for line in err.strip().splitlines():
        assert line[:4].isdigit() and line[10] == "T", line      # timestamped lines in a log


@pytest.mark.slow
@pytest.mark.gl
def test_sweep_renders_missing_references_on_its_cluster(tmp_path, monkeypatch):
    """Two scenes without a reference at 16x16: the sweep renders both on its own 2-worker cluster,
    then each scene's configurations against it; the references land in the cache."""
    names = ["sphere_homogeneous", "absorbing_sphere"]
    from harness.reference.cache import cache_path, read_reference_meta
    from harness.runs.sweep import SweepConfig, run_sweep
    from harness.store import Store

    monkeypatch.setenv("SSLPV_CACHE", str(tmp_path / "cache"))
    cfg = SweepConfig(scenes=names, params={"N": [8], "steps": [4]}, out=str(tmp_path / "s"), size=[16, 16],
                      reference_target=0.1)
    summary = run_sweep(cfg, workers=2, progress=False)
    assert sorted(summary["references_rendered"]) == sorted(names)
    assert summary["ok"] == 2 and summary["failed"] == 0
    for name in names:
        folder = cache_path(load_scene(name).with_resolution(16, 16))
        meta = read_reference_meta(folder)
        assert meta is not None and meta["executor"].startswith("a Dask cluster") and meta["target_met"]
        assert summary["references"][name] == str(folder)
    with Store(summary["store"]) as st:
        assert {Path(c["reference_dir"]).parent.name for c in st.configs()} == set(names)


# --------------------------------------------------------------------------- colour passes, Russian roulette

def test_rr_depth_rule():
    from harness.reference import mitsuba_scene as ms

    assert ms.rr_depth_for(0.6) == 5 and ms.rr_depth_for(0.0) == 5
    assert ms.rr_depth_for(0.99) == 230                     # ceil(ln 0.1 / ln 0.99) = ceil(229.1)
    assert ms.rr_depth_for(0.999042) == 2403
    assert ms.rr_depth_for(1.0) == ms.RR_DEPTH_CAP
    for a in (0.9, 0.99, 0.999):
        d = ms.rr_depth_for(a)
        assert a ** d <= ms.RR_WEIGHT < a ** (d - 1)


def test_channel_passes_and_grey_scene():
    from harness.reference import mitsuba_scene as ms

    grey = load_scene("sphere_homogeneous")
    assert ms.channel_passes(grey.medium) == (None,)
    marble = load_scene("marble_sphere")
    assert ms.channel_passes(marble.medium) == (0, 1, 2)
    g = ms.grey_medium_scene(marble, 2)
    assert np.all(g.medium.sigma_t == marble.medium.sigma_t[..., 2:3])
    assert np.all(g.medium.albedo == marble.medium.albedo[..., 2:3])
    notes = ms.scene_notes(marble)
    assert notes["integrator"]["R"]["rr_depth"] == 2403 and "grey pass per channel" in notes["channel_passes"]


def _channel_means(img, se, mask):
    """Mean over the masked pixels per channel and its standard error (pixels are independent samples)."""
    n = mask.sum()
    return img[mask].mean(axis=0), np.sqrt((se[mask] ** 2).sum(axis=0)) / n


@pytest.mark.slow
def test_channel_passes_agree_with_spectral_tracking_on_short_paths(mi, tmp_path):
    """Second route for the colour passes: on a strongly absorbing medium whose sigma_t differs per
    channel (paths of a few bounces, where Mitsuba's spectral tracking is well behaved) the reference
    (one grey pass per channel, channel c kept from pass c) agrees with one spectral RGB render of
    other seeds, per channel, on the mean over the covered pixels: |z| < 4."""
    from harness.io.images import read_exr
    from harness.reference import mitsuba_scene as ms
    from harness.reference.render import render_reference, seed_stats

    base = _tiny("absorbing_sphere")
    shape = base.medium.sigma_t.shape
    st = np.broadcast_to(np.array([6.0, 10.0, 16.0], np.float32), shape).copy()
    scene = base.with_medium(sigma_t=st)
    assert ms.channel_passes(scene.medium) == (0, 1, 2)
    K, spp = 8, 32
    meta = render_reference(scene, tmp_path / "ref", spp=spp, K=K)
    assert meta["passes"] == ["full_r", "full_g", "full_b"]
    ref = read_exr(tmp_path / "ref" / "subsurface.exr")
    mask = ms.coverage_mask(scene) >= 0.999
    sc = mi.load_dict(ms.build_scene_dict(scene))
    stack = np.stack([np.asarray(mi.render(sc, seed=1000 + k, spp=spp), np.float64) for k in range(K)])
    m, se = seed_stats(stack)
    a, sa = _channel_means(ref["rgb"].astype(np.float64), ref["se"].astype(np.float64), mask)
    b, sb = _channel_means(m, se, mask)
    z = (a - b) / np.hypot(sa, sb)
    print(f"colour passes vs spectral tracking: means {a} vs {b}, z {z}")
    assert np.all(np.abs(z) < 4), f"per-channel passes disagree with spectral tracking: z = {z}"
    # Power: a 5 % error in one channel is far outside the test (z > 4).
    z_wrong = (a * np.array([1.0, 1.0, 1.05]) - b) / np.hypot(sa, sb)
    assert abs(z_wrong[2]) > 4, z_wrong


# --------------------------------------------------------------------------- cost model

# The model's fits, its arithmetic and its validation table: tests/test_reference_cost.py.


def test_mean_chord_of_a_sphere_is_four_thirds_r():
    from harness.reference import cost

    scene = load_scene("marble_sphere")
    # Cauchy: 4V/S = 4R/3 for a sphere; the subdivided icosphere is within 1 %.
    assert cost.mean_chord(scene.mesh) == pytest.approx(4 * 60.0 / 3, rel=0.01)


def test_estimate_renders_nothing(mi, capsys):
    from harness.cli.main import main
    from harness.reference import plan

    n0 = plan.RENDER_COUNT
    code = main(["reference", "marble_sphere", "--size", "16x16", "--estimate", "--json", "--serial"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and plan.RENDER_COUNT == n0
    assert out["channel_passes"] == 3 and out["predicted_spp_per_seed"] * 8 == out["predicted_spp_total"]
    assert out["predicted_seconds"] > out["predicted_final_seconds"] > 0
    assert "not rendered" in out["summary"]


# --------------------------------------------------------------------------- the highly scattering scene

def test_marble_scene_carries_jensen_2001_measured_marble():
    """marble_sphere's coefficients are Jensen et al. 2001's measured marble (reduced sigma_s' and
    sigma_a per mm, typed here from the paper's table): albedo >= 0.99 and hundreds of mean free
    paths across."""
    from harness.scene.geometry import grid_inside

    sigma_s_reduced = np.array([2.19, 2.62, 3.00])
    sigma_a = np.array([0.0021, 0.0041, 0.0071])
    scene = load_scene("marble_sphere")
    assert scene.units == "mm" and "Jensen" in scene.description
    m = scene.medium
    np.testing.assert_allclose(m.sigma_t[0, 0, 0], sigma_s_reduced + sigma_a, rtol=1e-6)
    np.testing.assert_allclose(m.albedo[0, 0, 0], sigma_s_reduced / (sigma_s_reduced + sigma_a), rtol=1e-6)
    assert np.all(m.g == 0) and np.all(m.sigma_t == m.sigma_t[0, 0, 0]) and np.all(m.albedo >= 0.99)
    diameter = np.ptp(scene.mesh.vertices[:, 0])
    assert 2 * 60.0 * 0.99 < diameter <= 120.0
    assert np.all(diameter * m.sigma_t[0, 0, 0] > 250)          # 263 (red) to 361 (blue) mean free paths
    assert grid_inside(scene.mesh, m.bbox_min, m.bbox_max, m.resolution).any()


def test_unit_cost_averages_the_passes_and_drops_compiling_jobs():
    """Three grey passes at 1, 2 and 6 ms per sample, 4 seeds each, one job per pass compiling (+2 s): the cost
    of a unit is their mean, 3 ms, less the per-job overhead; the lower quartile over all jobs (1 ms, the
    cheapest channel) or the mean with the compiling jobs (about 4.4 ms) is not."""
    from harness.reference.render import unit_cost

    jobs = [(p, 100, rate * 100 + (2.0 if s == 0 else 0.0) + 0.01) for p, rate in (("r", 1e-3), ("g", 2e-3),
                                                                                    ("b", 6e-3)) for s in range(4)]
    assert unit_cost(jobs, overhead=0.01) == pytest.approx(3e-3, rel=1e-9)
    assert unit_cost(jobs) == pytest.approx(3.1e-3, rel=1e-9)


def test_unit_cost_from_kernel_seconds_is_the_mean_per_sample():
    """With the kernels' own seconds (compilation apart), a pass costs the mean of its jobs' kernel seconds per
    sample: one job in four at 5 ms per sample among 1 ms ones (a long path) makes 2 ms, not the median's 1 ms;
    the passes are averaged; a job's wall seconds (here 9 s of compilation) do not count."""
    from harness.reference.render import unit_cost

    jobs = [("r", 10, 9.0 + 10 * r, 10 * r) for r in (1e-3, 1e-3, 1e-3, 5e-3)] + \
           [("g", 20, 20 * 4e-3, 20 * 4e-3) for _ in range(4)]
    assert unit_cost(jobs) == pytest.approx((2e-3 + 4e-3) / 2, rel=1e-12)
    # A round where one job lacks them falls back to the lower quartile of wall seconds.
    assert unit_cost(jobs[:-1] + [("g", 20, 20 * 4e-3, None)]) != pytest.approx(3e-3, rel=1e-3)
