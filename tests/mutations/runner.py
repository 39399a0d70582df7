"""Apply each planted error to a temporary copy of the repository and run the tests that must catch it.

One copy per parallel job (``copy_repository``: the packages, the tests, the scene suite,
the baselines and ``pyproject.toml``; no caches). For each mutation the job writes the
mutated file into its copy, runs ``python -m pytest -x`` on the mutation's selection with
the copy alone on ``PYTHONPATH``, no bytecode written and one BLAS thread (the jobs run
side by side), restores the file, and records:

* ``killed``: pytest exited 1 (a test failed) -- the planted error was caught;
* ``survived``: pytest exited 0 -- a bug in the tests;
* ``error``: any other exit (no test collected, a collection error, a timeout) -- a bug
  in the mutation or its selection; never counted as a kill.

A mutation whose ``old`` text is not found exactly once raises :class:`MutationError`
naming the mutation, before anything runs: an unrelated change to the code can
therefore never disable a mutation silently.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import os
import queue
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
#: What a copy holds (everything a test selection may read).
COPY_DIRS = ("harness", "sslpv_gl", "dipole_gl", "tests", "reference_scenes", "baselines", "benchmarks",
             "docs")
COPY_FILES = ("pyproject.toml",)
_IGNORE = shutil.ignore_patterns("__pycache__", "*.pyc", ".pytest_cache", "test-artifacts", "refs_reseeded")
#: Seconds one mutation's selection may take (the slowest takes ~15 s alone on 2 cores).
TIMEOUT_S = 240


class MutationError(RuntimeError):
    """A mutation that cannot be applied (its code line is gone or ambiguous)."""


@dataclasses.dataclass(frozen=True)
class Mutation:
    """One exact edit and the tests that must fail with it."""

    name: str                 # unique, snake_case
    kind: str                 # glsl | physics | mitsuba | mapping | metric | scene | camera | cli
    path: str                 # file relative to the repository root
    old: str                  # exact text, found exactly once in the file
    new: str                  # what replaces it
    tests: tuple              # pytest node ids (files, classes or single tests)
    what: str = ""            # the planted error in words

    def apply(self, root):
        """Write the mutated file under ``root``; returns the original text (to restore)."""
        path = Path(root) / self.path
        if not path.is_file():
            raise MutationError(f"mutation {self.name}: {self.path} does not exist")
        text = path.read_text()
        n = text.count(self.old)
        if n != 1:
            raise MutationError(f"mutation {self.name}: the code to mutate occurs {n} times in {self.path} "
                                f"(needs exactly 1): {self.old!r}; update the mutation to the new code, never drop it")
        if self.new == self.old:
            raise MutationError(f"mutation {self.name}: 'new' equals 'old'")
        path.write_text(text.replace(self.old, self.new))
        return text


def check(mutations, root=REPO):
    """Every mutation applies to ``root`` (text found once) and names existing test files; raises otherwise."""
    names = [m.name for m in mutations]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise MutationError(f"duplicate mutation names: {', '.join(dup)}")
    for m in mutations:
        text = (Path(root) / m.path).read_text() if (Path(root) / m.path).is_file() else None
        if text is None:
            raise MutationError(f"mutation {m.name}: {m.path} does not exist")
        n = text.count(m.old)
        if n != 1:
            raise MutationError(f"mutation {m.name}: the code to mutate occurs {n} times in {m.path} "
                                f"(needs exactly 1): {m.old!r}; update the mutation to the new code, never drop it")
        if not m.tests:
            raise MutationError(f"mutation {m.name}: no tests named")
        for t in m.tests:
            if not (Path(root) / t.split("::")[0]).is_file():
                raise MutationError(f"mutation {m.name}: test file {t.split('::')[0]} does not exist")


def copy_repository(dest, root=REPO):
    dest = Path(dest)
    for d in COPY_DIRS:
        shutil.copytree(Path(root) / d, dest / d, ignore=_IGNORE, symlinks=True)
    for f in COPY_FILES:
        shutil.copy2(Path(root) / f, dest / f)
    return dest


def _first_failure(output):
    """The failing test and the line that caught the mutation (pytest's first informative ``E`` line)."""
    failed = re.findall(r"^FAILED (\S+)", output, re.M)
    lines = [ln[1:].strip() for ln in output.splitlines() if ln.startswith("E ")]
    lines = [ln for ln in lines if ln and ln not in ("AssertionError:", "AssertionError")]
    worst = [ln for ln in lines if ln.startswith("Max absolute difference")]
    if worst:                                   # numpy.testing: the tolerance and the worst difference
        head = next((ln for ln in lines if ln.startswith("Not equal")), "")
        line = f"{head}; {worst[0]}" if head else worst[0]
    else:
        line = lines[0] if lines else None
    return (failed[0] if failed else None), line


def run_one(m, root, timeout=TIMEOUT_S):
    """Apply ``m`` in the copy ``root``, run its tests, restore; returns a result dict."""
    original = m.apply(root)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTEST_ADDOPTS")}
    # one BLAS thread per test process: the jobs already run side by side, one per core
    env.update(PYTHONPATH=str(root), PYTHONDONTWRITEBYTECODE="1", OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1",
               MKL_NUM_THREADS="1")
    cmd = [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", "--no-header", "-rf",
           "-o", "addopts=", *m.tests]
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, cwd=root, env=env, capture_output=True, text=True, timeout=timeout)
        code, out = proc.returncode, proc.stdout + proc.stderr
    except subprocess.TimeoutExpired as exc:
        partial = exc.stdout.decode(errors="replace") if isinstance(exc.stdout, bytes) else (exc.stdout or "")
        code, out = None, f"timeout after {timeout} s\n" + partial
    finally:
        (Path(root) / m.path).write_text(original)
    seconds = time.perf_counter() - t0
    status = "killed" if code == 1 else "survived" if code == 0 else "error"
    test, line = _first_failure(out)
    if status == "error":
        tail = out.strip().splitlines()[-3:]
        line = line or " | ".join(tail)
    return {"name": m.name, "kind": m.kind, "status": status, "exit_code": code, "seconds": round(seconds, 2),
            "test": test, "line": line, "what": m.what, "tests": list(m.tests)}


