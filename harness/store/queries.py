"""Queries of the results store: runs, configurations with their metrics and timings, flat results, histories.

:meth:`StoreQueries.configs` returns each configuration as nested dicts (parameters,
stage timings, metric rows); :meth:`StoreQueries.results` one flat row per metric, which
is what :mod:`harness.store.export` writes and the report reads;
:meth:`StoreQueries.metric_history` one metric of one configuration across runs (the
nightly trends). Reads take the store's lock and see committed transactions only.
"""

from harness.errors import InputError
from harness.store.schema import STAGES
from harness.store.values import _dumps, _loads


class StoreQueries:
    """The reading half of :class:`harness.store.store.Store` (its connection: ``_read``, ``path``)."""

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
