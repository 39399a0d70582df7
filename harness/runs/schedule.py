"""The scheduling of a sweep: its step groups and missing references as Dask tasks, each result recorded as it arrives.

:func:`_dispatch` submits every step group (largest first; a scene whose reference is
missing waits for it, rendered on the same cluster by
:class:`harness.runs.references.SweepReferences`), and records each configuration as its
group comes back (:mod:`harness.runs.record`). A group whose scattered reference died with
its workers is submitted again (:data:`MAX_RESUBMITS` times); a cluster without workers for
:data:`NO_WORKERS_TIMEOUT_S` stops the sweep, incomplete, for the same command to continue.
"""

import os
import time

from harness.runs.record import _record
from harness.runs.references import load_reference


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


def _crash():
    """Die like a killed sweep: SIGKILL to this process group when it leads one, else to itself."""
    import signal

    if os.getpgid(0) == os.getpid():
        os.killpg(os.getpid(), signal.SIGKILL)
    os.kill(os.getpid(), signal.SIGKILL)
