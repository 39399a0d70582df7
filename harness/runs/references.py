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

import numpy as np

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


# --------------------------------------------------------------------------- the references a sweep reads

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


# --------------------------------------------------------------------------- the references a sweep renders

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
    from harness.runs.cluster import make_client

    client, cluster = make_client(scheduler, workers)
    if scheduler:
        return client, cluster, None
    n = len(client.scheduler_info().get("workers", {}))
    return client, cluster, local_threads(n)


def run_reference_cmd(scene_name, out_dir=None, target=None, spp=None, variant=None, force=False,
                      max_minutes=None, estimate=False, size=None, workers=None, scheduler=None, serial=False,
                      progress=True, sms_split=None):
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
    from harness.runs.plan import parse_size
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
    kwargs = {"spp": spp, "variant": variant, "target_rel_se": target, "max_seconds": max_seconds,
              "sms_split": sms_split}
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