def run_all(mutations, jobs=2, root=REPO, progress=None):
    """Run every mutation (``jobs`` at a time, one repository copy per job); returns (results, seconds).

    ``seconds`` is ``{"wall": ..., "cpu": ...}``: the wall time, and the CPU time (user + system)
    of the test processes, which does not depend on what else the machine runs.
    """
    mutations = list(mutations)
    check(mutations, root)
    t0 = time.perf_counter()
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    tmp = Path(tempfile.mkdtemp(prefix="sslpv-mutations-"))
    try:
        copies = queue.Queue()
        for j in range(max(1, int(jobs))):
            copies.put(copy_repository(tmp / f"copy{j}", root))

        def job(m):
            copy = copies.get()
            try:
                res = run_one(m, copy)
            finally:
                copies.put(copy)
            if progress:
                progress(res)
            return res

        with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, int(jobs))) as pool:
            results = list(pool.map(job, mutations))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    return results, {"wall": round(time.perf_counter() - t0, 1), "cpu": round(cpu, 1)}


def report(results, seconds):
    """Kill rate, every survivor and error, and one line per mutation."""
    killed = [r for r in results if r["status"] == "killed"]
    bad = [r for r in results if r["status"] != "killed"]
    lines = [f"mutation suite: {len(killed)}/{len(results)} killed ({100.0 * len(killed) / max(len(results), 1):.1f} %)"
             f" in {seconds['wall']:.1f} s wall, {seconds['cpu']:.1f} s CPU of the test processes"]
    for r in bad:
        lines.append(f"  {r['status'].upper()}: {r['name']} ({r['kind']}): {r['what']}; tests {' '.join(r['tests'])}"
                     + (f"; {r['line']}" if r["line"] else ""))
    for r in results:
        lines.append(f"  {r['status']:<8} {r['seconds']:6.1f} s  {r['name']:<34} {r['test'] or ''}")
        if r["line"]:
            lines.append(f"           {r['line'][:220]}")
    return "\n".join(lines)
