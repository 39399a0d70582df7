"""The results store: one SQLite file that a sweep or a nightly run fills and the report reads.

A *run* is one invocation of a sweep (or nightly job); a *configuration* is one
SSLPV render of one scene with one set of renderer parameters, compared with
that scene's reference; each configuration has *metric* rows (one per image
and metric, with its noise floor) and *timing* rows (ms per SSLPV stage). The
tables and their migrations are in :mod:`harness.store.schema`; the flat export
in :mod:`harness.store.export`.

Concurrency: the file is in WAL mode with a 30 s busy timeout, and every write
is one ``BEGIN IMMEDIATE`` transaction, so several processes (Dask workers) can
write to one store at once; each opens its own :class:`Store`. Do not put the
file on a network file system (WAL needs shared memory between processes).

Timestamps are UTC ISO 8601 (``2025-01-31T12:00:00+00:00``).
"""

import contextlib
import hashlib
import json
import math
import os
import re
import sqlite3
import threading
import time
from datetime import datetime, timezone
from pathlib import Path

from harness.errors import InputError
from harness.io.outputs import check_writable
from harness.store import provenance, schema
from harness.store.schema import BUSY_TIMEOUT_MS, CONFIG_STATUSES, IMAGES, METHOD_NAME, STAGES


# ---------------------------------------------------------------- helpers

def _now():
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def _plain(obj, canon=True):
    """JSON-ready copy: numpy scalars/arrays to Python, tuples to lists, integral floats to int.

    Integral floats become ints so that ``{"grid": 32.0}`` and ``{"grid": 32}``
    give the same configuration key.
    """
    if isinstance(obj, dict):
        return {str(k): _plain(v, canon) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v, canon) for v in obj]
    if hasattr(obj, "tolist") and not isinstance(obj, (str, bytes)):  # numpy scalar / array
        return _plain(obj.tolist(), canon)
    if isinstance(obj, Path):
        return str(obj)
    if canon and isinstance(obj, float) and math.isfinite(obj) and obj.is_integer() and abs(obj) < 2**53:
        return int(obj)
    return obj


def _dumps(obj, canon=True):
    """Compact sorted JSON; ``canon`` also turns integral floats into ints (for keys)."""
    return json.dumps(_plain(obj, canon), sort_keys=True, separators=(",", ":"), allow_nan=False)


def _loads(text):
    return None if text is None else json.loads(text)


def _retry_locked(fn, timeout_s=BUSY_TIMEOUT_MS / 1000):
    """``fn()``, retried with backoff while SQLite answers "database is locked", up to ``timeout_s``."""
    deadline, delay = time.monotonic() + timeout_s, 0.005
    while True:
        try:
            return fn()
        except sqlite3.OperationalError as exc:
            if "locked" not in str(exc) and "busy" not in str(exc) or time.monotonic() > deadline:
                raise
            time.sleep(delay)
            delay = min(2 * delay, 0.25)


def _finite(where, field, value, allow_none=False):
    """``value`` as a finite float, or an InputError naming the field."""
    if value is None and allow_none:
        return None
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(where, field, f"is {value!r}, not a number", "record numbers only") from None
    if not math.isfinite(v):
        raise InputError(where, field, f"is {v}, not finite",
                         "record finite numbers (a failed config has status 'failed')")
    return v


# ---------------------------------------------------------------- the store

