#!/usr/bin/env bash
# Sets up (idempotently) and runs the main job: the nightly comparison on the default scene suite.
# References come from the cache (rendered once, then reused). Extra arguments go to the command.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
exec .venv/bin/sslpv-harness nightly "$@"
