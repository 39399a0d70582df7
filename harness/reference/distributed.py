"""References on a Dask cluster: a plan's jobs as tasks, several references at once.

:class:`DaskDriver` runs :class:`harness.reference.plan.ReferencePlan` s on a
``dask.distributed.Client``: every job of a round (one ``mi.render`` call of one
pass, seed and chunk; :func:`harness.reference.jobs.render_job`) is a task; the
client merges each result as it arrives (in chunk order per seed, once per job)
and, when a plan's round is complete, asks the plan for its next round. Several
plans run side by side, so a sweep can render all the references it lacks at once
and start the SSLPV configurations of each scene as soon as its reference is
written (:meth:`DaskDriver.start`, :meth:`DaskDriver.handle`).

A task whose worker dies is re-run by Dask (``retries``); the driver merges the
result of each job exactly once, so nothing is counted twice and the reference
is bit-identical to the serial one for the same seeds and Dr.Jit thread count.
At a plan's time cap (``max_seconds``), the tasks of its running round are
cancelled and the round rolled back.

Before the first task, :func:`check_workers` asks every worker whether it can
render: the harness importable, Mitsuba importable with the variant, and a
libLLVM >= 16 for the ``llvm_*`` variants; a worker that cannot is named in one
line (:class:`harness.errors.EnvironmentProblem`, exit 3).
"""

import itertools
import os
import socket

from harness.errors import EnvironmentProblem

from . import jobs as _jobs

#: Seconds between looks at the clock while waiting for tasks (time caps).
POLL_S = 1.0
_IDS = itertools.count()


def probe_worker(variant=None):
    """What this process lacks to render references with ``variant`` (run on each worker)."""
    out = {"host": socket.gethostname(), "pid": os.getpid(), "missing": None}
    variant = variant or "llvm_ad_rgb"
    try:
        import mitsuba
    except Exception as exc:  # an ImportError, or a broken install raising anything
        out["missing"] = f"Mitsuba 3 is not importable ({type(exc).__name__}: {exc})"
        return out
    out["mitsuba"] = getattr(mitsuba, "__version__", "?")
    if variant.startswith("llvm"):
        from harness.reference.llvm import find_libllvm

        current = os.environ.get("DRJIT_LIBLLVM_PATH")
        llvm = current if current and os.path.exists(current) else find_libllvm()
        if llvm is None:
            out["missing"] = f"no libLLVM >= 16 for Mitsuba's {variant} (install Debian's libllvm19)"
            return out
        out["llvm"] = llvm
    try:
        variants = mitsuba.variants()
    except Exception:  # very old builds: let set_variant decide later
        variants = [variant]
    if variant not in variants:
        out["missing"] = f"Mitsuba {out['mitsuba']} was built without the {variant} variant"
    return out


def check_workers(client, variant=None):
    """Raise :class:`EnvironmentProblem` naming the first worker that cannot render; return the probes."""
    workers = client.scheduler_info().get("workers", {})
    if not workers:
        raise EnvironmentProblem("Dask cluster: no workers are connected to the scheduler; start workers with "
                                 "'dask worker ADDRESS' on machines that have this project installed")
    probes = client.run(probe_worker, variant, on_error="return")
    for addr, p in sorted(probes.items()):
        if isinstance(p, BaseException):
            raise EnvironmentProblem(f"Dask worker {addr}: cannot run the harness ({type(p).__name__}: "
                                     f"{str(p).splitlines()[0] if str(p) else ''}); install this project "
                                     "(pip install -e .) on every worker")
        if p.get("missing"):
            raise EnvironmentProblem(f"Dask worker {addr} (host {p['host']}): {p['missing']}; install Mitsuba 3 "
                                     "and libLLVM >= 16 on every worker (scripts/setup.sh) or remove that worker")
    return probes


def cluster_slots(client):
    """How many tasks the cluster runs at once: the sum of its workers' threads."""
    workers = client.scheduler_info().get("workers", {})
    return max(1, sum(int(w.get("nthreads", 1)) for w in workers.values()))


