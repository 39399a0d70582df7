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

import os
import time
from pathlib import Path

from harness.io.atomic import atomic_write
from harness.io.outputs import check_sweep_folder, check_writable, claim_sweep_folder
from harness.errors import InputError
from harness.runs.params import FIELD_TO_CLI

from harness.reference.committed import sized_scene
from harness.runs.cache import SweepCache, open_cache, workers_gl_renderer
from harness.runs.cluster import DEFAULT_LP_THREADS, ReleaseGL, _close_cluster, make_client  # noqa: F401
from harness.runs.plan import (SweepConfig, config_from_args, expand_all, group_configs,  # noqa: F401
                               parse_size, resolve_scenes)
from harness.runs.record import _record_cached, _resume_or_start
from harness.runs.references import fetch_references, load_reference, reference_coverage, reference_dir  # noqa: F401
from harness.runs.schedule import MAX_RESUBMITS, NO_WORKERS_TIMEOUT_S, _dispatch, _local_ref_threads  # noqa: F401
from harness.scene import load_scene

SWEEP_FILE = "sweep.json"


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


def run_sweep_cli(args):
    """``sslpv-harness sweep``: progress on stderr (``harness.progress``), the summary on stdout."""
    cfg = config_from_args(args)
    return run_sweep(cfg, scheduler=args.scheduler, workers=args.workers, progress=args.progress,
                     cache=not getattr(args, "no_cache", False))


__all__ = ["SweepConfig", "run_sweep", "run_sweep_cli", "FIELD_TO_CLI"]
