"""Step groups in the sweep: one propagation for every step count of a group.

* which configurations share a group (pure, no GL);
* grouped renders are bit-identical to single renders (worker level and whole sweeps);
* a mixed ``--steps 8,auto,steady,32`` list is grouped correctly, and the store records
  steps used, diagnostics and the shared stages;
* a sweep killed mid-group resumes without losing or duplicating rows.

References come from the committed 64x64 ones (``baselines/refs``); nothing is rendered
with Mitsuba here.
"""

import json
import os
import signal
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from harness.runs.sweep import SweepConfig, group_configs, run_sweep
from harness.store import Store

REPO = Path(__file__).resolve().parent.parent
DIAG_KEYS = {"steps_used", "injected_flux", "remaining_fraction", "outside_share"}


def _todo(scene_names, param_dicts):
    from sslpv_gl.params import SSLPVParams

    out = []
    for name in scene_names:
        for d in param_dicts:
            p = SSLPVParams(**d)
            out.append((SimpleNamespace(name=name), p, f"{name}-{p.N}-{p.steps}-{p.mapping}"))
    return out


class TestGrouping:
    def test_groups_share_everything_but_integer_steps(self):
        todo = _todo(["a", "b"], [{"N": n, "steps": k, "mapping": m} for n in (8, 16) for k in (32, 8, "auto",
                                                                                               "steady", 16)
                                 for m in ("collision", "literal")])
        groups = group_configs(todo)
        # per scene: 2 N x 2 mappings integer groups + 2 N x 2 mappings x (auto, steady) singles
        assert len(groups) == 2 * (4 + 8)
        covered = [key for _, _, members in groups for _, key in members]
        assert sorted(covered) == sorted(k for _, _, k in todo)          # each configuration once
        for s, p, members in groups:
            ks = [k for k, _ in members]
            if len(ks) > 1:
                assert ks == [8, 16, 32]                                 # ascending
            else:
                assert ks[0] in ("auto", "steady") or len(todo) == 0
            for k, key in members:                                      # same scene and params but steps
                assert key == f"{s.name}-{p.N}-{k}-{p.mapping}"
        # largest estimated cost first
        costs = [p.N ** 3 * max(k if isinstance(k, int) else 64 for k, _ in m) for _, p, m in groups]
        assert costs == sorted(costs, reverse=True)

    def test_mixed_steps_list_and_per_configuration_mode(self):
        todo = _todo(["a"], [{"N": 8, "steps": k} for k in (8, "auto", "steady", 32)])
        groups = group_configs(todo)
        assert sorted((tuple(k for k, _ in m) for _, _, m in groups), key=str) == \
            sorted([(8, 32), ("auto",), ("steady",)], key=str)
        singles = group_configs(todo, group=False)
        assert len(singles) == 4 and all(len(m) == 1 for _, _, m in singles)


@pytest.mark.gl
class TestWorker:
    def test_group_is_bit_identical_to_single_renders(self, gl_renderer, monkeypatch):
        from harness.regression.accuracy import load_case_reference, small_scene
        from harness.runs import worker

        monkeypatch.setattr(worker, "_RENDERER", gl_renderer)
        scene = small_scene("thin_ring")
        ref, floors = load_case_reference(scene)
        params = {"N": 16, "steps": 4, "mapping": "collision"}
        ks = [2, 4, 9, 16]
        grouped = worker.run_group(str(scene.path), [64, 64], params, ks, ref, floors)
        assert [g["status"] for g in grouped] == ["ok"] * 4
        for k, g in zip(ks, grouped):
            single = worker.run_config(str(scene.path), [64, 64], dict(params, steps=k), ref, floors)
            assert single["status"] == "ok" and single["shared"] is None
            for part in ("subsurface", "full"):
                assert np.array_equal(g["images"][part], single["images"][part]), (k, part)
            assert np.array_equal(g["mask"], single["mask"])
            assert g["metrics"] == single["metrics"]
            assert g["steps_used"] == single["steps_used"] == k
            assert set(g["diagnostics"]) == DIAG_KEYS and g["diagnostics"]["steps_used"] == k
            for name in ("remaining_fraction", "outside_share"):
                assert g["diagnostics"][name] == pytest.approx(single["diagnostics"][name], rel=1e-12)
            assert g["diagnostics"]["injected_flux"] == pytest.approx(single["diagnostics"]["injected_flux"],
                                                                      rel=1e-12)
            assert g["shared"] == {"stages": ["rsm", "injection", "host_material"], "group_steps": ks}
            assert set(g["timings"]) == {"rsm", "injection", "propagation", "shading", "total"}
        # RSM and injection were measured once for the group; propagation up to each K grows with K.
        assert len({g["timings"]["rsm"] for g in grouped}) == 1
        assert len({g["timings"]["injection"] for g in grouped}) == 1
        prop = [g["timings"]["propagation"] for g in grouped]
        assert prop == sorted(prop) and prop[0] < prop[-1]

    def test_injected_failure_fails_only_its_step_count(self, gl_renderer, monkeypatch):
        from harness.regression.accuracy import load_case_reference, small_scene
        from harness.runs import worker

        monkeypatch.setattr(worker, "_RENDERER", gl_renderer)
        monkeypatch.setenv("SSLPV_SWEEP_FAIL_CONFIG", "N8-K8-collision")
        scene = small_scene("thin_ring")
        ref, floors = load_case_reference(scene)
        res = worker.run_group(str(scene.path), [64, 64], {"N": 8, "steps": 4, "mapping": "collision"},
                               [4, 8, 16], ref, floors)
        statuses = [r["status"] for r in res]
        assert statuses == ["ok", "failed", "ok"], [r.get("error") for r in res]
        assert "injected" in res[1]["error"]
        assert res[0]["shared"]["group_steps"] == [4, 16]


