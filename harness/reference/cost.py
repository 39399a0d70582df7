"""A cost model of the ground truth: seconds per sample and noise per sample from optical size and albedo.

``benchmarks/bench_reference_cost.py`` renders a small family of homogeneous,
index-matched spheres (the camera and light of ``sphere_homogeneous``) over a grid
of optical size and albedo, measures for each

* ``t_px``: seconds per sample per covered pixel (one render, Dr.Jit's default thread count), and
* ``v``: the relative variance of one sample, ``v = r^2 N`` from the median relative standard
  error ``r`` measured with ``N`` samples per pixel in all (SE ~ 1/sqrt(N)),

and fits, by least squares on logarithms, the two-variable model

    log q = c0 + c1 x + c2 y + c3 x y,    x = log(tau),  y = log(1 / (1 - albedo))

for ``q = t_px`` and ``q = v``. ``tau`` is the optical size, ``sigma_t`` times the mesh's
mean chord ``4 V / S`` (Cauchy's formula for convex bodies); ``1 / (1 - albedo)`` is the
mean number of scattering events before absorption. The coefficients, the points they
were fitted to and the machine they were measured on are committed in
``cost_model.json`` beside this module.

:func:`estimate_reference` predicts a scene's reference without rendering it: each
colour pass contributes its ``t_px(tau_c, albedo_max_c)`` times the covered pixels (the
largest albedo sets where Russian roulette starts, so how long paths get); the
samples needed are ``v / target^2`` (median over the channels of ``v``), plus the
pilot; the time divides by the cores at hand over the cores the model was measured
on, and adds the measured fixed overhead. It knows nothing about the light's
placement, a rough dielectric boundary (its absorber pass and heavy tails) or
heterogeneity beyond the mean coefficients inside the mesh; ``benchmarks/
bench_reference_cost.py --check`` measures its error on real scenes.
"""

import json
import math
import os
from pathlib import Path

import numpy as np

from harness.errors import InputError

MODEL_FILE = Path(__file__).with_name("cost_model.json")


def features(tau, albedo):
    """The model's regressors ``[1, x, y, x y]`` for optical size ``tau`` and ``albedo`` (arrays broadcast)."""
    tau = np.asarray(tau, dtype=np.float64)
    a = np.minimum(np.asarray(albedo, dtype=np.float64), 1.0 - 1e-6)
    x, y = np.log(np.maximum(tau, 1e-6)), np.log(1.0 / (1.0 - a))
    return np.stack(np.broadcast_arrays(np.ones_like(x * y), x, y, x * y), axis=-1)


def fit(tau, albedo, q):
    """Least-squares coefficients of ``log q`` on :func:`features`, and the RMS residual (in log units)."""
    X = features(tau, albedo)
    yv = np.log(np.asarray(q, dtype=np.float64))
    coef, *_ = np.linalg.lstsq(X, yv, rcond=None)
    resid = yv - X @ coef
    return coef, float(np.sqrt(np.mean(resid ** 2)))


def predict(coef, tau, albedo):
    """``q`` from fitted coefficients (the inverse of :func:`fit`'s logarithm)."""
    return np.exp(features(tau, albedo) @ np.asarray(coef, dtype=np.float64))


def load_model(path=None):
    path = Path(path or MODEL_FILE)
    if not path.is_file():
        raise InputError(path, "file", "the reference cost model is missing",
                         "run .venv/bin/python benchmarks/bench_reference_cost.py --fit")
    return json.loads(path.read_text())


def mean_chord(mesh):
    """``4 V / S`` of a closed mesh (Cauchy: the mean chord of a convex body under uniform random lines)."""
    tri = np.asarray(mesh.triangles(), dtype=np.float64)
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1).sum()
    volume = abs(np.einsum("ij,ij->i", tri[:, 0], cross).sum()) / 6.0
    return 4.0 * volume / area


def medium_summary(scene):
    """Per channel: mean σt, mean and largest albedo over the voxels inside the mesh; the mean chord, optical size."""
    from harness.scene.geometry import grid_inside

    m = scene.medium
    inside = grid_inside(scene.mesh, m.bbox_min, m.bbox_max, m.resolution)
    if not inside.any():
        inside = np.ones(inside.shape, dtype=bool)
    st = np.asarray(m.sigma_t, np.float64)[inside].mean(axis=0)
    al = np.asarray(m.albedo, np.float64)[inside]
    chord = mean_chord(scene.mesh)
    return {"sigma_t": st.tolist(), "albedo": al.mean(axis=0).tolist(), "albedo_max": al.max(axis=0).tolist(),
            "mean_chord": chord, "tau": (st * chord).tolist()}


