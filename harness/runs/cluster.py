"""The Dask cluster of a sweep (and of the ``reference`` command): the client, its workers, and their close.

:func:`make_client` connects to a scheduler, or starts a LocalCluster of one single-threaded
worker process per core (a worker's GL context is not shared between threads) whose llvmpipe
keeps its own thread count (:data:`DEFAULT_LP_THREADS`; the measurements behind that default
are in :mod:`harness.runs.sweep`'s docstring). :class:`ReleaseGL` loads pymeshlab on each
worker's main thread and releases the worker's GL context at close; :func:`_close_cluster`
closes the client and cluster without raising once everything is recorded.
"""

import os

from dask.distributed import WorkerPlugin

from harness.errors import EnvironmentProblem, InputError

#: ``LP_NUM_THREADS`` for a LocalCluster's workers (``"default"``: llvmpipe's own). See the module docstring.
DEFAULT_LP_THREADS = "default"


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
