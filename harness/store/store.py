"""The results store: one SQLite file that a sweep or a nightly run fills and the report reads.

A *run* is one invocation of a sweep (or nightly job); a *configuration* is one
SSLPV render of one scene with one set of renderer parameters, compared with
that scene's reference; each configuration has *metric* rows (one per image
and metric, with its noise floor) and *timing* rows (ms per SSLPV stage). The
tables and their migrations are in :mod:`harness.store.schema`; the flat export
in :mod:`harness.store.export`. This module opens the file (creating, checking and
migrating it); writing is :mod:`harness.store.write`, the queries :mod:`harness.store.queries`.

Concurrency: the file is in WAL mode with a 30 s busy timeout, and every write
is one ``BEGIN IMMEDIATE`` transaction, so several processes (Dask workers) can
write to one store at once; each opens its own :class:`Store`. Do not put the
file on a network file system (WAL needs shared memory between processes).

Timestamps are UTC ISO 8601 (``2025-01-31T12:00:00+00:00``).
"""

import contextlib
import os
import sqlite3
import threading
import time
from pathlib import Path

from harness.errors import InputError
from harness.io.outputs import check_writable
from harness.store import schema
from harness.store.queries import StoreQueries
from harness.store.schema import BUSY_TIMEOUT_MS
from harness.store.values import _Row
from harness.store.write import StoreWrites


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


# ---------------------------------------------------------------- the store

class Store(StoreWrites, StoreQueries):
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