def estimate_reference(scene, target, workers=None, scheduler=None, model=None, coverage=None):
    """Predicted samples and wall time of ``scene``'s reference to ``target``, without rendering it.

    ``workers``: cores the render will use (None: this machine's serial renderer, all cores);
    with ``scheduler`` the cores of that cluster are counted. Returns a dict with a one-line
    ``summary``.
    """
    from harness.reference import mitsuba_scene as ms
    from harness.reference.render import DEFAULT_K, FULL_COVERAGE, PILOT_K, PILOT_SPP

    model = model or load_model()
    if coverage is None:
        ms.use_variant(None)
        coverage = ms.coverage_mask(scene)
    covered = int((np.asarray(coverage) >= FULL_COVERAGE).sum())
    summ = medium_summary(scene)
    tau, alb = np.asarray(summ["tau"]), np.asarray(summ["albedo"])
    # Cost follows path length up to Russian roulette, which starts at a depth set by the LARGEST
    # albedo (mitsuba_scene.rr_depth_for); noise follows the mean.
    alb_max = np.asarray(summ["albedo_max"])
    split = ms.channel_passes(scene.medium) != (None,)
    t_px = predict(model["time"]["coef"], tau, alb_max)        # per channel, as if each were its own pass
    t_spp = covered * (float(t_px.sum()) if split else float(t_px.max()))
    if ms.absorber_is_black(scene) is None:
        t_spp *= 2.0                                           # + the absorber pass (upper bound: same cost)
    # A smooth dielectric (mneevolpath) is outside the fitted family of index-matched spheres: its manifold
    # walks cost more per sample (benchmarks/bench_mnee.py --part time), so this under-predicts it.
    v = float(np.median(predict(model["noise"]["coef"], tau, alb)))
    n_total = v / float(target) ** 2
    per_seed = max(1, math.ceil(n_total / DEFAULT_K))
    cores_model = int(model["machine"]["cores"])
    cores, where = _cores_at_hand(workers, scheduler)
    speed = max(cores, 1) / max(cores_model, 1)
    render_s = (PILOT_K * PILOT_SPP + DEFAULT_K * per_seed) * t_spp / speed
    overhead = float(model["overhead_s"]["serial"]) + (float(model["overhead_s"]["cluster_start"]) if workers else 0.0)
    seconds = render_s + overhead
    w, h = scene.camera.width, scene.camera.height
    from harness.progress import format_duration

    summary = (f"{scene.name} {w}x{h}: predicted {DEFAULT_K} seeds x {per_seed} spp ({DEFAULT_K * per_seed} in all) "
               f"to reach {float(target):.2%}, about {format_duration(seconds)} {where} (cost model "
               f"{MODEL_FILE.name}, measured on {cores_model} cores; not rendered)")
    return {"scene": scene.name, "size": [w, h], "target_rel_se": float(target), "covered_pixels": covered,
            "medium": summ, "channel_passes": 3 if split else 1, "seconds_per_spp": t_spp / speed,
            "relative_variance_per_sample": v, "predicted_spp_total": DEFAULT_K * per_seed,
            "predicted_spp_per_seed": per_seed, "predicted_seconds": seconds, "cores": cores, "on": where,
            "model": str(MODEL_FILE), "summary": summary}


def _cores_at_hand(workers, scheduler):
    if scheduler:
        from dask.distributed import Client

        from harness.reference.distributed import cluster_slots

        try:
            with Client(scheduler, timeout="10s") as client:
                n = cluster_slots(client)
        except (OSError, TimeoutError) as exc:
            raise InputError("--scheduler", "scheduler", f"cannot reach Dask scheduler {scheduler!r} ({exc})",
                             "start it with 'dask scheduler' or drop --scheduler for a local cluster") from exc
        return n, f"on the Dask cluster at {scheduler} ({n} worker threads)"
    if workers:
        cpu, w = os.cpu_count() or 1, int(workers)
        cores = min(cpu, w * max(1, cpu // w))     # workers x Dr.Jit threads each (harness.runs.references)
        return cores, f"on a LocalCluster of {w} worker{'s' if w > 1 else ''} ({cores} cores)"
    cores = os.cpu_count() or 1
    return cores, f"in this process ({cores} cores)"
