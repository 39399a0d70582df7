"""``benchmarks/bench_sweep.py``'s propagation table: a step group counts once, with its largest K."""

import sys
from pathlib import Path

import pytest

from harness.store import Store

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import bench_sweep  # noqa: E402


def _row(store, run, N, k, prop_ms, group=None):
    shared = {"stages": ["rsm", "injection", "host_material"], "group_steps": group} if group else None
    store.record_config(run, "slab", "h", {"N": N, "steps": k, "mapping": "collision"}, "ok",
                        timings={"rsm": 1.0, "injection": 2.0, "propagation": prop_ms, "shading": 3.0},
                        steps_used=k, shared=shared)


def test_groups_count_once(tmp_path, capsys):
    old, new = tmp_path / "old.sqlite", tmp_path / "new.sqlite"
    with Store(old) as st:
        run = st.start_run("sweep", {})
        for N, k, ms in ((16, 4, 40.0), (16, 8, 80.0), (32, 4, 400.0), (32, 8, 800.0)):
            _row(st, run, N, k, ms)
    with Store(new) as st:
        run = st.start_run("sweep", {})
        for N, k, ms in ((16, 4, 41.0), (16, 8, 82.0), (32, 4, 390.0), (32, 8, 790.0)):
            _row(st, run, N, k, ms, group=[4, 8])
    a, b = bench_sweep.propagation_by_grid(old), bench_sweep.propagation_by_grid(new)
    assert {n: r["steps"] for n, r in a.items()} == {16: 12, 32: 12}          # 4 + 8: one task per K
    assert {n: r["steps"] for n, r in b.items()} == {16: 8, 32: 8}            # one task per group, to K = 8
    assert a[16]["s"] == pytest.approx(0.12) and a[32]["s"] == pytest.approx(1.2)
    assert b[16]["s"] == pytest.approx(0.082) and b[32]["s"] == pytest.approx(0.79)   # the K = 8 rows only
    rows = bench_sweep.print_propagation(old, new)
    assert [r["N"] for r in rows] == [16, 32]
    out = capsys.readouterr().out
    assert "| 32 | 1.2 | 12 | 0.1000 | 0.8 | 8 | 0.0988 | 0.658 |" in out
    assert f"| all | 1.3 | | | 0.9 | | | {0.872 / 1.32:.3f} |" in out
