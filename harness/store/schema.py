"""The results store's schema: its tables, and the migrations that build them.

A *run* is one invocation of a sweep (or nightly job); a *configuration* is one
SSLPV render of one scene with one set of renderer parameters, compared with
that scene's reference; each configuration has *metric* rows (one per image
and metric, with its noise floor) and *timing* rows (ms per SSLPV stage).

=================  ==============================================================
table              columns
=================  ==============================================================
``runs``           id, kind (``sweep``, ``nightly``, ...), started_at, finished_at,
                   date, git_commit, versions_json, machine_json, gl_renderer,
                   config_json, out_dir, status (``running``, ``ok``, ...)
``configurations`` id, run_id, scene, scene_hash, config_key, params_json, status
                   (``ok`` | ``failed``), error, render_dir, reference_dir,
                   created_at; UNIQUE(run_id, config_key); since v2 also
                   steps_used (INTEGER; NULL for ``steps = steady`` or when
                   unknown), diagnostics_json (remaining_fraction,
                   outside_share, injected_flux, steps_used), calibration_json
                   (path and sha256 of a calibrated mapping file, or NULL) and
                   shared_json (NULL for a configuration rendered alone; for one
                   rendered in a step group, ``{"stages": [...], "group_steps":
                   [...]}``: the stages measured once for the whole group and the
                   step counts that shared them); since v3 also method (TEXT, the
                   ``--method`` that rendered it; ``sslpv`` for every older row),
                   precompute_json (``{step: {"ms", "work"}}``: the method's
                   precomputation, kept apart from the frame) and work_json
                   (``{stage: count}``: device-independent work per frame stage);
                   since v4 also cached_from (the key of the result-cache entry
                   the configuration was served from, ``harness.runs.cache``; NULL
                   when it was rendered in its run)
``metrics``        config_id, image (``subsurface`` | ``full``), metric, value,
                   noise_floor, per_channel_json, params_json;
                   PRIMARY KEY(config_id, image, metric)
``timings``        config_id, stage (SSLPV's ``rsm``, ``injection``, ``propagation``,
                   ``shading``; another method's own stages, e.g. ``gather``; and
                   ``total``, the frame), ms; PRIMARY KEY(config_id, stage)
=================  ==============================================================

Concurrency: the file is in WAL mode with a 30 s busy timeout, and every write
is one ``BEGIN IMMEDIATE`` transaction, so several processes (Dask workers) can
write to one store at once; each opens its own :class:`Store`. Do not put the
file on a network file system (WAL needs shared memory between processes).

Schema versions: ``PRAGMA user_version`` holds the number of migrations that
have been applied; :data:`MIGRATIONS` is the ordered list. To change the
schema, append a function to it (never edit an old one). A store written by a
newer harness is refused untouched.

Recognition: ``PRAGMA application_id`` is :data:`APPLICATION_ID` in every store this
harness creates or migrates (stores made before that are recognised by their four
tables). Any other SQLite file is refused, read-only, before anything is written to it.

Timestamps are UTC ISO 8601 (``2025-01-31T12:00:00+00:00``).
"""

#: Images that metrics are recorded for.
IMAGES = ("subsurface", "full")
#: SSLPV stages that timings are recorded for (``total`` is the whole frame); another method
#: records its own (``Store.record_config(stages=...)``).
STAGES = ("rsm", "injection", "propagation", "shading", "total")
#: What a method name may look like.
METHOD_NAME = r"[a-z][a-z0-9_]{0,31}"
#: Status of one configuration.
CONFIG_STATUSES = ("ok", "failed")

BUSY_TIMEOUT_MS = 30_000
#: ``PRAGMA application_id`` of a results store ("SSLP"), set when a store is created or
#: migrated: another program's SQLite file is recognised and refused before it is written.
APPLICATION_ID = 0x53534C50
#: The tables of the first migration: a store made before the application id was set has them.
TABLES = ("runs", "configurations", "metrics", "timings")


