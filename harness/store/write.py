"""Writing to the results store: a run's start and end, and one configuration with its metrics and timings.

Every write is one ``BEGIN IMMEDIATE`` transaction (:meth:`Store._write`), so several
processes can record into one store at once. :meth:`StoreWrites.record_config` checks
everything it is given (status, parameters, metric rows, stage timings, finite numbers)
before the transaction, and refuses a configuration already recorded as ``ok`` in its run;
:meth:`StoreWrites.config_key` is the stable key a resumed sweep skips by.
"""

import hashlib
import re
import sqlite3

from harness.errors import InputError
from harness.store import provenance
from harness.store.schema import CONFIG_STATUSES, IMAGES, METHOD_NAME, STAGES
from harness.store.values import _dumps, _finite, _now


class StoreWrites:
    """The writing half of :class:`harness.store.store.Store` (its connection: ``_write``, ``_read``, ``path``)."""

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
