"""``sslpv-harness sweep``: every SSLPV configuration of a parameter grid against
each scene's cached Mitsuba reference, on Dask distributed.

=====================  ==============================================================
option                 meaning
=====================  ==============================================================
``--scenes A,B``       suite scenes (default: all)
``--grid 16,32``       any renderer parameter as a comma-separated list
                       (``--steps``, ``--mapping``, ``--lookup``, ...)
``--size WxH``         image size for SSLPV and the reference (default: the scene's)
``--scheduler ADDR``   run on an existing Dask cluster (default: a LocalCluster with
                       one single-threaded worker process per core)
``--config FILE``      re-run from the ``sweep.json`` a sweep wrote
=====================  ==============================================================

The client renders (or fetches) references, scatters them to the workers, and is
the only writer of files and of the store. Each finished configuration is
committed to the store at once, so Ctrl-C, a killed worker (Dask re-runs its
task elsewhere) or a crash loses nothing; running the same command again skips
every configuration already recorded as ``ok`` and retries failed ones. A run is
``finished`` only when every configuration is ``ok`` (else ``incomplete``,
``interrupted``, or still ``running`` after a crash); running the same sweep again
continues such a run, while re-running a finished sweep from its ``sweep.json``
makes a new run (a reproduction).
"""

import dataclasses
import json
import os
import time
from pathlib import Path

import numpy as np
from dask.distributed import WorkerPlugin

from harness.io.atomic import atomic_write
from harness.errors import InputError
from harness.runs.params import CLI_TO_FIELD, FIELD_TO_CLI, expand, parse_lists
from harness.scene import list_scenes, load_scene, scene_path

SWEEP_FILE = "sweep.json"


@dataclasses.dataclass
class SweepConfig:
    """The resolved configuration of a sweep; written beside its results as ``sweep.json``."""

    scenes: list                      # scene names or folders
    params: dict                      # SSLPVParams field -> list of values
    out: str                          # output folder
    store: str = ""                   # results store (default OUT/store.sqlite)
    size: list = None                 # [W, H] or None for the scenes' own size
    kind: str = "sweep"               # run kind in the store
    reference_target: float = None    # median relative SE asked of references (None: renderer default)

    def to_json(self):
        return json.dumps(dataclasses.asdict(self), indent=2)

    @classmethod
    def from_file(cls, path):
        path = Path(path)
        if not path.is_file():
            raise InputError(path, "file", "does not exist", "give the sweep.json a sweep wrote")
        try:
            data = json.loads(path.read_text())
            return cls(**data)
        except (json.JSONDecodeError, TypeError) as exc:
            raise InputError(path, "sweep.json", f"is not a sweep configuration ({exc})",
                             "give the sweep.json a sweep wrote") from exc


def parse_size(text):
    if text is None:
        return None
    try:
        w, h = (int(x) for x in str(text).lower().split("x"))
        if w <= 0 or h <= 0:
            raise ValueError
    except ValueError:
        raise InputError("--size", "size", f"{text!r} is not WIDTHxHEIGHT", "write e.g. 128x128") from None
    return [w, h]


def resolve_scenes(spec):
    """Comma-separated names (or a list) -> validated list; unknown or empty gives one line."""
    names = [s.strip() for s in spec.split(",")] if isinstance(spec, str) else list(spec or list_scenes())
    if not names or any(not n for n in names):
        raise InputError("--scenes", "scenes", f"empty scene name in {spec!r}", "list scene names separated by commas")
    known = list_scenes()
    for n in names:
        if not scene_path(n).is_file():
            raise InputError("--scenes", "scenes", f"unknown scene {n!r}", f"choose from: {', '.join(known)}")
    return names


def config_from_args(args):
    if args.config:
        cfg = SweepConfig.from_file(args.config)
        if args.out:
            cfg.out = str(args.out)
        return cfg
    if not args.out:
        raise InputError("--out", "out", "is required", "give an output folder, or --config sweep.json")
    lists = parse_lists({k: getattr(args, k, None) for k in CLI_TO_FIELD})
    return SweepConfig(scenes=resolve_scenes(args.scenes) if args.scenes else list_scenes(), params=lists,
                       out=str(args.out), store=str(args.store or ""), size=parse_size(args.size))


# --------------------------------------------------------------------------- references

