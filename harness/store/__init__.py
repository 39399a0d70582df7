"""The results store: one SQLite file of runs, configurations, metrics and timings.

=====================  ======================================================
module                 job
=====================  ======================================================
:mod:`.schema`         the tables, at a glance, and the ordered migrations
:mod:`.store`          :class:`Store`: opening, checking and migrating the file
:mod:`.write`          a run's start and end, one configuration with its rows
:mod:`.queries`        runs, configurations, flat results, metric histories
:mod:`.values`         canonical JSON, finite numbers, timestamps, rows
:mod:`.export`         the flat CSV / Parquet export
:mod:`.provenance`     git commit, package versions and machine of a run
=====================  ======================================================

Sweeps and the nightly job write it; the report and the regression machinery read it.
It imports no renderer.
"""

from harness.store.provenance import git_commit, machine, versions
from harness.store.schema import CONFIG_STATUSES, IMAGES, MIGRATIONS, STAGES, schema_version
from harness.store.store import Store

__all__ = ["CONFIG_STATUSES", "IMAGES", "MIGRATIONS", "STAGES", "Store", "git_commit", "machine",
           "schema_version", "versions"]
