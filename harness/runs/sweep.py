"""``sslpv-harness sweep``: every configuration of a parameter grid (SSLPV's, and with
``--method`` the dipole rivals') against each scene's cached Mitsuba reference, on Dask distributed.

=====================  ==============================================================
option                 meaning
=====================  ==============================================================
``--scenes A,B``       suite scenes (default: all)
``--method A,B``      methods to sweep (default ``sslpv``; ``dipole``, ``dirpole``:
                       ``harness.methods``); each takes the parameters that belong to it
``--grid 16,32``       any renderer parameter as a comma-separated list
                       (``--steps``, ``--mapping``, ``--lookup``, ``--gather``, ``--spacing``, ...)
``--size WxH``         image size for SSLPV and the reference (default: the scene's);
                       ``--size small``: each scene at its committed small size (64x64, or
                       its own aspect: ``harness.reference.committed.small_size``), whose
                       committed references are used
``--scheduler ADDR``   run on an existing Dask cluster (default: a LocalCluster with
                       one single-threaded worker process per core; see "CPU use")
``--config FILE``      re-run from the ``sweep.json`` a sweep wrote
=====================  ==============================================================

The client renders (or fetches) references, scatters them to the workers, and is
the only writer of files and of the store. The output folder must be new, empty or a
sweep's (a user's folder is refused), and it is locked while the sweep runs: a second
sweep into it is refused with one line (``harness.io.outputs``). Every output is checked
before the first file is written. Progress goes to stderr (``harness.progress``: one
line per reference, then the configurations with done/total, the ETA and the failures),
the summary to stdout; a run that ends ``incomplete`` makes the command exit 1 with one
line that says how to resume it. Each finished configuration is
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
from typing import Annotated, Optional, Union

import numpy as np
from dask.distributed import WorkerPlugin
from pydantic import Discriminator, Field, Tag
from pydantic.dataclasses import dataclass as pydantic_dataclass

from harness.io.atomic import atomic_write
from harness.io.outputs import check_sweep_folder, check_writable, claim_sweep_folder
from harness.errors import EnvironmentProblem, InputError
from harness.runs.params import CLI_TO_FIELD, FIELD_TO_CLI, any_product_model, check_methods, check_products, \
    config_label, parse_lists, product_dict
from harness.validation import INPUT_CONFIG, MAX_IMAGE_SIZE, SweepSize, read_json, validate

from harness.reference.committed import sized_scene
from harness.runs.cache import SweepCache, open_cache, workers_gl_renderer
from harness.scene import list_scenes, load_scene, scene_path, unknown_scene_fix


def expand_all(params):
    """One product (dict of lists) or several (a list of them) -> their configurations, first seen first.

    A product may name its method (``{"method": "dipole", ...}``, :mod:`harness.runs.rivals`);
    SSLPV's configurations are SSLPVParams, another method's :class:`~harness.runs.rivals.MethodConfig`.
    """
    from harness.runs.rivals import expand_product, method_of

    products = params if isinstance(params, list) else [params]
    out, seen = [], set()
    for product in products:
        for p in expand_product(product):
            key = (method_of(p), tuple(sorted(p.as_dict().items())))
            if key not in seen:
                seen.add(key)
                out.append(p)
    return out


SWEEP_FILE = "sweep.json"
#: ``LP_NUM_THREADS`` for a LocalCluster's workers (``"default"``: llvmpipe's own). See the module docstring.
DEFAULT_LP_THREADS = "default"


_PRODUCT = any_product_model("field")
# One product or a list of them, chosen by the value's shape, so that a bad value is reported
# from the one branch that was meant (a plain union reports both, and loses the field's path).
_PRODUCTS = Annotated[Union[Annotated[_PRODUCT, Tag("product")], Annotated[list[_PRODUCT], Tag("products")]],
                      Discriminator(lambda v: "products" if isinstance(v, list) else "product")]


@pydantic_dataclass(config=INPUT_CONFIG)
class SweepConfig:
    """The resolved configuration of a sweep; written beside its results as ``sweep.json``.

    A typed input (a pydantic dataclass): a ``sweep.json`` given to ``--config`` is checked
    field by field (unknown keys, wrong types, sizes beyond 8192 are refused with one line).
    """

    scenes: Annotated[list[Annotated[str, Field(min_length=1)]], Field(min_length=1)]  # names or folders
    params: _PRODUCTS                        # field -> list of values (or a list of such products; "method")
    out: str                                 # output folder
    store: str = ""                          # results store (default OUT/store.sqlite)
    size: Optional[SweepSize] = None         # [W, H]; "small": each scene's committed size; None: the scene's own
    kind: str = "sweep"                      # run kind in the store
    reference_target: Optional[Annotated[float, Field(gt=0, lt=1)]] = None  # median rel. SE asked of references

    def __post_init__(self):
        # Plain dicts again: sweep.json and the store's run config stay what they always were.
        self.params = ([product_dict(p) for p in self.params] if isinstance(self.params, list)
                       else product_dict(self.params))

    def to_json(self):
        return json.dumps(dataclasses.asdict(self), indent=2)

    @classmethod
    def from_file(cls, path):
        """A ``sweep.json``, validated: types by the dataclass, values by SSLPVParams, scenes by the suite."""
        data = read_json(path, "a sweep.json", "give the sweep.json a sweep wrote")
        if isinstance(data, dict):
            check_methods(data.get("params", {}), path, "params")
        cfg = validate(cls, data, path, syntax="json")
        check_products(cfg.params, path, "params", keys="field")
        resolve_scenes(cfg.scenes, where=path)
        return cfg


def parse_size(text):
    """``WxH`` -> ``[W, H]``; ``small`` -> ``"small"``; None -> None."""
    if text is None:
        return None
    if str(text).strip().lower() == "small":
        return "small"
    try:
        w, h = (int(x) for x in str(text).lower().split("x"))
        if w <= 0 or h <= 0:
            raise ValueError
    except ValueError:
        raise InputError("--size", "size", f"{text!r} is not WIDTHxHEIGHT", "write e.g. 128x128, or small") from None
    if w > MAX_IMAGE_SIZE or h > MAX_IMAGE_SIZE:
        raise InputError("--size", "size", f"{w}x{h} is larger than {MAX_IMAGE_SIZE}x{MAX_IMAGE_SIZE}",
                         f"give a width and height of at most {MAX_IMAGE_SIZE}, e.g. 128x128")
    return [w, h]


def resolve_scenes(spec, where="--scenes", field="scenes"):
    """Comma-separated names (or a list) -> validated list; unknown or empty gives one line.

    ``where``/``field`` name the source in the message: the flag, or a file and its key.
    """
    listed = not isinstance(spec, str)
    names = list(spec or list_scenes()) if listed else [s.strip() for s in spec.split(",")]
    if not names or any(not n for n in names):
        raise InputError(where, field, f"empty scene name in {spec!r}", "list scene names separated by commas")
    known = list_scenes()
    for i, n in enumerate(names):
        if not scene_path(n).is_file():
            raise InputError(where, f"{field}[{i}]" if listed and where != "--scenes" else field,
                             f"unknown scene {n!r}", unknown_scene_fix(n, known))
    return names


def config_from_args(args):
    if args.config:
        # The file holds the whole configuration: a flag beside it would be silently ignored.
        from harness.methods.params import all_cli_names

        given = [k for k in (*all_cli_names(), "method", "scenes", "size", "store")
                 if getattr(args, k, None) is not None]
        if given:
            flag = "--" + given[0].replace("_", "-")
            raise InputError(flag, given[0], "cannot be combined with --config (the file holds the whole sweep)",
                             "edit the sweep.json, or drop --config")
        cfg = SweepConfig.from_file(args.config)
        if args.out:
            cfg.out = str(args.out)
        return cfg
    if not args.out:
        raise InputError("--out", "out", "is required", "give an output folder, or --config sweep.json")
    lists = _params_from_args(args)
    return SweepConfig(scenes=resolve_scenes(args.scenes) if args.scenes else list_scenes(), params=lists,
                       out=str(args.out), store=str(args.store or ""), size=parse_size(args.size))


def _params_from_args(args):
    """The sweep's products: SSLPV's lists as before methods, or one product per method (``--method``)."""
    from harness.methods import parse_methods
    from harness.methods.params import all_cli_names, products

    methods = parse_methods(getattr(args, "method", None))
    values = {k: getattr(args, k, None) for k in all_cli_names()}
    if methods == ["sslpv"]:
        products(methods, values)                     # a flag of another method is refused here
        return parse_lists({k: values.get(k) for k in CLI_TO_FIELD})
    return products(methods, values)


# --------------------------------------------------------------------------- references

def reference_coverage(ref_path, layers, shape):
    """``(coverage, source)``: the coverage of the reference image ``ref_path``, or ``(None, None)``.

    ``layers`` is ``ref_path`` as :func:`harness.io.images.read_exr` read it. The coverage is its
    ``mask`` layer, else the ``mask.exr`` beside it (a reference folder's); ``source`` names
    which (``"FILE[mask]"`` or the ``mask.exr`` path). Its
    :func:`~harness.metrics.coverage.comparison_mask` is the comparison mask of
    :func:`load_reference` and of ``sslpv-harness compare``.
    """
    from harness.io.images import read_exr

    ref_path = Path(ref_path)
    if layers.get("mask") is not None:
        return np.asarray(layers["mask"], dtype=np.float32), f"{ref_path}[mask]"
    beside = ref_path.with_name("mask.exr")
    if beside.is_file():
        return read_exr(beside, expect_shape=shape)["rgb"][..., 0], str(beside)
    return None, None


def load_reference(ref_dir, shape):
    """Arrays the workers compare against: subsurface, full, halves, per-pixel standard errors and the mask.

    ``mask`` is :func:`harness.metrics.coverage.comparison_mask` of the reference's
    coverage (fully covered pixels only; ``coverage`` keeps the fractions), the one
    comparison mask of every metric, verdict and calibration. ``se`` and ``se_full``
    are the standard errors of the subsurface and full images (None where the file
    has none), ``K`` the number of independent seeds they were estimated from. A reference
    whose ``reference.json`` says ``"exact": false`` is refused in one line unless
    ``SSLPV_ALLOW_INEXACT_REFERENCE=1`` (:func:`harness.reference.losses.check_exact`).
    """
    import json

    from harness.io.images import read_exr
    from harness.metrics.coverage import comparison_mask

    from harness.reference.losses import check_exact

    ref_dir = Path(ref_dir)
    check_exact(ref_dir)      # a reference that says it is not exact is refused without the opt-in
    sub = read_exr(ref_dir / "subsurface.exr", expect_shape=shape)
    full = read_exr(ref_dir / "full.exr", expect_shape=shape)
    mask_layer, _ = reference_coverage(ref_dir / "subsurface.exr", sub, shape)
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
    """The committed small reference when it matches the scene exactly, else the cache's; None when
    neither is there (the sweep then renders it on its cluster, :class:`harness.runs.references.SweepReferences`).

    A reference that missed its own noise target is refused in one line
    (:func:`harness.runs.references.check_target`), never judged against.
    """
    from harness.reference.cache import _serves, cache_path, read_reference_meta
    from harness.reference.committed import find_committed_reference
    from harness.runs.references import check_target

    committed = find_committed_reference(scene)
    if committed is not None:
        check_target(committed, scene.name)
        return committed
    folder = cache_path(scene)
    meta = read_reference_meta(folder)
    if meta is not None and meta.get("content_hash") == scene.content_hash:
        check_target(folder, scene.name)
    target = target or scene.tolerances.get("reference_rel_se")
    return folder if _serves(meta, scene, {"target_rel_se": float(target)} if target else {}) else None


def fetch_references(scenes, target, progress=True):
    """``(refs, missing)``: each scene's committed or cached reference folder, and the scenes that have
    none (the sweep renders those on its cluster); one progress line per scene says which."""
    from harness.progress import Progress
    from harness.reference.committed import find_committed_reference

    refs, missing = {}, []
    with Progress("references", len(scenes), unit="references", enabled=progress) as bar:
        for s in scenes:
            ref = reference_dir(s, target)
            if ref is None:
                t = target or s.tolerances.get("reference_rel_se") or 0.05
                missing.append(s)
                bar.log(f"{s.name}: not cached: rendering it with Mitsuba to {100 * float(t):g} % median "
                        "relative SE on the sweep's cluster, beside the configurations that have a reference")
            else:
                refs[s.name] = ref
                where = ("the committed small reference" if find_committed_reference(s) is not None
                         else f"the cache ({ref})")
                bar.log(f"{s.name}: {where}")
            bar.advance(detail=s.name)
    return refs, missing


# --------------------------------------------------------------------------- cluster

class ReleaseGL(WorkerPlugin):
    """Dask worker plugin: load pymeshlab on the worker's main thread; release the GL context at close.

    ``setup`` runs on the worker's main (event-loop) thread. Importing :mod:`harness.scene`
    there loads pymeshlab, and with it MeshLab's Qt plugins, before any task runs. Left to
    the first task, the import happens on Dask's executor thread, and the plugins' QObjects
    then belong to that thread. At process exit, MeshLab's static ``PluginManager``
    unloads them after Qt has freed that thread's ``QThreadData``. That use-after-free
    (valgrind: ``QThreadData::deref`` in ``~QObjectPrivate`` from ``~PluginManager``)
    corrupts the heap, and glibc aborts the worker with ``malloc_consolidate(): unaligned
    fastbin chunk detected``. It happened in 10 of 10 small sweeps before this.
    """

    name = "sslpv-release-gl"

    def setup(self, worker):
        import harness.scene  # noqa: F401  (loads pymeshlab on this, the main, thread)

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
        except Exception as exc:  # distributed's parser: ValueError, AssertionError, ...
            why = str(exc).strip().splitlines()[0] if str(exc).strip() else "unknown protocol"
            raise InputError("--scheduler", "scheduler", f"{scheduler!r} is not a Dask scheduler address ({why})",
                             "write e.g. tcp://127.0.0.1:8786") from None
    else:
        n = workers or os.cpu_count() or 1
        lp = DEFAULT_LP_THREADS if lp_threads is None else lp_threads
        # LP_NUM_THREADS already in the environment wins; "default" leaves llvmpipe's own choice.
        env = {} if lp == "default" or "LP_NUM_THREADS" in os.environ else {"LP_NUM_THREADS": str(int(lp))}
        try:
            # The scheduler serves HTTP (health, metrics) even without a dashboard, by default on
            # 0.0.0.0:8787, and warns on stderr when another cluster holds that port: a free
            # localhost port instead.
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                                   silence_logs=50, env=env, scheduler_kwargs={"dashboard_address": "127.0.0.1:0"})
        except Exception as exc:  # a worker that died while starting: "Nanny failed to start."
            raise EnvironmentProblem(f"Dask could not start {n} local worker processes ({exc}); check the free "
                                     "memory and processes, then run the same command again") from exc
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


def run_sweep(cfg, scheduler=None, workers=None, progress=True, group=True, lp_threads=None, cache=True):
    """Run (or resume) a sweep; returns what it wrote and measured.

    Everything that can be wrong with the input (scenes, parameters, the scheduler,
    the reference images) is checked before the store or the output folder is touched.

    ``group=True`` (the default) renders each step group (:func:`group_configs`) as one
    worker task with one propagation; ``group=False`` renders every configuration on
    its own (the sweep before step groups; kept for the benchmark). Both record the
    same rows, with bit-identical images and metrics. ``lp_threads`` sets
    ``LP_NUM_THREADS`` for a LocalCluster's workers (see :data:`DEFAULT_LP_THREADS`).

    ``cache``: the result cache (:mod:`harness.runs.cache`) that configurations are served from
    and stored in: True for the default folder, a :class:`~harness.runs.cache.ResultCache`, or
    False to render everything afresh (``--no-cache``). A served configuration is recorded like a
    rendered one, with the metric rows kept in its entry (measured again when the metric code has
    changed since), and its store row names the cache entry (``cached_from``).
    """
    from harness.progress import Progress
    from harness.store import Store

    t0 = time.perf_counter()
    out = Path(cfg.out)
    store_path = Path(cfg.store) if cfg.store else out / "store.sqlite"
    configs = expand_all(cfg.params)
    if not configs:
        raise InputError("sweep", "params", "no configurations", "give at least one value per parameter")
    scenes = [sized_scene(load_scene(n), cfg.size) for n in cfg.scenes]
    from harness.runs.rivals import check_scenes, method_of

    check_scenes(scenes, configs)            # a rival on a scene it cannot represent: one line, nothing written
    # ---- every output is checked before the first thing is written (and before minutes of references)
    check_sweep_folder(out)
    check_writable(store_path, "--store")
    Store.check(store_path)                  # another program's database, a corrupt or newer store: refused
    results_cache = open_cache(cache)   # a folder that is not a result cache: refused here
    client, cluster = make_client(scheduler, workers, lp_threads) if scheduler else (None, None)
    try:
        with claim_sweep_folder(out):        # held until the sweep ends: a second sweep here is refused
            # References: committed or cached ones are read now; the missing ones are rendered on the
            # sweep's cluster together with the configurations (_dispatch, SweepReferences).
            refs, missing = fetch_references(scenes, cfg.reference_target, progress)
            arrays = {s.name: load_reference(refs[s.name], (s.camera.height, s.camera.width))
                      for s in scenes if s.name in refs}
            cfg.store = str(store_path)
            with atomic_write(out / SWEEP_FILE) as tmp:
                tmp.write_text(cfg.to_json())
            with Store(store_path) as store:
                run_id = _resume_or_start(store, cfg, out)
                done = store.done_keys(run_id)
                todo = [(s, p, key) for s in scenes for p in configs
                        if (key := store.config_key(s.content_hash, p.as_dict(), method_of(p))) not in done]
                summary = {"out": str(out), "store": str(store_path), "run_id": run_id,
                           "sweep_json": str(out / SWEEP_FILE), "configurations": len(scenes) * len(configs),
                           "skipped_done": len(scenes) * len(configs) - len(todo), "ok": 0, "failed": 0,
                           "not_run": 0, "references": {k: str(v) for k, v in refs.items()}, "gl_renderer": None}
                summary["reused"] = 0
                if results_cache is not None and todo:
                    reuse = SweepCache(results_cache, workers_gl_renderer(client), refs)
                    hits, todo = reuse.split(todo, method_of)
                    _record_cached(store, run_id, hits, arrays, out, refs, summary, results_cache)
                    if progress and (hits or results_cache.rejected):
                        Progress("sweep", None).log(f"result cache {results_cache.root}: {len(hits)} of "
                                                    f"{len(hits) + len(todo)} configurations reused, "
                                                    f"{len(todo)} to render")
                else:
                    reuse = None
                # SSLPV in step groups; another method's configuration alone (harness.runs.rivals), one "group" each
                groups = group_configs([t for t in todo if method_of(t[1]) == "sslpv"], group)
                groups += [(s, p, [(None, key)]) for s, p, key in todo if method_of(p) != "sslpv"]
                summary["groups"] = len(groups)
                render_refs = [s for s in missing if any(t[0] is s for t in todo)]
                summary["references_rendered"] = [s.name for s in render_refs]
                if todo:
                    if client is None:
                        if progress:
                            Progress("sweep", None).log(f"starting a local Dask cluster of "
                                                        f"{workers or os.cpu_count() or 1} workers")
                        client, cluster = make_client(None, workers, lp_threads)
                    _dispatch(client, store, run_id, groups, arrays, out, refs, cfg, summary, progress,
                              render_refs=render_refs,
                              ref_threads=None if scheduler else _local_ref_threads(client), reuse=reuse)
                    summary["references"] = {k: str(v) for k, v in refs.items() if v is not None}
                # A run with failed (or never rendered) configurations stays open: the same command
                # retries them, and the command line exits non-zero.
                status = "finished" if summary["failed"] == 0 and summary["not_run"] == 0 else "incomplete"
                store.finish_run(run_id, status, gl_renderer=summary["gl_renderer"])
                summary["status"] = status
                if status != "finished":
                    summary["resume"] = f"sslpv-harness sweep --config {out / SWEEP_FILE}"
    finally:
        _close_cluster(client, cluster, progress)
        if results_cache is not None:
            results_cache.prune()
    summary["wall_s"] = round(time.perf_counter() - t0, 2)
    return summary


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


def _close_cluster(client, cluster, progress):
    """Close the client and a LocalCluster. Everything is recorded by then: a worker that is
    slow to stop (a loaded machine: the nanny's join times out) is said on stderr, not raised."""
    from harness.progress import Progress

    for thing in (client, cluster):
        if thing is None:
            continue
        try:
            thing.close()
        except (TimeoutError, OSError, RuntimeError) as exc:
            if progress:
                Progress("sweep", None).log(f"the Dask {type(thing).__name__} did not close cleanly "
                                            f"({type(exc).__name__}: {exc}); every result was recorded before")


#: Seconds a sweep waits for a Dask worker when its cluster has none before it stops (incomplete).
NO_WORKERS_TIMEOUT_S = 60.0
#: How often a step group is submitted again after its reference was lost with dead workers.
MAX_RESUBMITS = 3


def _lost_data(exc):
    """Was a task cancelled by the cluster ("lost dependencies": the workers that held its
    scattered reference died), rather than failed by itself (an error, ``KilledWorker``)?"""
    return type(exc).__name__ in ("FutureCancelledError", "CancelledError")


class _NoWorkers(Exception):
    pass


def _local_ref_threads(client):
    from harness.runs.references import local_threads

    return local_threads(len(client.scheduler_info().get("workers", {})))


def _dispatch(client, store, run_id, groups, arrays, out, refs, cfg, summary, progress, render_refs=(),
              ref_threads=None, reuse=None):
    """Submit every step group, then record each configuration as its group arrives (client-side only).

    ``render_refs``: scenes whose reference is missing. Their reference jobs run on the same
    cluster, side by side with the groups of the other scenes (:class:`SweepReferences`; a
    reference job whose worker dies is re-run by Dask and merged once); a scene's groups are
    submitted when its reference is written, and fail with the reason when it cannot be (a
    job failed, or the reference missed its target).

    Dead workers: a LocalCluster's nannies start new ones, and Dask runs a task that was on
    a dead worker again (``retries``; one that kills its worker three times fails with
    ``KilledWorker`` and is recorded as failed). The scattered references die with the
    workers that held them, and the tasks that need them are cancelled ("lost
    dependencies"): such a group is submitted again with its reference scattered anew
    (:data:`MAX_RESUBMITS` times; ``SSLPV_SWEEP_MAX_RESUBMITS`` overrides it). When the
    cluster has had no worker for :data:`NO_WORKERS_TIMEOUT_S`, the sweep stops: what is not recorded is counted in
    ``not_run``, the run stays incomplete, and the same command continues it.

    Test hooks: with ``SSLPV_SWEEP_CRASH_MID_GROUP=1`` the client kills its own process
    group (itself and a LocalCluster's workers, as a crash would) right after recording
    the first configuration of a group of two or more; nothing else of that group is
    recorded. Only for the tests: run it in a process group of its own.
    ``SSLPV_SWEEP_KILL_WORKERS=1`` makes every task kill its worker (``harness.runs.worker``).

    ``reuse`` (a :class:`~harness.runs.cache.SweepCache`) stores each rendered configuration.
    """
    from harness.io.images import auto_exposure
    from harness.progress import Progress

    from harness.runs import rivals, worker as sweep_worker

    from harness.runs.references import SweepReferences

    shared = {}

    def share(name):
        # Scatter the dict as ONE object: scattering a dict scatters its values under its keys
        # ("subsurface", "mask", ...), and every scene would then overwrite the previous one's.
        arr = arrays[name]
        shared[name] = (client.scatter([arr], broadcast=True)[0], sweep_worker.reference_floors(arr),
                        auto_exposure(arr["subsurface"]))

    for name in arrays:
        share(name)
    pending, attempts, waiting = {}, [0] * len(groups), {}
    n_groups = len(groups)

    def submit(i):
        s, p, members = groups[i]
        ref_f, floors, _ = shared[s.name]
        size = [s.camera.width, s.camera.height] if cfg.size else None      # each scene's own ("small")
        if rivals.method_of(p) != "sslpv":     # before the SSLPV groups: a dense gather is often the longest task
            pending[rivals.submit(client, sweep_worker, s, size, p, ref_f, floors, n_groups + 1,
                                  attempts[i])] = i
            return
        ks = [k for k, _ in members]
        tag = members[0][1] if len(members) == 1 else "group-" + members[0][1] + f"-{len(members)}"
        tag += f"-r{attempts[i]}" if attempts[i] else ""
        # Priority: groups come largest first; Dask runs higher priorities first.
        fut = client.submit(sweep_worker.run_group, str(s.path), size, p.as_dict(), ks, ref_f, floors,
                            key=f"sslpv-{tag}", pure=False, retries=2, priority=n_groups - i)
        pending[fut] = i

    for i in range(n_groups):
        if groups[i][0].name in shared:
            submit(i)
        else:                                # its reference is rendered first, on this cluster
            waiting.setdefault(groups[i][0].name, []).append(i)
    # --- references the sweep lacks, rendered on its cluster
    pending_refs = SweepReferences(client, list(render_refs), cfg.reference_target, ref_threads)
    crash_mid_group = os.environ.get("SSLPV_SWEEP_CRASH_MID_GROUP") == "1"
    total = sum(len(m) for _, _, m in groups)
    try:
        with Progress("sweep", total, unit="configurations", enabled=progress) as bar:
            no_workers_since = None
            idle_since = time.monotonic()
            ref_futs = set(pending_refs.start())
            while pending or ref_futs:
                # Polled rather than distributed.wait(), which raises as soon as one future is cancelled.
                done_refs = [f for f in ref_futs if f.done()]
                for fut in done_refs:
                    ref_futs.discard(fut)
                    name, new, ref, err = pending_refs.handle(fut)
                    ref_futs.update(new)
                    if ref is None and err is None:
                        continue
                    if ref is not None:
                        refs[name] = ref
                        sc = groups[waiting[name][0]][0]
                        arrays[name] = load_reference(ref, (sc.camera.height, sc.camera.width))
                        share(name)
                        bar.log(f"{name}: reference written ({ref})")
                    for i in waiting.pop(name, []):
                        if err is None:
                            submit(i)
                            continue
                        s, p, members = groups[i]
                        refs.setdefault(name, None)
                        for k, key in members:
                            _record(store, run_id, s, p.replace(steps=k), key, {"status": "failed", "error": err},
                                    out, refs, summary, 0.0)
                            bar.advance(failed=1, detail=f"{s.name}: no reference")
                done = [f for f in pending if f.done()]
                if not done:
                    if done_refs:
                        continue
                    time.sleep(0.1)
                    if time.monotonic() - idle_since < 2.0:
                        continue
                    idle_since = time.monotonic()
                    if client.scheduler_info().get("workers"):
                        no_workers_since = None
                    elif no_workers_since is None:
                        no_workers_since = time.monotonic()
                        bar.log("the cluster has no workers: waiting for new ones")
                    elif time.monotonic() - no_workers_since > NO_WORKERS_TIMEOUT_S:
                        raise _NoWorkers()
                    continue
                for fut in done:
                    i = pending.pop(fut)
                    s, p, members = groups[i]
                    try:
                        results = fut.result()
                    except Exception as exc:  # a worker died more often than the retries allow
                        if _lost_data(exc) and attempts[i] < int(os.environ.get("SSLPV_SWEEP_MAX_RESUBMITS",
                                                                                MAX_RESUBMITS)):
                            attempts[i] += 1
                            if shared[s.name][0].status != "finished":
                                bar.log(f"the reference of {s.name} was lost with dead workers: scattering it again")
                                client.wait_for_workers(1, timeout=NO_WORKERS_TIMEOUT_S)
                                share(s.name)
                            submit(i)
                            continue
                        err = f"{type(exc).__name__}: {exc}".splitlines()[0]
                        results = [{"status": "failed", "error": err} for _ in members]
                    if rivals.method_of(p) != "sslpv":     # another method's configuration (one result)
                        res = results if isinstance(results, dict) else results[0]
                        if reuse is not None:
                            reuse.put(members[0][1], res)
                        _record(store, run_id, s, p, members[0][1], res, out, refs, summary, shared[s.name][2])
                        bar.advance(failed=int(res["status"] != "ok"), detail=f"{s.name} {p.label()}")
                        continue
                    for n_recorded, ((k, key), res) in enumerate(zip(members, results)):
                        pk = p.replace(steps=k)
                        if reuse is not None:
                            reuse.put(key, res)
                        _record(store, run_id, s, pk, key, res, out, refs, summary, shared[s.name][2])
                        bar.advance(failed=int(res["status"] != "ok"),
                                    detail=f"{s.name} N={pk.N} K={pk.steps} {pk.mapping}")
                        if crash_mid_group and n_recorded == 0 and len(members) > 1:
                            _crash()
    except (_NoWorkers, TimeoutError) as exc:
        # No worker came back: stop here; what was recorded stays, the rest is left for a re-run.
        summary["not_run"] = (sum(len(groups[i][2]) for i in pending.values())
                              + sum(len(groups[i][2]) for ii in waiting.values() for i in ii))
        summary["error"] = (f"the Dask cluster lost all its workers and none came back within "
                            f"{NO_WORKERS_TIMEOUT_S:g} s" + (f" ({exc})" if str(exc) else ""))
        client.cancel(list(pending))
    except KeyboardInterrupt:
        store.finish_run(run_id, "interrupted", gl_renderer=summary["gl_renderer"])
        raise
    finally:
        pending_refs.close()


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


def run_sweep_cli(args):
    """``sslpv-harness sweep``: progress on stderr (``harness.progress``), the summary on stdout."""
    cfg = config_from_args(args)
    return run_sweep(cfg, scheduler=args.scheduler, workers=args.workers, progress=args.progress,
                     cache=not getattr(args, "no_cache", False))


__all__ = ["SweepConfig", "run_sweep", "run_sweep_cli", "FIELD_TO_CLI"]