def load_reference(ref_dir, shape):
    """Arrays the workers compare against: subsurface, full, halves and the object mask."""
    from harness.io.images import read_exr

    ref_dir = Path(ref_dir)
    sub = read_exr(ref_dir / "subsurface.exr", expect_shape=shape)
    full = read_exr(ref_dir / "full.exr", expect_shape=shape)
    mask_layer = sub.get("mask")
    if mask_layer is None and (ref_dir / "mask.exr").is_file():
        mask_layer = read_exr(ref_dir / "mask.exr", expect_shape=shape)["rgb"][..., 0]
    if mask_layer is None:
        raise InputError(ref_dir, "mask", "the reference has no object mask", "re-render the reference")
    return {"subsurface": sub["rgb"], "full": full["rgb"], "se": sub.get("se"),
            "half_a": read_exr(ref_dir / "half_a.exr", expect_shape=shape)["rgb"],
            "half_b": read_exr(ref_dir / "half_b.exr", expect_shape=shape)["rgb"],
            "mask": np.asarray(mask_layer) > 0.5}


def reference_dir(scene, target=None):
    """The committed small reference when it matches the scene exactly, else the cache's (rendered if absent)."""
    from harness.reference.committed import find_committed_reference
    from harness.reference.cache import reference_for

    committed = find_committed_reference(scene)
    if committed is not None:
        return committed
    target = target or scene.tolerances.get("reference_rel_se")
    kwargs = {"target_rel_se": float(target)} if target else {}
    return Path(reference_for(scene, cache_dir=None, **kwargs))


# --------------------------------------------------------------------------- cluster

class ReleaseGL(WorkerPlugin):
    """Dask worker plugin: each worker releases its GL context when it closes."""

    name = "sslpv-release-gl"

    def setup(self, worker):
        pass

    def teardown(self, worker):
        from harness.runs import worker as sweep_worker

        sweep_worker.release_renderer()


def make_client(scheduler=None, workers=None):
    from dask.distributed import Client, LocalCluster

    if scheduler:
        try:
            client, cluster = Client(scheduler, timeout="10s"), None
        except (OSError, TimeoutError) as exc:
            raise InputError("--scheduler", "scheduler", f"cannot reach Dask scheduler {scheduler!r} ({exc})",
                             "start it with 'dask scheduler' or drop --scheduler for a local cluster") from exc
    else:
        n = workers or os.cpu_count() or 1
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=50)
        client = Client(cluster)
    client.register_plugin(ReleaseGL())
    return client, cluster


def _write_render(render_dir, res):
    from harness.runs.render import write_render_dir

    info = {k: res[k] for k in ("params", "timings", "gl_renderer", "scene", "scene_hash")}
    write_render_dir(render_dir, res["images"]["full"], res["images"]["subsurface"], res["mask"], info,
                     res["images"]["subsurface"], res.get("exposure", 0.0))


def run_sweep(cfg, scheduler=None, workers=None, progress=True):
    """Run (or resume) a sweep; returns what it wrote and measured.

    Everything that can be wrong with the input (scenes, parameters, the scheduler,
    the reference images) is checked before the store or the output folder is touched.
    """
    from harness.store import Store

    t0 = time.perf_counter()
    out = Path(cfg.out)
    store_path = Path(cfg.store) if cfg.store else out / "store.sqlite"
    configs = expand(cfg.params)
    if not configs:
        raise InputError("sweep", "params", "no configurations", "give at least one value per parameter")
    scenes = [load_scene(n) for n in cfg.scenes]
    if cfg.size:
        scenes = [s.with_resolution(*cfg.size) for s in scenes]
    client, cluster = make_client(scheduler, workers) if scheduler else (None, None)
    try:
        refs = {}
        for s in scenes:
            # A missing reference is rendered here, which can take minutes: say so.
            with _status(progress, f"reference of {s.name}: from the cache, or rendering it with Mitsuba"):
                refs[s.name] = reference_dir(s, cfg.reference_target)
        arrays = {s.name: load_reference(refs[s.name], (s.camera.height, s.camera.width)) for s in scenes}

        out.mkdir(parents=True, exist_ok=True)
        cfg.store = str(store_path)
        with atomic_write(out / SWEEP_FILE) as tmp:
            tmp.write_text(cfg.to_json())
        with Store(store_path) as store:
            run_id = _resume_or_start(store, cfg, out)
            done = store.done_keys(run_id)
            todo = [(s, p, key) for s in scenes for p in configs
                    if (key := store.config_key(s.content_hash, p.as_dict())) not in done]
            summary = {"out": str(out), "store": str(store_path), "run_id": run_id,
                       "sweep_json": str(out / SWEEP_FILE), "configurations": len(scenes) * len(configs),
                       "skipped_done": len(scenes) * len(configs) - len(todo), "ok": 0, "failed": 0,
                       "references": {k: str(v) for k, v in refs.items()}, "gl_renderer": None}
            if todo:
                if client is None:
                    client, cluster = make_client(None, workers)
                _dispatch(client, store, run_id, todo, arrays, out, refs, cfg, summary, progress)
            # A run with failed configurations stays open: the same command retries them.
            status = "finished" if summary["failed"] == 0 else "incomplete"
            store.finish_run(run_id, status, gl_renderer=summary["gl_renderer"])
            summary["status"] = status
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    summary["wall_s"] = round(time.perf_counter() - t0, 2)
    return summary