class DaskDriver:
    """Run reference plans' jobs as Dask tasks; merge on the client. See the module docstring."""

    def __init__(self, client, variant=None, check=True, retries=3):
        self.client = client
        self.retries = int(retries)
        if check:
            check_workers(client, variant)
        self.slots = cluster_slots(client)
        n = len(client.scheduler_info().get("workers", {}))
        self.name = f"a Dask cluster of {n} worker{'s' if n != 1 else ''}"
        self._setups = {}          # setup key -> scattered future
        self._owner = {}           # future -> (plan, job)
        self._plan_futures = {}    # id(plan) -> set of its futures

    # ----------------------------------------------------------------- low level (the sweep uses these)

    def start(self, plan):
        """Start ``plan``; returns the futures of its first round."""
        plan.plan_id = next(_IDS)
        self._plan_futures[id(plan)] = set()
        return self._submit(plan, plan.start())

    def _submit(self, plan, jobs):
        if jobs is None:
            return []
        key = plan.setup.key
        if key not in self._setups:
            self._setups[key] = self.client.scatter(plan.setup, hash=False)
        futures = []
        n = len(jobs)
        for i, job in enumerate(jobs):
            fut = self.client.submit(_jobs.render_job, self._setups[key], job, pure=False, retries=self.retries,
                                     key=f"reference-{plan.scene.name}-{plan.plan_id}-{job.pass_name}-s{job.seed}"
                                         f"-c{job.chunk}", priority=n - i)
            self._owner[fut] = (plan, job)
            self._plan_futures[id(plan)].add(fut)
            futures.append(fut)
        return futures

    def owns(self, fut):
        return fut in self._owner

    def plan_of(self, fut):
        return self._owner[fut][0]

    def handle(self, fut):
        """Merge a finished reference task; returns ``(plan, new futures, meta or None)``.

        ``meta`` is the plan's ``reference.json`` once it finished (the folder is written).
        A task that failed more often than its retries raises its error, naming the plan's scene.
        """
        plan, job = self._owner.pop(fut)
        self._plan_futures[id(plan)].discard(fut)
        try:
            result = fut.result()
        except Exception as exc:
            self.cancel(plan)
            plan.close_progress()
            raise RuntimeError(f"reference of {plan.scene.name}: job {job.pass_name} seed {job.seed} chunk "
                               f"{job.chunk} failed ({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''})"
                               ) from exc
        plan.merge(job, result)
        if not plan.round_complete():
            return plan, [], None
        return self._advance(plan)

    def _advance(self, plan):
        jobs = plan.next_jobs()
        if jobs is None:
            self._plan_futures.pop(id(plan), None)
            return plan, [], plan.finish()
        return plan, self._submit(plan, jobs), None

    def cancel(self, plan):
        futs = list(self._plan_futures.get(id(plan), ()))
        for f in futs:
            self._owner.pop(f, None)
        if futs:
            self.client.cancel(futs)
        self._plan_futures[id(plan)] = set()

    def check_deadlines(self, plans):
        """Abandon the running round of every plan past its time cap; returns ``(plan, meta)`` of those finished."""
        done = []
        for plan in plans:
            if id(plan) in self._plan_futures and plan.abortable() and plan.past_deadline():
                self.cancel(plan)
                plan.abort_round()
                _, futs, meta = self._advance(plan)
                assert not futs
                done.append((plan, meta))
        return done

    # ----------------------------------------------------------------- high level

    def run(self, plans):
        """Run ``plans`` to the end side by side; returns their metadata in order."""
        from dask.distributed import wait

        metas = {}
        pending = set()
        try:
            for plan in plans:
                pending.update(self.start(plan))
            live = list(plans)
            while len(metas) < len(plans):
                for plan, meta in self.check_deadlines([p for p in live if id(p) not in metas]):
                    metas[id(plan)] = meta
                pending = {f for f in pending if f in self._owner}
                if not pending:
                    # A plan whose round completed without new tasks has finished; nothing else can be waiting.
                    if len(metas) < len(plans):
                        raise RuntimeError("reference plans stalled with no task in flight")
                    break
                timeout = POLL_S if any(p.deadline is not None for p in live if id(p) not in metas) else None
                try:
                    finished = wait(list(pending), timeout=timeout, return_when="FIRST_COMPLETED").done
                except TimeoutError:
                    continue
                for fut in finished:
                    if fut not in self._owner:
                        continue
                    pending.discard(fut)
                    plan, new, meta = self.handle(fut)
                    pending.update(new)
                    if meta is not None:
                        metas[id(plan)] = meta
        finally:
            for plan in plans:
                if id(plan) not in metas:
                    self.cancel(plan)
                    plan.close_progress()
        return [metas[id(p)] for p in plans]