class Store:
    """An SQLite results store; use it as a context manager.

    Parameters
    ----------
    path : str or Path
        The store file; created (with its folder) when missing.
    readonly : bool
        Open an up-to-date store without writing anything (``export``, ``report``); it
        then also opens in a folder this process cannot write. An older store is migrated
        first, which needs a writable folder.

    Raises
    ------
    InputError
        When the file is not an SQLite database, is another program's database, was
        written by a newer harness (in all three cases nothing in it is changed), or
        cannot be written where it is (the message says why: a read-only folder or file).

    Examples
    --------
    >>> with Store(tmp / "results.sqlite") as st:                  # doctest: +SKIP
    ...     run = st.start_run("sweep", {"scenes": ["slab"]})
    ...     st.record_config(run, "slab", h, {"grid": 32, "steps": 16}, "ok",
    ...                      metrics=rows, timings={"total": 4.2})
    ...     st.finish_run(run, "ok")
    """

    def __init__(self, path, readonly=False):
        self.path = Path(path)
        self.readonly = bool(readonly)
        self._lock = threading.Lock()
        self._db = None
        found = self._inspect()                      # read-only: a foreign or newer file is never touched
        if self.readonly and found == schema.schema_version():
            self._db = self._connect_readonly()
            return
        if found is None:
            check_writable(self.path, "the store")
            self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            db = sqlite3.connect(self.path, timeout=BUSY_TIMEOUT_MS / 1000, isolation_level=None,
                                 check_same_thread=False)
        except sqlite3.Error as exc:
            raise self._open_error(exc) from exc
        self._db = db
        try:
            db.execute(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_MS}")
            # Switching to WAL takes the file's lock without calling the busy handler: while
            # another process creates the same new store, it fails at once with "database is
            # locked". Retry it until the busy timeout, as every other statement waits.
            mode = _retry_locked(lambda: db.execute("PRAGMA journal_mode = WAL").fetchone()[0])
            if mode.lower() != "wal":
                raise InputError(self.path, "journal_mode", f"could not switch to WAL (got {mode})",
                                 "put the store on a local file system")
            db.execute("PRAGMA foreign_keys = ON")
            db.execute("PRAGMA synchronous = NORMAL")  # safe with WAL; a crash loses at most the last commit
            _retry_locked(self._migrate)
        except sqlite3.DatabaseError as exc:
            self.close()
            raise self._open_error(exc) from exc
        except BaseException:
            self.close()
            raise

    @classmethod
    def check(cls, path):
        """Refuse, without writing anything, what ``Store(path)`` would refuse: a folder, a file that
        is not SQLite, another program's database, a newer store. Returns its schema version (None: new)."""
        probe = cls.__new__(cls)
        probe.path, probe.readonly, probe._db = Path(path), True, None
        return probe._inspect()

    # -- opening -------------------------------------------------------------

    def _open_error(self, exc):
        """The InputError for a store that SQLite could not open or write: say what is actually wrong."""
        try:
            check_writable(self.path, "the store")
        except InputError:
            return InputError(self.path, "folder", f"{self.path.parent} is not writable, and a store writes its "
                              "journal (-wal, -shm) beside it", "copy the store to a folder you can write to, "
                              "or make the folder writable")
        if self.path.exists() and not os.access(self.path, os.W_OK):
            return InputError(self.path, "file", "is read-only", "make it writable, or copy it")
        return InputError(self.path, "file", f"is not a usable SQLite results store ({exc})",
                          "pass a results store or a new file name")

    def _inspect(self):
        """Look at an existing file through a read-only connection, before anything is written.

        Returns None for a missing or empty file, else its schema version; raises an
        InputError for a folder, a file that is not SQLite, another program's database
        and a store of a newer harness. A store is recognised by its application id, or,
        for stores made before the id was set, by its four tables.
        """
        if self.path.is_dir():
            raise InputError(self.path, "file", "is a folder, not a results store",
                             "give the store.sqlite inside it")
        if not self.path.exists() or self.path.stat().st_size == 0:
            return None
        try:
            ro = self._connect_readonly(check=False)
        except InputError:
            raise
        except sqlite3.Error as exc:
            raise InputError(self.path, "file", f"cannot be opened ({exc})", "check the path and permissions") from exc
        try:
            app_id = ro.execute("PRAGMA application_id").fetchone()[0]
            found = ro.execute("PRAGMA user_version").fetchone()[0]
            tables = {r[0] for r in ro.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        except sqlite3.DatabaseError as exc:
            if "not a database" in str(exc) or "malformed" in str(exc):
                raise InputError(self.path, "file", f"is not an SQLite database ({exc})",
                                 "pass a results store or a new file name") from exc
            raise self._open_error(exc) from exc
        finally:
            ro.close()
        ours = app_id == schema.APPLICATION_ID or (app_id == 0 and set(schema.TABLES) <= tables)
        if not ours and (tables or app_id or found):
            listed = ", ".join(sorted(tables)[:6]) + (", ..." if len(tables) > 6 else "")
            raise InputError(self.path, "file", f"is another program's SQLite database (tables: {listed or 'none'}), "
                             "not a results store; it was not changed",
                             "give a store that sslpv-harness wrote, or a new file name")
        if found > schema.schema_version():
            raise InputError(self.path, "schema",
                             f"store schema v{found} is newer than this harness (v{schema.schema_version()})",
                             "upgrade the harness")
        return found if tables else None

    def _connect_readonly(self, check=True):
        """A connection that is only read from, and that leaves the folder as it found it.

        SQLite's ``mode=ro`` on a WAL store creates the ``-wal`` and ``-shm`` files and, not
        allowed to write, leaves them behind; so where the folder is writable and they do not
        exist yet, the connection is an ordinary one that is never written through (the last
        one to close removes them). Where they exist, ``mode=ro`` uses them as they are. In a
        folder this process cannot write, the store is read as immutable, which is exact
        only when no writer left a WAL behind, so one that did is refused.
        """
        uri = self.path.resolve().as_uri()
        try:
            check_writable(self.path, "the store")
            writable = True
        except InputError:
            writable = False
        wal = Path(f"{self.path}-wal")
        if not writable:
            if wal.exists() and wal.stat().st_size > 0:
                raise InputError(self.path, "folder", f"{self.path.parent} is not writable and the store has "
                                 "changes in its -wal file that are not merged yet",
                                 "copy the store with its -wal file to a folder you can write to")
            uri += "?mode=ro&immutable=1"
        elif wal.exists() or Path(f"{self.path}-shm").exists():
            uri += "?mode=ro"
        return sqlite3.connect(uri, uri=True, timeout=BUSY_TIMEOUT_MS / 1000, isolation_level=None,
                               check_same_thread=False)

    def _migrate(self):
        with self._write() as db:
            found = db.execute("PRAGMA user_version").fetchone()[0]
            if found > schema.schema_version():  # a newer harness migrated it after our read-only check
                raise InputError(self.path, "schema",
                                 f"store schema v{found} is newer than this harness (v{schema.schema_version()})",
                                 "upgrade the harness")
            for version in range(found, schema.schema_version()):
                schema.MIGRATIONS[version](db)
                db.execute(f"PRAGMA user_version = {version + 1}")
            if db.execute("PRAGMA application_id").fetchone()[0] != schema.APPLICATION_ID:
                db.execute(f"PRAGMA application_id = {schema.APPLICATION_ID}")

    def close(self):
        """Close the connection (also done on leaving the ``with`` block)."""
        if self._db is not None:
            self._db.close()
            self._db = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    @property
    def user_version(self):
        return self._read("PRAGMA user_version")[0][0]

    @property
    def journal_mode(self):
        return self._read("PRAGMA journal_mode")[0][0]

    @contextlib.contextmanager
    def _write(self):
        """One write transaction: BEGIN IMMEDIATE takes the write lock up front (waiting up
        to the busy timeout), so two writers never deadlock upgrading a read lock."""
        if self._db is None:
            raise ValueError(f"{self.path}: the store is closed")
        with self._lock:
            self._db.execute("BEGIN IMMEDIATE")
            try:
                yield self._db
            except BaseException:
                self._db.execute("ROLLBACK")
                raise
            self._db.execute("COMMIT")

    def _read(self, sql, args=()):
        if self._db is None:
            raise ValueError(f"{self.path}: the store is closed")
        with self._lock:
            cur = self._db.execute(sql, args)
            names = [d[0] for d in cur.description] if cur.description else []
            rows = cur.fetchall()
        return [_Row(names, r) for r in rows]

    # -- runs -----------------------------------------------------------------

    def start_run(self, kind, config, gl_renderer=None, out_dir=None, git_commit=None, versions=None):
        """Record the start of a run; returns its id.

        ``config`` is the run's resolved configuration (JSON-ready dict).
        ``versions`` defaults to :func:`~harness.store.provenance.versions`; ``git_commit`` is
        stored as given (call :func:`~harness.store.provenance.git_commit` to fill it).
        """
        if not isinstance(kind, str) or not kind.strip():
            raise InputError(self.path, "kind", f"is {kind!r}", "name the run kind, e.g. 'sweep' or 'nightly'")
        vers = provenance.versions() if versions is None else versions
        started = _now()
        try:
            config_json = _dumps(config if config is not None else {}, False)
        except (TypeError, ValueError) as exc:
            raise InputError(self.path, "config", f"is not JSON-serialisable ({exc})",
                             "pass plain numbers, strings, lists and dicts") from exc
        with self._write() as db:
            cur = db.execute(
                "INSERT INTO runs (kind, started_at, date, git_commit, versions_json, machine_json,"
                " gl_renderer, config_json, out_dir, status) VALUES (?,?,?,?,?,?,?,?,?,?)",
                (kind, started, started[:10], git_commit, _dumps(vers), _dumps(provenance.machine()),
                 gl_renderer, config_json, None if out_dir is None else str(out_dir), "running"))
            return cur.lastrowid

    def finish_run(self, run_id, status, gl_renderer=None):
        """Mark a run finished with ``status`` (e.g. ``"finished"``, ``"failed"``, ``"interrupted"``).

        ``gl_renderer`` (known only once a worker has rendered) replaces the
        stored one when given.
        """
        with self._write() as db:
            cur = db.execute("UPDATE runs SET finished_at = ?, status = ?, gl_renderer = COALESCE(?, gl_renderer)"
                             " WHERE id = ?", (_now(), str(status), gl_renderer, run_id))
            if cur.rowcount != 1:
                raise InputError(self.path, "run_id", f"run {run_id} does not exist", "pass an id from start_run")

    def runs(self, kind=None):
        """All runs (oldest first) as dicts, JSON columns decoded (``versions``, ``machine``, ``config``)."""
        sql = "SELECT r.*, (SELECT COUNT(*) FROM configurations c WHERE c.run_id = r.id) AS n_configs FROM runs r"
        rows = self._read(sql + (" WHERE kind = ?" if kind else "") + " ORDER BY started_at, id",
                          (kind,) if kind else ())
        out = []
        for r in rows:
            d = dict(r)
            d["versions"] = _loads(d.pop("versions_json"))
            d["machine"] = _loads(d.pop("machine_json"))
            d["config"] = _loads(d.pop("config_json"))
            out.append(d)
        return out

    def run(self, run_id):
        """One run as in :meth:`runs`, or an InputError (naming the runs there are) when it does not exist."""
        runs = self.runs()
        for r in runs:
            if r["id"] == run_id:
                return r
        ids = ", ".join(str(r["id"]) for r in runs)
        raise InputError(self.path, "run_id", f"run {run_id} does not exist",
                         f"pick one of {ids}" if ids else "the store has no runs yet")

    def scenes(self, run_id=None):
        """The scene names that have configurations (in ``run_id``, or in any run), sorted."""
        sql = "SELECT DISTINCT scene FROM configurations" + (" WHERE run_id = ?" if run_id is not None else "")
        return sorted(r[0] for r in self._read(sql + " ORDER BY scene", (run_id,) if run_id is not None else ()))

    # -- configurations --------------------------------------------------------

    @staticmethod
    def config_key(scene_hash, params, method="sslpv"):
        """Stable key of one configuration: sha256 of the scene hash, the method and the canonical params JSON.

        Key order, tuples vs lists, numpy vs Python numbers and ``32.0`` vs
        ``32`` do not change the key. An SSLPV key is the one it was before methods
        (the method is left out of the hashed text), so older stores resume as before.
        """
        doc = {"scene_hash": str(scene_hash), "params": params}
        if method != "sslpv":
            doc["method"] = str(method)
        text = _dumps(doc)
        return hashlib.sha256(text.encode()).hexdigest()[:24]

    def record_config(self, run_id, scene, scene_hash, params, status, error=None, metrics=(),
                      timings=None, render_dir=None, reference_dir=None, steps_used=None, diagnostics=None,
                      calibration=None, shared=None, method="sslpv", precompute=None, work=None, stages=None,
                      cached_from=None):
        """Record one configuration with its metrics and timings in ONE transaction.

        Either everything is written or nothing is (a bad metric value rolls
        back the configuration row too). Recording a key that is already
        recorded in the run as ``failed`` replaces it (a retry); one recorded
        as ``ok`` raises an InputError.

        Parameters
        ----------
        run_id : int
        scene, scene_hash : str
        params : dict
            Every renderer parameter (grid, steps, mapping, ...), JSON-ready.
        status : {"ok", "failed"}
        error : str, optional
            Why it failed (one line is best).
        metrics : list of dict
            Each ``{image, metric, value, noise_floor, per_channel, params}``
            (rows of ``harness.metrics.compare_images`` plus ``image``).
        timings : dict of str to float
            Stage (SSLPV's :data:`STAGES`, or the method's own ``stages``) -> milliseconds.
        render_dir, reference_dir : path, optional
            Where the SSLPV render and the reference images are.
        steps_used : int, optional
            Propagation steps the render ran (``steps = auto`` decides it;
            None for ``steps = steady``, which solves instead of stepping).
        diagnostics : dict, optional
            The renderer's diagnostics (``remaining_fraction``,
            ``outside_share``, ``injected_flux``, ``steps_used``), stored as JSON.
        calibration : dict, optional
            ``{"path", "sha256", ...}`` of the calibrated mapping file the render
            used (None for a built-in mapping).
        shared : dict, optional
            For a configuration rendered in a step group (one propagation for
            several step counts): ``{"stages": [...], "group_steps": [...]}``,
            the stages whose timings were measured once for the group.
        method : str
            The method that rendered it (``--method``; default ``sslpv``).
        precompute : dict, optional
            ``{step: {"ms": float, "work": int}}``: the method's precomputation.
        work : dict, optional
            ``{stage: count}``: device-independent work per frame stage.
        stages : sequence of str, optional
            The method's frame stages that ``timings`` may name (besides ``total``);
            default SSLPV's (:data:`STAGES`).
        cached_from : str, optional
            The result-cache key the render was served from (``harness.runs.cache``);
            None when it was rendered in this run.

        Returns
        -------
        int
            The configuration id.
        """
        where = f"{self.path} config {scene}"
        if status not in CONFIG_STATUSES:
            raise InputError(where, "status", f"is {status!r}", f"use one of {', '.join(CONFIG_STATUSES)}")
        if not isinstance(params, dict):
            raise InputError(where, "params", f"is a {type(params).__name__}", "pass a dict of renderer parameters")
        try:
            params_json = _dumps(params)
        except (TypeError, ValueError) as exc:
            raise InputError(where, "params", f"is not JSON-serialisable ({exc})",
                             "pass plain numbers, strings, lists and dicts") from exc
        if steps_used is not None and (isinstance(steps_used, bool) or not isinstance(steps_used, int)
                                       or steps_used < 0):
            raise InputError(where, "steps_used", f"is {steps_used!r}", "record a step count >= 0, or None")
        if not isinstance(method, str) or not re.fullmatch(METHOD_NAME, method):
            raise InputError(where, "method", f"is {method!r}", "name the method, e.g. 'sslpv'")
        extra = {}
        for name, value in (("diagnostics", diagnostics), ("calibration", calibration), ("shared", shared),
                            ("precompute", precompute), ("work", work)):
            if value is not None and not isinstance(value, dict):
                raise InputError(where, name, f"is a {type(value).__name__}", "pass a dict, or None")
            if name == "calibration" and value is not None and not {"path", "sha256"} <= set(value):
                raise InputError(where, name, f"has keys {sorted(value)}", "give at least 'path' and 'sha256'")
            try:
                extra[name] = None if value is None else _dumps(value, False)
            except (TypeError, ValueError) as exc:
                raise InputError(where, name, f"is not JSON-serialisable with finite numbers ({exc})",
                                 "pass plain numbers (None for a missing one), strings, lists and dicts") from exc
        key = self.config_key(scene_hash, params, method)
        with self._write() as db:
            old = db.execute("SELECT id, status FROM configurations WHERE run_id = ? AND config_key = ?",
                             (run_id, key)).fetchone()
            if old is not None:
                if old[1] == "ok":
                    raise InputError(where, "config_key", f"{key} is already recorded in run {run_id}",
                                     "skip the keys in done_keys(run_id)")
                db.execute("DELETE FROM configurations WHERE id = ?", (old[0],))
            if db.execute("SELECT 1 FROM runs WHERE id = ?", (run_id,)).fetchone() is None:
                raise InputError(where, "run_id", f"run {run_id} does not exist", "pass an id from start_run")
            cur = db.execute(
                "INSERT INTO configurations (run_id, scene, scene_hash, config_key, params_json, status,"
                " error, render_dir, reference_dir, created_at, steps_used, diagnostics_json, calibration_json,"
                " shared_json, method, precompute_json, work_json, cached_from)"
                " VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
                (run_id, str(scene), str(scene_hash), key, params_json, status,
                 None if error is None else str(error),
                 None if render_dir is None else str(render_dir),
                 None if reference_dir is None else str(reference_dir), _now(), steps_used,
                 extra["diagnostics"], extra["calibration"], extra["shared"], method, extra["precompute"],
                 extra["work"], None if cached_from is None else str(cached_from)))
            cid = cur.lastrowid
            # Rows are checked one at a time as they are inserted; a bad one
            # raises inside the transaction and everything above rolls back.
            for i, m in enumerate(metrics or ()):
                f = f"metrics[{i}]"
                image, name = m.get("image"), m.get("metric")
                if image not in IMAGES:
                    raise InputError(where, f"{f}.image", f"is {image!r}", f"use one of {', '.join(IMAGES)}")
                if not isinstance(name, str) or not name:
                    raise InputError(where, f"{f}.metric", f"is {name!r}", "name the metric")
                pc = m.get("per_channel")
                if pc is not None:
                    pc = [_finite(where, f"{f}.per_channel", v) for v in pc]
                try:
                    db.execute(
                        "INSERT INTO metrics (config_id, image, metric, value, noise_floor, per_channel_json,"
                        " params_json) VALUES (?,?,?,?,?,?,?)",
                        (cid, image, name, _finite(where, f"{f}.value", m.get("value")),
                         _finite(where, f"{f}.noise_floor", m.get("noise_floor"), allow_none=True),
                         None if pc is None else _dumps(pc, False), _dumps(m.get("params") or {}, False)))
                except sqlite3.IntegrityError as exc:
                    raise InputError(where, f, f"{image}/{name} is given twice ({exc})",
                                     "record each (image, metric) once") from exc
                except (TypeError, ValueError) as exc:
                    if isinstance(exc, InputError):
                        raise
                    raise InputError(where, f"{f}.params", f"is not JSON-serialisable ({exc})",
                                     "pass plain numbers, strings, lists and dicts") from exc
            allowed = tuple(STAGES if stages is None else tuple(stages) + ("total",))
            for stage, ms in (timings or {}).items():
                if stage not in allowed:
                    raise InputError(where, "timings", f"unknown stage {stage!r}", f"use {', '.join(allowed)}")
                ms = _finite(where, f"timings.{stage}", ms)
                if ms < 0:
                    raise InputError(where, f"timings.{stage}", f"is {ms} ms", "record elapsed times >= 0")
                db.execute("INSERT INTO timings (config_id, stage, ms) VALUES (?,?,?)", (cid, stage, ms))
            return cid

    def done_keys(self, run_id, include_failed=False):
        """Config keys already recorded in ``run_id`` (status ``ok``; also ``failed`` if asked).

        A resumed sweep skips these; failed ones are retried by default.
        """
        sql = "SELECT config_key FROM configurations WHERE run_id = ?"
        if not include_failed:
            sql += " AND status = 'ok'"
        return {r[0] for r in self._read(sql, (run_id,))}

    def configs(self, run_id=None, scene=None):
        """Configurations (oldest first) as nested dicts.

        Each has the ``configurations`` columns, ``run_*`` fields of its run,
        ``params`` (dict), ``timings`` (stage -> ms), ``cost_ms`` (``total``,
        else the sum of the stages, else None), ``metrics``
        (``{image: {metric: {value, noise_floor, per_channel, params}}}``),
        ``steps_used`` (int or None), ``diagnostics``, ``calibration``,
        ``shared``, ``precompute`` and ``work`` (dicts, or None), and ``method``
        (see :meth:`record_config`).
        """
        where, args = self._filter(run_id, scene)
        confs = self._read("SELECT c.*, r.kind AS run_kind, r.date AS run_date, r.started_at AS run_started_at,"
                           " r.git_commit AS run_git_commit FROM configurations c JOIN runs r ON r.id = c.run_id"
                           + where + " ORDER BY c.id", args)
        out = {}
        for c in confs:
            d = dict(c)
            d["params"] = _loads(d.pop("params_json"))
            for name in ("diagnostics", "calibration", "shared", "precompute", "work"):
                d[name] = _loads(d.pop(f"{name}_json"))
            d["timings"], d["metrics"], d["cost_ms"] = {}, {}, None
            out[d["id"]] = d
        if not out:
            return []
        sub = "SELECT c.id FROM configurations c" + where
        for m in self._read(f"SELECT * FROM metrics WHERE config_id IN ({sub})", args):
            out[m["config_id"]]["metrics"].setdefault(m["image"], {})[m["metric"]] = {
                "value": m["value"], "noise_floor": m["noise_floor"],
                "per_channel": _loads(m["per_channel_json"]), "params": _loads(m["params_json"])}
        for t in self._read(f"SELECT * FROM timings WHERE config_id IN ({sub})", args):
            out[t["config_id"]]["timings"][t["stage"]] = t["ms"]
        for d in out.values():
            t = d["timings"]
            d["cost_ms"] = t.get("total", sum(t.values()) if t else None)
        return list(out.values())

    def results(self, run_id=None, scene=None):
        """Flat rows, one per (configuration, image, metric); a configuration without
        metrics (a failure) gives one row with ``image``/``metric``/``value`` None.

        Columns: run_id, config_id, scene, scene_hash, config_key, status,
        error, render_dir, reference_dir, created_at, cost_ms, ``ms_<stage>``
        for each SSLPV stage and each stage another method of the selection
        recorded, steps_used, diagnostics, calibration, shared, precompute,
        work (dicts or None), method, params (dict), image, metric, value,
        noise_floor, per_channel (list or None), metric_params (dict).
        """
        rows = []
        configs = self.configs(run_id, scene)
        stages = list(STAGES) + sorted({s for c in configs for s in c["timings"]} - set(STAGES))
        for c in configs:
            base = {k: c[k] for k in ("run_id", "id", "scene", "scene_hash", "config_key", "status", "error",
                                      "render_dir", "reference_dir", "created_at", "cost_ms", "steps_used",
                                      "diagnostics", "calibration", "shared", "method", "precompute", "work")}
            base["config_id"] = base.pop("id")
            for s in stages:
                base[f"ms_{s}"] = c["timings"].get(s)
            base["params"] = c["params"]
            mrows = [(img, name, m) for img, ms in c["metrics"].items() for name, m in ms.items()]
            if not mrows:
                rows.append({**base, "image": None, "metric": None, "value": None, "noise_floor": None,
                             "per_channel": None, "metric_params": None})
            for img, name, m in mrows:
                rows.append({**base, "image": img, "metric": name, "value": m["value"],
                             "noise_floor": m["noise_floor"], "per_channel": m["per_channel"],
                             "metric_params": m["params"]})
        return rows

    def metric_history(self, scene, params_key, metric, image="subsurface", kind=None):
        """One metric of one configuration over all runs (oldest first), for nightly trends.

        ``params_key`` is either a config key (same scene content and params)
        or a params dict (same params, whatever the scene hash: the trend then
        also shows changes of the scene). Each row: run_id, run_kind, date,
        started_at, git_commit, scene_hash, config_key, status, value,
        noise_floor (value None when that run's configuration failed).
        """
        if isinstance(params_key, dict):
            cond, arg = "c.params_json = ?", _dumps(params_key)
        else:
            cond, arg = "c.config_key = ?", str(params_key)
        sql = ("SELECT r.id AS run_id, r.kind AS run_kind, r.date, r.started_at, r.git_commit, c.scene_hash,"
               " c.config_key, c.status, m.value, m.noise_floor FROM configurations c JOIN runs r ON r.id = c.run_id"
               " LEFT JOIN metrics m ON m.config_id = c.id AND m.metric = ? AND m.image = ?"
               f" WHERE c.scene = ? AND {cond}" + (" AND r.kind = ?" if kind else "")
               + " ORDER BY r.started_at, r.id")
        args = (metric, image, scene, arg) + ((kind,) if kind else ())
        return [dict(r) for r in self._read(sql, args)]

    def _filter(self, run_id, scene):
        conds, args = [], []
        if run_id is not None:
            conds.append("c.run_id = ?")
            args.append(run_id)
        if scene is not None:
            conds.append("c.scene = ?")
            args.append(scene)
        return (" WHERE " + " AND ".join(conds) if conds else ""), tuple(args)

    # -- export ----------------------------------------------------------------

    def export(self, path, run_id=None, scene=None):
        """Write :meth:`results` to ``path`` (see :func:`harness.store.export.export`); returns the row count."""
        from harness.store.export import export

        return export(self, path, run_id, scene)


class _Row(dict):
    """A result row: a dict that can also be indexed by position."""

    def __init__(self, names, values):
        super().__init__(zip(names, values))
        self._values = values

    def __getitem__(self, key):
        if isinstance(key, int):
            return self._values[key]
        return super().__getitem__(key)