def _dispatch(client, store, run_id, todo, arrays, out, refs, cfg, summary, progress):
    """Submit every configuration, then record each result as it arrives (client-side only)."""
    from dask.distributed import as_completed

    from harness.io.images import auto_exposure

    from harness.runs import worker as sweep_worker

    shared = {}
    for name, arr in arrays.items():
        # Scatter the dict as ONE object: scattering a dict scatters its values under its keys
        # ("subsurface", "mask", ...), and every scene would then overwrite the previous one's.
        shared[name] = (client.scatter([arr], broadcast=True)[0], sweep_worker.reference_floors(arr),
                        auto_exposure(arr["subsurface"]))
    futures = {}
    for s, p, key in todo:
        ref_f, floors, _ = shared[s.name]
        fut = client.submit(sweep_worker.run_config, str(s.path), cfg.size, p.as_dict(), ref_f, floors,
                            key=f"sslpv-{key}", pure=False, retries=2)
        futures[fut] = (s, p, key)
    try:
        with _progress(progress, len(futures)) as advance:
            for fut in as_completed(list(futures)):
                s, p, key = futures.pop(fut)
                try:
                    res = fut.result()
                except Exception as exc:  # a worker died more often than the retries allow
                    res = {"status": "failed", "error": f"{type(exc).__name__}: {exc}".splitlines()[0]}
                render_dir = None
                if res["status"] == "ok":
                    summary["gl_renderer"] = summary["gl_renderer"] or res["gl_renderer"]
                    render_dir = out / "renders" / s.name / key[:16]
                    res.update(params=p.as_dict(), scene=s.name, scene_hash=s.content_hash,
                               exposure=shared[s.name][2])
                    _write_render(render_dir, res)
                    summary["ok"] += 1
                else:
                    summary["failed"] += 1
                store.record_config(run_id, s.name, s.content_hash, p.as_dict(), res["status"],
                                    error=res.get("error"), metrics=res.get("metrics", []),
                                    timings=res.get("timings", {}),
                                    render_dir=str(render_dir) if render_dir else None,
                                    reference_dir=str(refs[s.name]))
                advance(f"{s.name} N={p.N} K={p.steps} {p.mapping}")
    except KeyboardInterrupt:
        store.finish_run(run_id, "interrupted", gl_renderer=summary["gl_renderer"])
        raise


def _resume_or_start(store, cfg, out):
    """The same sweep (same folder, same configuration) continues its unfinished run."""
    from harness.store import git_commit

    cfg_json = json.loads(cfg.to_json())
    for run in reversed(store.runs()):
        if run.get("out_dir") == str(out) and run.get("config") == cfg_json and run.get("status") != "finished":
            return run["id"]
    return store.start_run(cfg.kind, cfg_json, out_dir=str(out), git_commit=git_commit())


def _status(enabled, text):
    import contextlib

    if not enabled:
        return contextlib.nullcontext()
    from rich.console import Console

    return Console(stderr=True).status(text)


class _progress:
    """A rich progress bar with an ETA, or nothing."""

    def __init__(self, enabled, total):
        self.enabled, self.total = enabled, total

    def __enter__(self):
        if not self.enabled:
            return lambda label: None
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, \
            TimeRemainingColumn

        self.bar = Progress(TextColumn("[bold]sweep"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                            TextColumn("ETA"), TimeRemainingColumn(), TextColumn("{task.description}"),
                            transient=False)
        self.bar.__enter__()
        task = self.bar.add_task("", total=self.total)
        return lambda label: self.bar.update(task, advance=1, description=label)

    def __exit__(self, *exc):
        if self.enabled:
            self.bar.__exit__(*exc)
        return False


def run_sweep_cli(args):
    cfg = config_from_args(args)
    import sys

    return run_sweep(cfg, scheduler=args.scheduler, workers=args.workers,
                     progress=not args.no_progress and not args.json and sys.stderr.isatty() or
                     (not args.no_progress and not args.json))


__all__ = ["SweepConfig", "run_sweep", "run_sweep_cli", "FIELD_TO_CLI"]
