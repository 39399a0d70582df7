"""The physics mutation suite in the normal test run (``pytest -m mutation`` runs it alone).

* ``test_catalogue``: at least 30 planted errors, in every part of the code the issue
  names, each found exactly once in today's code (so that a later edit cannot disable
  one silently: this test then fails naming it) and each naming existing tests.
* ``test_every_planted_error_is_caught``: applies each to a temporary copy of the
  repository, runs its tests there and requires them to fail. It prints the kill rate,
  every survivor and the line each test failed with, and writes
  ``test-artifacts/mutations/report.txt`` and ``report.json``. Cost: 77-82 s of CPU (two
  mutations at a time; 133-202 s wall on this 2-core machine while other jobs loaded it).
"""

import json

import pytest

from .catalogue import MUTATIONS
from .runner import REPO, check, report, run_all

pytestmark = pytest.mark.mutation

#: The parts of the code the issue asks the suite to cover.
KINDS = {"glsl", "physics", "mitsuba", "mapping", "metric"}


def test_catalogue():
    assert len(MUTATIONS) >= 30, f"only {len(MUTATIONS)} mutations"
    assert KINDS <= {m.kind for m in MUTATIONS}, f"missing kinds: {KINDS - {m.kind for m in MUTATIONS}}"
    for m in MUTATIONS:
        assert not any(t.startswith("tests/mutations") for t in m.tests), f"{m.name} selects the mutation suite"
    check(MUTATIONS)          # raises naming the mutation whose code is gone


def test_every_planted_error_is_caught():
    results, seconds = run_all(MUTATIONS, jobs=2)
    text = report(results, seconds)
    print(text)
    out = REPO / "test-artifacts" / "mutations"
    out.mkdir(parents=True, exist_ok=True)
    (out / "report.txt").write_text(text + "\n")
    (out / "report.json").write_text(json.dumps({"seconds": seconds, "results": results}, indent=1))
    bad = [r for r in results if r["status"] != "killed"]
    assert not bad, "planted errors the tests did not catch (bugs in the tests):\n" + "\n".join(
        f"  {r['status']}: {r['name']}: {r['what']} (tests {' '.join(r['tests'])}) {r['line'] or ''}" for r in bad)
