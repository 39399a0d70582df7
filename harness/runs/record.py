"""The recording of a sweep: each configuration's render folder and store row, and the run it belongs to.

The client is the only writer: :func:`_record` writes one configuration's render folder
(:func:`harness.runs.render.write_render_dir`), then its store row in one transaction;
:func:`_record_cached` records configurations served by the result cache (measuring their
metrics again where the metric code changed); :func:`_resume_or_start` continues the same
sweep's unfinished run, or starts a new one.
"""

import json

from harness.runs.params import config_label


def _write_render(render_dir, res):
    from harness.runs.render import write_render_dir

    info = {k: res[k] for k in ("params", "timings", "gl_renderer", "scene", "scene_hash")}
    write_render_dir(render_dir, res["images"]["full"], res["images"]["subsurface"], res["mask"], info,
                     res["images"]["subsurface"], res.get("exposure", 0.0))


def _record_cached(store, run_id, hits, arrays, out, refs, summary, cache):
    """Record configurations served by the result cache.

    Their metric rows come from the entry when today's metric code computed them (the entry's key
    holds the images and the reference); otherwise they are measured now against this sweep's
    reference and kept in the entry for the next time (:meth:`ResultCache.put_metrics`).
    """
    from harness.io.images import auto_exposure

    from harness.runs import worker as sweep_worker

    floors, exposure = {}, {}
    for s, p, key, res in hits:
        arr = arrays[s.name]
        if s.name not in exposure:
            exposure[s.name] = auto_exposure(arr["subsurface"])
        if res.get("metrics") is None:
            if s.name not in floors:
                floors[s.name] = sweep_worker.reference_floors(arr)
            res["metrics"] = sweep_worker.measure(res["images"], arr, floors[s.name])
            cache.put_metrics(res["cached"], res["metrics"])
        _record(store, run_id, s, p, key, res, out, refs, summary, exposure[s.name])
        summary["reused"] += 1


def _record(store, run_id, s, p, key, res, out, refs, summary, exposure):
    """Write one configuration's render folder, then its store row (one transaction).

    ``p`` is SSLPVParams, or another method's :class:`~harness.runs.rivals.MethodConfig`, whose row
    also records its method and stages (:func:`harness.runs.rivals.store_fields`).
    """
    from harness.runs.rivals import store_fields

    extra = store_fields(p)
    render_dir = None
    if res["status"] == "ok":
        summary["gl_renderer"] = summary["gl_renderer"] or res["gl_renderer"]
        render_dir = out / "renders" / s.name / key[:16]
        res.update(params=dict(p.as_dict(), **({"method": extra["method"]} if extra else {})), scene=s.name,
                   scene_hash=s.content_hash, exposure=exposure)
        _write_render(render_dir, res)
        summary["ok"] += 1
    else:
        summary["failed"] += 1
        summary.setdefault("first_error", f"{s.name} {p.label() if extra else config_label(p)}: {res.get('error')}")
    store.record_config(run_id, s.name, s.content_hash, p.as_dict(), res["status"], **extra,
                        error=res.get("error"), metrics=res.get("metrics", []),
                        timings=res.get("timings", {}),
                        render_dir=str(render_dir) if render_dir else None,
                        reference_dir=str(refs[s.name]) if refs.get(s.name) else None,
                        steps_used=res.get("steps_used"),
                        diagnostics=res.get("diagnostics"), calibration=res.get("calibration"),
                        shared=res.get("shared"), precompute=res.get("precompute"), work=res.get("work"),
                        cached_from=res.get("cached"))


def _resume_or_start(store, cfg, out):
    """The same sweep (same folder, same configuration) continues its unfinished run."""
    from harness.store import git_commit

    cfg_json = json.loads(cfg.to_json())
    for run in reversed(store.runs()):
        if run.get("out_dir") == str(out) and run.get("config") == cfg_json and run.get("status") != "finished":
            return run["id"]
    return store.start_run(cfg.kind, cfg_json, out_dir=str(out), git_commit=git_commit())
