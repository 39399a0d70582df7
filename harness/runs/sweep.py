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
                       one single-threaded worker process per core; see "CPU use")
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

Step groups (``run_sweep(group=True)``, the default). Configurations of one scene
that share every parameter but an integer ``steps`` form one group, rendered by ONE
worker task with :meth:`sslpv_gl.renderer.SSLPVRenderer.render_steps`: RSM,
injection and the material grid once, one propagation to the group's largest step
count, the shading pass as each count passes. Every image is bit-identical to a
render of its count alone (``tests/test_sweep_groups.py``), and each count is still
its own configuration row with its own metrics. Its timings are those
``render_steps`` reports: ``propagation`` is the GL time of the steps up to that
count (what a render of it alone spends), while ``rsm`` and ``injection`` were
measured ONCE for the group and repeated in each of its rows, whose ``shared``
column (``{"stages", "group_steps"}``) says so; ``total`` is their sum, the cost of
that count rendered alone. ``steps = auto`` and ``steady`` cannot share a
propagation: each is a group of its own (so ``--steps 8,auto,steady,32`` gives
three groups). ``group=False`` renders every configuration on its own (the sweep
before step groups; ``benchmarks/bench_sweep.py`` compares the two). Groups are
submitted largest first (N^3 x largest count) so that the long ones do not trail.
Every row also records ``steps_used``, the renderer's diagnostics (read back
outside the stage timers) and the calibrated mapping file with its hash.

Resuming is per configuration: the store's done keys are per step count, and a
group is formed from the MISSING configurations only, so a group that was
interrupted after some of its counts were recorded renders only the rest (as a
smaller group) and no row is ever written twice.

