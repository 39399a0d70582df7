"""A store's results as one flat table: CSV, or Parquet when pyarrow is installed."""

import csv
from pathlib import Path

from harness.errors import InputError
from harness.io.atomic import atomic_write
from harness.io.outputs import check_writable
from harness.store.schema import STAGES
from harness.store.values import _dumps


#: Fixed leading columns of :meth:`Store.export` (``param.<name>`` columns follow).
EXPORT_COLUMNS = ["run_id", "config_id", "scene", "scene_hash", "config_key", "status", "error", "render_dir",
                  "reference_dir", "created_at", "cost_ms"] + [f"ms_{s}" for s in STAGES] + [
                  "steps_used", "diagnostics_json", "calibration_json", "shared_json", "params_json", "image", "metric", "value", "noise_floor", "per_channel_json",
                  "metric_params_json", "method", "precompute_json", "work_json"]


def export(store, path, run_id=None, scene=None):
    """Write :meth:`Store.results <harness.store.queries.StoreQueries.results>` to ``path``: ``.csv``, or ``.parquet`` when pyarrow is installed.

    ``scene`` (a name, or a list of names, each of which must have configurations) keeps only their rows.

    Dicts and lists become JSON text columns (``params_json``,
    ``per_channel_json``, ``metric_params_json``, ``diagnostics_json``,
    ``calibration_json``, ``shared_json``) and each parameter also
    gets its own ``param.<name>`` column (JSON text). Floats are written
    with ``repr`` so that they read back exactly. Returns the row count.
    """
    path = Path(path)
    fmt = path.suffix.lower()
    if path.is_dir():
        raise InputError(path, "output", "is a folder", "give --out a file name ending in .csv or .parquet")
    if fmt not in (".csv", ".parquet"):
        raise InputError(path, "format", f"unknown extension {path.suffix!r}", "export to .csv or .parquet")
    check_writable(path, "--out")
    if run_id is not None:
        store.run(run_id)                        # an unknown id is refused, as `report --run` refuses it
    wanted = [scene] if isinstance(scene, str) else scene
    if wanted is not None:
        scenes = store.scenes(run_id)
        for name in wanted:
            if name not in scenes:
                within = f" of run {run_id}" if run_id is not None else ""
                raise InputError(store.path, "scene", f"no configuration{within} is of scene {name!r}",
                                 f"pick one of: {', '.join(scenes)}" if scenes else "the store has no configurations")
    if fmt == ".parquet":
        try:
            import pyarrow as pa
            import pyarrow.parquet as pq
        except ImportError:
            raise InputError(path, "format", "writing Parquet needs pyarrow, which is not installed",
                             "install pyarrow (pip install pyarrow) or export to .csv") from None
    rows = store.results(run_id) if wanted is None else [r for n in wanted for r in store.results(run_id, n)]
    pnames = sorted({k for r in rows for k in r["params"]})
    flat = []
    for r in rows:
        d = {k: v for k, v in r.items() if k not in ("params", "per_channel", "metric_params", "diagnostics",
                                                     "calibration", "shared", "precompute", "work")}
        for name in ("diagnostics", "calibration", "shared", "precompute", "work"):
            d[f"{name}_json"] = None if r[name] is None else _dumps(r[name], False)
        d["params_json"] = _dumps(r["params"])
        d["per_channel_json"] = None if r["per_channel"] is None else _dumps(r["per_channel"], False)
        d["metric_params_json"] = None if r["metric_params"] is None else _dumps(r["metric_params"], False)
        for p in pnames:
            d[f"param.{p}"] = _dumps(r["params"][p]) if p in r["params"] else None
        flat.append(d)
    # another method's stages (``ms_gather``, ...) follow SSLPV's fixed ones
    extra_ms = sorted({k for d in flat for k in d if k.startswith("ms_")} - set(EXPORT_COLUMNS))
    columns = EXPORT_COLUMNS + extra_ms + [f"param.{p}" for p in pnames]
    with atomic_write(path) as tmp:
        if fmt == ".parquet":
            table = pa.Table.from_pylist(flat) if flat else pa.table({c: [] for c in columns})
            pq.write_table(table, tmp)
        else:
            with open(tmp, "w", newline="", encoding="utf-8") as fh:
                w = csv.DictWriter(fh, fieldnames=columns)
                w.writeheader()
                for d in flat:
                    w.writerow({k: ("" if v is None else repr(v) if isinstance(v, float) else v)
                                for k, v in d.items()})
    return len(flat)