# ---------------------------------------------------------------- migrations

def _migration_1(db):
    """Create the four tables."""
    _run_script(db, """
        CREATE TABLE runs (
            id            INTEGER PRIMARY KEY AUTOINCREMENT,
            kind          TEXT NOT NULL,
            started_at    TEXT NOT NULL,
            finished_at   TEXT,
            date          TEXT NOT NULL,
            git_commit    TEXT,
            versions_json TEXT NOT NULL,
            machine_json  TEXT NOT NULL,
            gl_renderer   TEXT,
            config_json   TEXT NOT NULL,
            out_dir       TEXT,
            status        TEXT NOT NULL
        );
        CREATE TABLE configurations (
            id            INTEGER PRIMARY KEY AUTOINCREMENT,
            run_id        INTEGER NOT NULL REFERENCES runs(id) ON DELETE CASCADE,
            scene         TEXT NOT NULL,
            scene_hash    TEXT NOT NULL,
            config_key    TEXT NOT NULL,
            params_json   TEXT NOT NULL,
            status        TEXT NOT NULL CHECK (status IN ('ok', 'failed')),
            error         TEXT,
            render_dir    TEXT,
            reference_dir TEXT,
            created_at    TEXT NOT NULL,
            UNIQUE (run_id, config_key)
        );
        CREATE INDEX configurations_scene ON configurations(scene, config_key);
        CREATE TABLE metrics (
            config_id        INTEGER NOT NULL REFERENCES configurations(id) ON DELETE CASCADE,
            image            TEXT NOT NULL,
            metric           TEXT NOT NULL,
            value            REAL NOT NULL,
            noise_floor      REAL,
            per_channel_json TEXT,
            params_json      TEXT NOT NULL,
            PRIMARY KEY (config_id, image, metric)
        );
        CREATE TABLE timings (
            config_id INTEGER NOT NULL REFERENCES configurations(id) ON DELETE CASCADE,
            stage     TEXT NOT NULL,
            ms        REAL NOT NULL CHECK (ms >= 0),
            PRIMARY KEY (config_id, stage)
        );
    """)


def _migration_2(db):
    """Steps used, renderer diagnostics, the calibration file and shared-stage notes per configuration."""
    _run_script(db, """
        ALTER TABLE configurations ADD COLUMN steps_used INTEGER;
        ALTER TABLE configurations ADD COLUMN diagnostics_json TEXT;
        ALTER TABLE configurations ADD COLUMN calibration_json TEXT;
        ALTER TABLE configurations ADD COLUMN shared_json TEXT
    """)


def _migration_3(db):
    """The method of each configuration (older rows: SSLPV), its precomputation and its work counts."""
    _run_script(db, """
        ALTER TABLE configurations ADD COLUMN method TEXT NOT NULL DEFAULT 'sslpv';
        ALTER TABLE configurations ADD COLUMN precompute_json TEXT;
        ALTER TABLE configurations ADD COLUMN work_json TEXT;
        CREATE INDEX configurations_method ON configurations(scene, method)
    """)


def _migration_4(db):
    """The result-cache entry a configuration was served from (NULL: rendered in its run)."""
    _run_script(db, """
        ALTER TABLE configurations ADD COLUMN cached_from TEXT
    """)


def _run_script(db, script):
    """Run ``;``-separated DDL statement by statement (``executescript`` would
    COMMIT the migration's transaction half-way)."""
    for stmt in script.split(";"):
        if stmt.strip():
            db.execute(stmt)


#: Ordered schema migrations; ``MIGRATIONS[i]`` takes the schema from version
#: ``i`` to ``i + 1``. Each runs inside the transaction that bumps
#: ``user_version``, so a failed migration leaves the store as it was.
MIGRATIONS = [_migration_1, _migration_2, _migration_3, _migration_4]


def schema_version():
    """The schema version this harness writes (the number of migrations)."""
    return len(MIGRATIONS)