@pytest.mark.gl
@pytest.mark.slow
def test_mixed_steps_sweep_grouped_equals_per_configuration(tmp_path):
    """``--steps 8,auto,steady,32``: 8 and 32 share one propagation, auto and steady run alone;
    the grouped sweep's rows equal the per-configuration sweep's exactly."""
    params = {"N": [8], "steps": [8, "auto", "steady", 32]}
    stores = {}
    for group in (True, False):
        cfg = SweepConfig(scenes=["thin_ring"], params=dict(params), out=str(tmp_path / f"g{int(group)}"),
                          size=[64, 64])
        summary = run_sweep(cfg, workers=2, progress=False, group=group, cache=False)   # both render
        assert summary["ok"] == 4 and summary["failed"] == 0 and summary["status"] == "finished"
        assert summary["groups"] == (3 if group else 4)
        with Store(summary["store"]) as st:
            stores[group] = {c["params"]["steps"]: c for c in st.configs()}
    g, single = stores[True], stores[False]
    assert set(g) == set(single) == {8, "auto", "steady", 32}
    for k in g:
        assert g[k]["config_key"] == single[k]["config_key"]
        assert g[k]["metrics"] == single[k]["metrics"], k          # bit-identical images give equal metrics
        assert g[k]["steps_used"] == single[k]["steps_used"]
        assert set(g[k]["diagnostics"]) == DIAG_KEYS and g[k]["calibration"] is None
        assert single[k]["shared"] is None
    assert g[8]["steps_used"] == 8 and g[32]["steps_used"] == 32
    assert isinstance(g["auto"]["steps_used"], int) and g["auto"]["steps_used"] > 0
    assert g["steady"]["steps_used"] is None and g["steady"]["diagnostics"]["steps_used"] is None
    assert g[8]["shared"]["group_steps"] == g[32]["shared"]["group_steps"] == [8, 32]
    assert g["auto"]["shared"] is None and g["steady"]["shared"] is None
    assert g[8]["timings"]["rsm"] == g[32]["timings"]["rsm"]       # measured once for the group


@pytest.mark.gl
@pytest.mark.slow
def test_sweep_killed_mid_group_resumes_without_losing_or_duplicating(tmp_path):
    out = tmp_path / "s"
    cmd = [sys.executable, "-m", "harness.cli", "sweep", "--scenes", "thin_ring", "--grid", "8,16",
           "--steps", "4,8,16", "--size", "64x64", "--workers", "2", "--out", str(out), "--no-progress", "--json"]
    # The client kills itself and its workers right after recording the first configuration of a group.
    env = dict(os.environ, SSLPV_SWEEP_CRASH_MID_GROUP="1")
    crashed = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=300, env=env,
                             start_new_session=True)
    assert crashed.returncode == -signal.SIGKILL, crashed.stderr[-2000:]
    with Store(out / "store.sqlite") as st:
        (run,) = st.runs()
        before = st.configs(run_id=run["id"])
    assert run["status"] == "running"                               # it never got to close the run
    assert len(before) == 1                                         # one K of a 3-K group, then the crash
    first = before[0]
    assert first["shared"]["group_steps"] == [4, 8, 16]
    env.pop("SSLPV_SWEEP_CRASH_MID_GROUP")
    rerun = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=300, env=env)
    assert rerun.returncode == 0, rerun.stderr[-2000:]
    summary = json.loads(rerun.stdout)
    assert summary["run_id"] == run["id"] and summary["skipped_done"] == 1 and summary["ok"] == 5
    assert summary["groups"] == 2 and summary["status"] == "finished"
    with Store(out / "store.sqlite") as st:
        after = st.configs()
    keys = [c["config_key"] for c in after]
    assert len(keys) == 6 and len(set(keys)) == 6
    assert after[0]["id"] == first["id"] and after[0]["metrics"] == first["metrics"]   # kept, not redone
    # The interrupted group rendered only its missing step counts, still as one group.
    resumed = [c for c in after[1:] if c["params"]["N"] == first["params"]["N"]]
    missing = sorted({4, 8, 16} - {first["params"]["steps"]})
    assert sorted(c["params"]["steps"] for c in resumed) == missing
    assert all(c["shared"]["group_steps"] == missing for c in resumed)
    assert all(c["status"] == "ok" and c["steps_used"] == c["params"]["steps"] for c in after)
