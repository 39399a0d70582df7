"""References for runs: the ``reference`` command on a Dask cluster, and the references a sweep lacks.

``sslpv-harness reference SCENE`` renders (or takes from the cache) a scene's Mitsuba
ground truth. By default its jobs run on a ``LocalCluster`` (one single-threaded
worker per core, each render with ``cores // workers`` Dr.Jit threads); ``--scheduler
ADDR`` uses an existing cluster whose workers have this project installed;
``--serial`` renders in this process. ``--max-minutes`` caps the wall time,
``--estimate`` prints the cost model's prediction without rendering
(:mod:`harness.reference.cost`).

:class:`SweepReferences` is how a sweep renders the references it lacks on ITS
cluster, side by side with the SSLPV configurations that already have one: the
sweep's ``as_completed`` loop hands it the reference tasks, and when a scene's
reference is written the sweep submits that scene's configurations.

A reference that missed its own noise target (a ``--max-minutes`` cap, or the
``max_spp_per_seed`` cap) is never judged against: :func:`check_target` refuses it
in one line.
"""

import json
import os
import shutil
from pathlib import Path

from harness.errors import InputError


def check_target(ref_dir, scene_name=None):
    """Refuse (one line) a reference folder whose ``reference.json`` says it missed its noise target."""
    meta_path = Path(ref_dir) / "reference.json"
    if not meta_path.is_file():
        return
    try:
        meta = json.loads(meta_path.read_text())
    except ValueError:
        return
    if meta.get("target_met", True) is not False:
        return
    r, t = meta.get("median_rel_se_subsurface"), meta.get("target_rel_se")
    name = scene_name or meta.get("scene", "SCENE")
    if not isinstance(r, (int, float)):
        raise InputError(meta_path, "target_met", "the reference has no fully covered lit pixel to measure its "
                         "noise on at this image size; SSLPV is not judged against it", "render a larger image")
    why = f" (stopped by {meta['capped_by']})" if meta.get("capped_by") else ""
    raise InputError(meta_path, "target_met", f"the reference reached {r:.2%} median relative SE, its target is "
                     f"{t:.2%}{why}; SSLPV is not judged against it",
                     f"re-render it without a time cap: sslpv-harness reference {name} --force")


