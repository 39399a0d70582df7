"""The study's results table: one row per (scene, method, setting), written as CSV and Parquet.

Each row holds every metric of the subsurface and the full image (``subsurface_relmse``, ...) with
its noise floor (``..._floor``: the metric between the reference's two independent halves), the cost
(``frame_ms``: the frame's GL time on this device, ``ms_<stage>``; ``work``: the device-independent
work count summed over the frame's stages, ``work_json`` per stage; ``precompute_ms``), the
configuration (``method``, ``family``, ``setting``, ``N``, ``K``, ``params_json``) and the paths
anyone needs to recompute the row: ``render_dir`` (its ``subsurface.exr`` and ``full.exr``) and
``reference_dir`` (the reference's ``subsurface.exr``; the comparison mask is its coverage
>= :data:`harness.metrics.coverage.FULL_COVERAGE`).

Limits: failed configurations have no row (the study stops before the table when any failed);
the Parquet file needs ``pyarrow``.
"""

import csv
import json

from harness.io.atomic import atomic_write
from harness.metrics import METRICS
from harness.methods import config_label
from harness.study.extensions import family_suffix
from harness.study.spec import study_label

IMAGES = ("subsurface", "full")
#: Leading columns, in order; the metric and stage columns follow.
BASE_COLUMNS = ("scene", "method", "family", "setting", "N", "K", "steps_used", "frame_ms", "work", "precompute_ms",
                "outside_share", "cached", "render_dir", "reference_dir", "scene_hash", "config_key", "params_json",
                "work_json")


def family_of(method, params):
    """The family a configuration competes in: SSLPV's mapping (``calibrated diffusion`` for a calibrated
    file of that family), a rival's method and gather (``dipole dense``), with ``S1`` where it adds Jensen
    et al.'s single scattering (``dipole dense + S1``, ``terms = both``; ``dipole dense S1 only`` for
    ``terms = single``). An SSLPV configuration with options the paper does not have competes in its own
    family, named after them (``collision + interior``; :mod:`harness.study.extensions`)."""
    if method == "sslpv":
        label = study_label(params.get("mapping"))
        # a calibrated file's settings (its outside treatment, say) belong to the calibration, named by its label
        return label if label.startswith("calibrated") else label + family_suffix(params)
    terms = params.get("terms", "diffusion")
    suffix = {"both": " + S1", "single": " S1 only"}.get(terms, "")
    return f"{method} {params.get('gather', '')}".strip() + suffix


def _k(params):
    return params.get("steps")


def rows_of(configs):
    """The table's rows from the store's ``ok`` configurations (:meth:`harness.store.Store.configs`)."""
    rows = []
    for c in configs:
        if c["status"] != "ok":
            continue
        method = c.get("method") or "sslpv"
        p = c["params"]
        work = c.get("work") or {}
        pre = c.get("precompute") or {}
        diag = c.get("diagnostics") or {}
        row = {"scene": c["scene"], "method": method, "family": family_of(method, p),
               "setting": config_label(method, p), "N": p.get("N") if method == "sslpv" else None,
               "K": str(_k(p)) if method == "sslpv" else None, "steps_used": c.get("steps_used"),
               "frame_ms": c.get("cost_ms"),
               # steady solves instead of stepping: its work count has no propagation term, so no total
               "work": float(sum(work.values())) if work and (method != "sslpv" or "propagation" in work) else None,
               "precompute_ms": (float(sum(v["ms"] for v in pre.values() if v.get("ms") is not None))
                                 if pre else None),
               "outside_share": diag.get("outside_share"), "cached": bool(c.get("cached_from")),
               "render_dir": c["render_dir"], "reference_dir": c["reference_dir"], "scene_hash": c["scene_hash"],
               "config_key": c["config_key"], "params_json": json.dumps(p, sort_keys=True),
               "work_json": json.dumps(work, sort_keys=True)}
        for image in IMAGES:
            for name in METRICS:
                m = c["metrics"].get(image, {}).get(name)
                row[f"{image}_{name}"] = None if m is None else m["value"]
                row[f"{image}_{name}_floor"] = None if m is None else m["noise_floor"]
        for stage, ms in sorted(c["timings"].items()):
            row[f"ms_{stage}"] = ms
        rows.append(row)
    rows.sort(key=lambda r: (r["scene"], r["method"] != "sslpv", r["family"], r["N"] or 0, _k_order(r["K"]),
                             r["setting"]))
    return rows


def _k_order(k):
    if k is None:
        return 0
    return int(k) if str(k).isdigit() else 1 << 30


def columns(rows):
    """Every column of ``rows``: :data:`BASE_COLUMNS`, the metrics, then the stage timings."""
    metric_cols = [f"{i}_{n}{s}" for i in IMAGES for n in METRICS for s in ("", "_floor")]
    stages = sorted({k for r in rows for k in r if k.startswith("ms_")})
    return list(BASE_COLUMNS) + metric_cols + stages


def write_csv(rows, path):
    """``rows`` as CSV (every column, empty for a missing value), atomically."""
    cols = columns(rows)
    with atomic_write(path) as tmp:
        with open(tmp, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=cols, extrasaction="raise")
            w.writeheader()
            for r in rows:
                w.writerow({k: ("" if r.get(k) is None else repr(r[k]) if isinstance(r.get(k), float) else r[k])
                            for k in cols})
    return path


def write_parquet(rows, path):
    """``rows`` as Parquet (pyarrow), atomically; the same columns as the CSV."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    cols = columns(rows)
    table = pa.Table.from_pylist([{k: r.get(k) for k in cols} for r in rows])
    with atomic_write(path) as tmp:
        pq.write_table(table, tmp)
    return path


def read_csv(path):
    """The CSV back as dicts of strings (for the tests and ``--docs``)."""
    with open(path, newline="") as f:
        return list(csv.DictReader(f))