CPU use. A LocalCluster has one worker process per core, one thread each (a
worker's GL context is not shared between threads), and llvmpipe keeps its own
thread count (``LP_NUM_THREADS`` unset: one thread per core;
:data:`DEFAULT_LP_THREADS`, ``run_sweep(lp_threads=...)``; an ``LP_NUM_THREADS``
in the environment is passed on). Measured on this 2-core machine with
``benchmarks/bench_sweep.py --table`` (grouped sweep, 3 scenes x N 32, 64 x
K 4..64 at 64x64, two runs each): workers x LP_NUM_THREADS 1x1 57.8 s, 1x2
30.5/32.9 s, 2x1 38.6/34.3 s, 2x2 31.9/34.0 s, 2 x llvmpipe's default 19.6/45.6 s.
One llvmpipe thread per worker is clearly slower; among the rest the differences
are within this machine's run-to-run noise, so the default restricts nothing
(workers = cores, llvmpipe's own thread count), which also scales to larger machines.
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


def expand_all(params):
    """One product (dict of lists) or several (a list of them) -> their configurations, first seen first."""
    products = params if isinstance(params, list) else [params]
    out, seen = [], set()
    for product in products:
        for p in expand(product):
            key = tuple(sorted(p.as_dict().items()))
            if key not in seen:
                seen.add(key)
                out.append(p)
    return out


SWEEP_FILE = "sweep.json"
#: ``LP_NUM_THREADS`` for a LocalCluster's workers (``"default"``: llvmpipe's own). See the module docstring.
DEFAULT_LP_THREADS = "default"


@dataclasses.dataclass
class SweepConfig:
    """The resolved configuration of a sweep; written beside its results as ``sweep.json``."""

    scenes: list                      # scene names or folders
    params: dict                      # SSLPVParams field -> list of values (or a list of such products)
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
    """Arrays the workers compare against: subsurface, full, halves, per-pixel standard errors and the mask.

    ``mask`` is :func:`harness.metrics.coverage.comparison_mask` of the reference's
    coverage (fully covered pixels only; ``coverage`` keeps the fractions), the one
    comparison mask of every metric, verdict and calibration. ``se`` and ``se_full``
    are the standard errors of the subsurface and full images (None where the file
    has none), ``K`` the number of independent seeds they were estimated from.
    """
    import json

    from harness.io.images import read_exr
    from harness.metrics.coverage import comparison_mask

    ref_dir = Path(ref_dir)
    sub = read_exr(ref_dir / "subsurface.exr", expect_shape=shape)
    full = read_exr(ref_dir / "full.exr", expect_shape=shape)
    mask_layer = sub.get("mask")
    if mask_layer is None and (ref_dir / "mask.exr").is_file():
        mask_layer = read_exr(ref_dir / "mask.exr", expect_shape=shape)["rgb"][..., 0]
    if mask_layer is None:
        raise InputError(ref_dir, "mask", "the reference has no object mask", "re-render the reference")
    meta = ref_dir / "reference.json"
    k = json.loads(meta.read_text()).get("K") if meta.is_file() else None
    return {"subsurface": sub["rgb"], "full": full["rgb"], "se": sub.get("se"), "se_full": full.get("se"),
            "half_a": read_exr(ref_dir / "half_a.exr", expect_shape=shape)["rgb"],
            "half_b": read_exr(ref_dir / "half_b.exr", expect_shape=shape)["rgb"],
            "coverage": np.asarray(mask_layer, dtype=np.float32), "mask": comparison_mask(mask_layer),
            "K": int(k) if k else None, "dir": str(ref_dir)}


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


def make_client(scheduler=None, workers=None, lp_threads=None):
    """A Dask client: on ``scheduler``, else on a LocalCluster of ``workers`` single-threaded
    processes (default: one per core) whose llvmpipe uses ``lp_threads`` threads
    (``LP_NUM_THREADS``; default :data:`DEFAULT_LP_THREADS`; ``"default"`` leaves
    llvmpipe's own choice, one thread per core; 0 renders in the calling thread). An
    ``LP_NUM_THREADS`` already set in the environment is kept. Each worker process owns
    one GL context, which is not shared between threads, so ``threads_per_worker`` is
    always 1. The workers of an existing scheduler keep their own environment."""
    from dask.distributed import Client, LocalCluster

    if scheduler:
        try:
            client, cluster = Client(scheduler, timeout="10s"), None
        except (OSError, TimeoutError) as exc:
            raise InputError("--scheduler", "scheduler", f"cannot reach Dask scheduler {scheduler!r} ({exc})",
                             "start it with 'dask scheduler' or drop --scheduler for a local cluster") from exc
    else:
        n = workers or os.cpu_count() or 1
        lp = DEFAULT_LP_THREADS if lp_threads is None else lp_threads
        # LP_NUM_THREADS already in the environment wins; "default" leaves llvmpipe's own choice.
        env = {} if lp == "default" or "LP_NUM_THREADS" in os.environ else {"LP_NUM_THREADS": str(int(lp))}
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=50, env=env)
        client = Client(cluster)
    client.register_plugin(ReleaseGL())
    return client, cluster


def _write_render(render_dir, res):
    from harness.runs.render import write_render_dir

    info = {k: res[k] for k in ("params", "timings", "gl_renderer", "scene", "scene_hash")}
    write_render_dir(render_dir, res["images"]["full"], res["images"]["subsurface"], res["mask"], info,
                     res["images"]["subsurface"], res.get("exposure", 0.0))


def group_configs(todo, group=True):
    """``[(scene, params, key)]`` -> ``[(scene, base_params, [(steps, key), ...])]``: step groups.

    Configurations of one scene that share every parameter but an integer ``steps``
    form one group (step counts ascending); ``steps = auto`` and ``steady`` cannot share
    a propagation and each form a group of their own, as does every configuration
    when ``group`` is False (the per-configuration sweep). Groups come out largest
    estimated cost first (N^3 x largest step count), so the longest ones do not
    trail at the end of the sweep.
    """
    groups = {}
    for s, p, key in todo:
        d = p.as_dict()
        if group and isinstance(p.steps, int) and not isinstance(p.steps, bool):
            gkey = (s.name, json.dumps({k: v for k, v in d.items() if k != "steps"}, sort_keys=True, default=str))
        else:
            gkey = (s.name, key)
        groups.setdefault(gkey, (s, p, []))[2].append((p.steps, key))
    out = [(s, p, sorted(members, key=lambda m: (not isinstance(m[0], int), m[0] if isinstance(m[0], int) else 0)))
           for s, p, members in groups.values()]
    out.sort(key=_group_cost, reverse=True)      # stable: input order among equal costs
    return out


def _group_cost(g):
    _, p, members = g
    ks = [k if isinstance(k, int) else 64 for k, _ in members]
    return p.N ** 3 * max(max(ks), 1)


def run_sweep(cfg, scheduler=None, workers=None, progress=True, group=True, lp_threads=None):
    """Run (or resume) a sweep; returns what it wrote and measured.

    Everything that can be wrong with the input (scenes, parameters, the scheduler,
    the reference images) is checked before the store or the output folder is touched.

    ``group=True`` (the default) renders each step group (:func:`group_configs`) as one
    worker task with one propagation; ``group=False`` renders every configuration on
    its own (the sweep before step groups; kept for the benchmark). Both record the
    same rows, with bit-identical images and metrics. ``lp_threads`` sets
    ``LP_NUM_THREADS`` for a LocalCluster's workers (see :data:`DEFAULT_LP_THREADS`).
    """
    from harness.store import Store

    t0 = time.perf_counter()
    out = Path(cfg.out)
    store_path = Path(cfg.store) if cfg.store else out / "store.sqlite"
    configs = expand_all(cfg.params)
    if not configs:
        raise InputError("sweep", "params", "no configurations", "give at least one value per parameter")
    scenes = [load_scene(n) for n in cfg.scenes]
    if cfg.size:
        scenes = [s.with_resolution(*cfg.size) for s in scenes]
    client, cluster = make_client(scheduler, workers, lp_threads) if scheduler else (None, None)
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
            groups = group_configs(todo, group)
            summary["groups"] = len(groups)
            if todo:
                if client is None:
                    client, cluster = make_client(None, workers, lp_threads)
                _dispatch(client, store, run_id, groups, arrays, out, refs, cfg, summary, progress)
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


def _dispatch(client, store, run_id, groups, arrays, out, refs, cfg, summary, progress):
    """Submit every step group, then record each configuration as its group arrives (client-side only).

    Test hook: with ``SSLPV_SWEEP_CRASH_MID_GROUP=1`` the client kills its own process
    group (itself and a LocalCluster's workers, as a crash would) right after recording
    the first configuration of a group of two or more; nothing else of that group is
    recorded. Only for the tests: run it in a process group of its own.
    """
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
    n_groups = len(groups)
    for i, (s, p, members) in enumerate(groups):
        ref_f, floors, _ = shared[s.name]
        ks = [k for k, _ in members]
        tag = members[0][1] if len(members) == 1 else "group-" + members[0][1] + f"-{len(members)}"
        # Priority: groups come largest first; Dask runs higher priorities first.
        fut = client.submit(sweep_worker.run_group, str(s.path), cfg.size, p.as_dict(), ks, ref_f, floors,
                            key=f"sslpv-{tag}", pure=False, retries=2, priority=n_groups - i)
        futures[fut] = (s, p, members)
    crash_mid_group = os.environ.get("SSLPV_SWEEP_CRASH_MID_GROUP") == "1"
    try:
        with _progress(progress, sum(len(m) for _, _, m in futures.values())) as advance:
            for fut in as_completed(list(futures)):
                s, p, members = futures.pop(fut)
                try:
                    results = fut.result()
                except Exception as exc:  # a worker died more often than the retries allow
                    err = f"{type(exc).__name__}: {exc}".splitlines()[0]
                    results = [{"status": "failed", "error": err} for _ in members]
                for n_recorded, ((k, key), res) in enumerate(zip(members, results)):
                    pk = p.replace(steps=k)
                    _record(store, run_id, s, pk, key, res, out, refs, summary, shared[s.name][2])
                    advance(f"{s.name} N={pk.N} K={pk.steps} {pk.mapping}")
                    if crash_mid_group and n_recorded == 0 and len(members) > 1:
                        _crash()
    except KeyboardInterrupt:
        store.finish_run(run_id, "interrupted", gl_renderer=summary["gl_renderer"])
        raise


def _record(store, run_id, s, p, key, res, out, refs, summary, exposure):
    """Write one configuration's render folder, then its store row (one transaction)."""
    render_dir = None
    if res["status"] == "ok":
        summary["gl_renderer"] = summary["gl_renderer"] or res["gl_renderer"]
        render_dir = out / "renders" / s.name / key[:16]
        res.update(params=p.as_dict(), scene=s.name, scene_hash=s.content_hash, exposure=exposure)
        _write_render(render_dir, res)
        summary["ok"] += 1
    else:
        summary["failed"] += 1
    store.record_config(run_id, s.name, s.content_hash, p.as_dict(), res["status"],
                        error=res.get("error"), metrics=res.get("metrics", []),
                        timings=res.get("timings", {}),
                        render_dir=str(render_dir) if render_dir else None,
                        reference_dir=str(refs[s.name]), steps_used=res.get("steps_used"),
                        diagnostics=res.get("diagnostics"), calibration=res.get("calibration"),
                        shared=res.get("shared"))


def _crash():
    """Die like a killed sweep: SIGKILL to this process group when it leads one, else to itself."""
    import signal

    if os.getpgid(0) == os.getpid():
        os.killpg(os.getpid(), signal.SIGKILL)
    os.kill(os.getpid(), signal.SIGKILL)


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