def local_threads(n_workers):
    """Dr.Jit threads per render on a LocalCluster of ``n_workers``: the cores shared out, at least 1."""
    return max(1, (os.cpu_count() or 1) // max(1, int(n_workers)))


class SweepReferences:
    """Render a sweep's missing references on its client, several at once (see the module docstring)."""

    def __init__(self, client, scenes, target=None, threads=None, progress=False):
        from harness.reference.cache import cache_path
        from harness.reference.distributed import DaskDriver
        from harness.reference.render import ReferencePlan, RenderSetup

        self.driver = DaskDriver(client) if scenes else None
        self.plans = {}
        for s in scenes:
            t = target or s.tolerances.get("reference_rel_se") or 0.05
            plan = ReferencePlan(RenderSetup(s, threads=threads), cache_path(s), target_rel_se=float(t),
                                 progress=progress, slots=self.driver.slots, executor=self.driver.name)
            self.plans[s.name] = plan

    def start(self):
        """Submit the first round of every reference; returns the futures."""
        return [f for plan in self.plans.values() for f in self.driver.start(plan)]

    def owns(self, fut):
        return self.driver is not None and self.driver.owns(fut)

    def handle(self, fut):
        """``(scene name, new futures, reference folder or None, error line or None)``."""
        plan = self.driver.plan_of(fut)
        name = plan.scene.name
        try:
            _, new, meta = self.driver.handle(fut)
        except RuntimeError as exc:
            return name, [], None, str(exc)
        if meta is None:
            return name, new, None, None
        try:
            check_target(plan.out_dir, name)
        except InputError as exc:
            return name, [], None, str(exc)
        return name, [], plan.out_dir, None

    def close(self):
        if self.driver is not None:
            for plan in self.plans.values():
                self.driver.cancel(plan)
                plan.close_progress()


# --------------------------------------------------------------------------- the reference command

def _client(scheduler, workers, serial):
    """``(client, cluster, threads per render)`` for the reference command (``(None, None, None)``: serial)."""
    if serial:
        if scheduler or workers:
            raise InputError("--serial", "serial", "renders in this process and takes no cluster",
                             "drop --scheduler/--workers, or drop --serial")
        return None, None, None
    from harness.runs.sweep import make_client

    client, cluster = make_client(scheduler, workers)
    if scheduler:
        return client, cluster, None
    n = len(client.scheduler_info().get("workers", {}))
    return client, cluster, local_threads(n)


def run_reference_cmd(scene_name, out_dir=None, target=None, spp=None, variant=None, force=False,
                      max_minutes=None, estimate=False, size=None, workers=None, scheduler=None, serial=False,
                      progress=True):
    """``sslpv-harness reference SCENE [...]``: render (or fetch from the cache) a suite scene's reference.

    Copies it to ``out_dir`` when given, and returns what it wrote and measured. ``estimate``
    prints the cost model's prediction instead of rendering anything.
    """
    from harness.io.atomic import atomic_dir
    from harness.io.outputs import check_replaceable, check_writable
    from harness.reference import plan as _plan
    from harness.reference.cache import read_reference_meta, reference_for
    from harness.reference.committed import sized_scene
    from harness.reference.render import check_max_seconds
    from harness.runs.sweep import parse_size
    from harness.scene import load_scene

    scene = sized_scene(load_scene(scene_name), parse_size(size))
    if target is not None and not (0 < float(target) < 1):
        raise InputError("--target", "target", f"must be a relative standard error in (0, 1), got {target}",
                         "use e.g. 0.05")
    if out_dir is not None and not estimate:   # refused before minutes of rendering, not after them
        check_replaceable(out_dir)
        check_writable(out_dir, "--out")
    max_seconds = None
    if max_minutes is not None:
        max_seconds = 60.0 * check_max_seconds(max_minutes, "--max-minutes", "max-minutes")
    # The scene states the noise its reference needs (dielectric scenes converge slowly).
    target = target if target is not None else scene.tolerances.get("reference_rel_se")
    target = float(target) if target is not None else 0.05
    if estimate:
        from harness.reference.cost import estimate_reference

        n_slots = None if serial else (workers or os.cpu_count() or 1)
        return estimate_reference(scene, target, workers=n_slots, scheduler=scheduler)
    kwargs = {"spp": spp, "variant": variant, "target_rel_se": target, "max_seconds": max_seconds}
    client, cluster, threads = _client(scheduler, workers, serial)
    try:
        before = _plan.RENDER_COUNT
        folder = reference_for(scene, force=force, client=client, threads=threads, progress=progress, **kwargs)
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    meta = read_reference_meta(folder)
    result = {"scene": scene.name, "content_hash": scene.content_hash, "reference_dir": str(folder),
              "rendered": _plan.RENDER_COUNT != before, "out_dir": None, "files": meta["files"],
              "median_rel_se_subsurface": meta.get("median_rel_se_subsurface"),
              "median_rel_se_full": meta.get("median_rel_se_full"), "target_rel_se": meta.get("target_rel_se"),
              "target_met": meta.get("target_met"), "capped_by": meta.get("capped_by"),
              "spp_total": meta.get("spp_total"), "K": meta.get("K"), "render_seconds": meta.get("render_seconds"),
              "wall_seconds": meta.get("wall_seconds"), "executor": meta.get("executor")}
    if out_dir is not None:
        out = Path(out_dir)
        if out.resolve() != folder.resolve():
            with atomic_dir(out) as tmp:
                for name in meta["files"]:
                    shutil.copy2(folder / name, tmp / name)
        result["out_dir"] = str(out)
    return result
