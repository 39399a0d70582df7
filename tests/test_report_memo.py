"""The report's pictures kept by what they are drawn from (``harness.report.memo``).

A second report of the same store draws nothing and writes the same bytes; a changed
metric redraws exactly the plots that show it; a memo entry never leaks a configuration's
name into another; with four scenes or more the pages are drawn in parallel processes and
give the same site as one process does.
"""

import sqlite3
from pathlib import Path

import harness.report.scene_page as scene_page
from harness.report import build_report
from harness.report.memo import Memo

from .synthetic_store import make_synthetic_store


def _pictures(site):
    return {str(p.relative_to(site)): p.read_bytes() for p in sorted(Path(site).rglob("*.png"))}


def test_a_second_report_draws_nothing_and_writes_the_same_bytes(tmp_path):
    store, _ = make_synthetic_store(tmp_path / "s")
    first = build_report(store, tmp_path / "a", memo=Memo(tmp_path / "memo"))
    assert first["pictures"]["kept"] == 0 and first["pictures"]["drawn"] > 10
    second = build_report(store, tmp_path / "b", memo=Memo(tmp_path / "memo"))
    assert second["pictures"] == {"kept": first["pictures"]["drawn"], "drawn": 0}
    assert _pictures(tmp_path / "a") == _pictures(tmp_path / "b")
    plain = build_report(store, tmp_path / "c", memo=False)              # no memo: drawn afresh, same bytes
    assert plain["pictures"] == {"kept": 0, "drawn": first["pictures"]["drawn"]}
    assert _pictures(tmp_path / "c") == _pictures(tmp_path / "a")


def test_a_changed_metric_redraws_its_plots_only(tmp_path):
    store, _ = make_synthetic_store(tmp_path / "s", scenes=("slab",))
    first = build_report(store, tmp_path / "a", memo=Memo(tmp_path / "memo"))
    with sqlite3.connect(store) as db:
        db.execute("UPDATE metrics SET value = value * 1.5 WHERE metric = 'flip'")
    second = build_report(store, tmp_path / "b", memo=Memo(tmp_path / "memo"))
    redrawn = {k for k, v in _pictures(tmp_path / "b").items() if _pictures(tmp_path / "a").get(k) != v}
    assert second["pictures"]["drawn"] >= 1 and second["pictures"]["kept"] > 0
    assert redrawn and all("flip" in k for k in redrawn), redrawn
    assert second["pictures"]["drawn"] < first["pictures"]["drawn"]


def test_parallel_pages_give_the_same_site(tmp_path, monkeypatch):
    store, _ = make_synthetic_store(tmp_path / "s")
    monkeypatch.setattr(scene_page, "PARALLEL_FROM", 2)                 # two scenes: one process each
    info = build_report(store, tmp_path / "a", memo=False)
    monkeypatch.setattr(scene_page, "PARALLEL_FROM", 10**9)             # here, one after the other
    build_report(store, tmp_path / "b", memo=False)
    assert _pictures(tmp_path / "a") == _pictures(tmp_path / "b")
    assert len(info["scene_pages"]) == 2 and info["pictures"]["drawn"] > 10


def test_the_order_of_the_configurations_draws_nothing_again(tmp_path, monkeypatch):
    """A night served from the result cache records its configurations in another order than a night that
    rendered them (the order renders finished): the same set is the same plot, kept, not drawn again."""
    from harness.store import Store

    store, _ = make_synthetic_store(tmp_path / "s")
    first = build_report(store, tmp_path / "a", memo=Memo(tmp_path / "memo"))
    in_order = Store.configs
    monkeypatch.setattr(Store, "configs", lambda self, *a, **k: list(reversed(in_order(self, *a, **k))))
    second = build_report(store, tmp_path / "b", memo=Memo(tmp_path / "memo"))
    assert second["pictures"] == {"kept": first["pictures"]["drawn"], "drawn": 0}
