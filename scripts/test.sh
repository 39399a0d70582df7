#!/usr/bin/env bash
# Sets up (idempotently) and runs the checks and the whole test suite. Extra arguments go to pytest.
#   1. ruff: a small lint rule set ([tool.ruff] in pyproject.toml);
#   2. lint-imports: the pipeline's layers ([tool.importlinter], docs/architecture.md);
#   3. pytest, on one worker per core (at most 4; SSLPV_TEST_WORKERS overrides), each test file on one
#      worker (pytest-xdist --dist loadfile: a file's module fixtures are built once), in collection order
#      (--no-loadscope-reorder), so that the mutation suite, the longest file and collected first, starts
#      at once beside the rest instead of last. The suite is mostly single-threaded Python and NumPy, so a
#      second core nearly halves it; -n 0 runs it in one process.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
echo "test.sh: ruff check"
.venv/bin/ruff check .
echo "test.sh: lint-imports"
.venv/bin/lint-imports --no-cache
workers=${SSLPV_TEST_WORKERS:-$(nproc)}
[ "$workers" -gt 4 ] && workers=4
set +e
.venv/bin/python -m pytest -n "$workers" --dist loadfile --no-loadscope-reorder "$@"
code=$?
set -e
# pytest exits 5 when it collected no test: that is a failure here, never a pass.
if [ "$code" -eq 5 ]; then
    echo "test.sh: pytest collected no tests" >&2
    exit 1
fi
exit "$code"
