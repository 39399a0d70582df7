"""A cost model of the ground truth: what a reference costs, structured by what costs time.

The reference renderer (:mod:`harness.reference.render`) runs a pilot (4 seeds x 16 spp, in two rounds),
then rounds of ``K = 8`` seeds until the median relative standard error meets the target.
Each seed of each colour pass is one job (one ``mi.render`` call). So its time on the
model's machine is

    seconds = c_job x jobs + samples x covered pixels x passes x t_px(scene)

(``samples``: per pixel, pilot and final render together; ``passes``: one RGB pass, or one
grey pass per colour channel when sigma_t differs between channels, times two with an
absorber pass) and the samples it needs are ``v / target^2`` for ``v`` the relative
variance of one sample (SE ~ 1/sqrt(N)). Both parts are fitted by least squares on
logarithms:

    log t_px = b0 + b1 log tau + b2 log L + b3 [mneevolpath] + b4 [32x32 family]
    log v    = a0 + a1 log tau + a2 log(1/(1 - albedo)) + a3 log(1/(1 - |g|)) + a4 cv + a5 [dielectric] + a6 [family]

* ``tau``: optical size, sigma_t times the mesh's mean chord ``4 V / S`` (Cauchy's formula for
  convex bodies); in the time model the majorant's (the grid's largest sigma_t, largest channel
  for an RGB pass), with which delta tracking steps; in the noise model the mean's (median channel);
* ``L = min(1 / (1 - albedo_max), rr_depth + 20)``: the scattering events a path can make,
  set by absorption (mean ``albedo / (1 - albedo)`` events) or by Russian roulette, which
  Mitsuba starts at ``rr_depth`` and caps at survival 0.95 (about 20 more events);
* ``g`` the largest |g| inside (Henyey-Greenstein; a forward-peaked phase function makes next-event
  estimation noisy: on the family, v grows as a power of ``1 / (1 - g)``), ``cv`` the largest channel's coefficient
  of variation of sigma_t inside the mesh (heterogeneity), ``[dielectric]`` a refractive
  boundary, ``[mneevolpath]`` the smooth-dielectric integrator (manifold walks per
  sample, :mod:`harness.reference.mnee`);
* ``[family]`` an offset for the 32x32 homogeneous spheres of ``cost_model.json``'s
  ``family`` points: those inform the slopes in tau, albedo, roulette and g, while the
  level is that of the committed 64x64 references (``baselines/refs``).

``c_job`` (seconds per job: kernel launch, image readback, scheduling) is chosen on a grid
by the least squared log error of the total seconds. Fitting and leave-one-scene-out
validation: ``benchmarks/bench_reference_cost.py --fit``, which writes ``cost_model.json``
and ``docs/reference_cost.md``.

Limits (``docs/reference_cost.md`` has the leave-one-scene-out errors):

* 14 scenes and a small family: a suite scene with a feature no other has (the rough
  dielectric's absorber pass, the high-albedo optically thick marble) is predicted from the
  others' slopes only, and misses;
* most committed references were rendered before today's integrator choices (roulette from
  depth 5 at any albedo, one RGB pass on chromatic sigma_t): the model is fitted to and
  validated on how each reference WAS rendered (recorded in its ``reference.json``), and
  ``--estimate`` extrapolates to today's passes and roulette depth through the same features;
* two references (apple_sphere, wide_slab) cost 10 to 20 times more per sample than their
  features say, for reasons the references do not record (their single RGB pass on chromatic
  sigma_t? the machine's load?); the Huber fit keeps them from pulling the others;
* no measured reference used specular manifold sampling (``sms_trials``; every one of
  ``cost_suite.json``'s was rendered without it): the walks per connection grow with the cap
  and with the chains, so for a scene that samples the estimate is a floor, and it says so
  (:func:`outside_the_fit`); the pilot measures the cost;
* the light's placement is unknown to it; the recorded times come from a 2-core machine
  shared with other work (load averages of 2 to 19, not recorded per reference), which makes
  the seconds, not the samples, noisy by a factor of 2 or more;
* the 32x32 family's seconds per sample are several times the 64x64 references' (a per-point
  cost the model does not resolve), hence its own offset: the family sets slopes, not levels.
"""

import json
import math
import os
from pathlib import Path

import numpy as np

from harness.errors import InputError

from .jobs import DEFAULT_K, PILOT_EARLY_SPP, PILOT_K, PILOT_SPP

MODEL_FILE = Path(__file__).with_name("cost_model.json")
RR_TAIL = 20.0            # mean extra events under Mitsuba's roulette, survival capped at 0.95: 1 / (1 - 0.95)
PILOT_ROUNDS = 2          # the pilot's rounds (PILOT_EARLY_SPP, then the rest of PILOT_SPP), one job per seed each
TIME_TERMS = ("1", "log tau", "log L", "mneevolpath", "family")
NOISE_TERMS = ("1", "log tau", "log 1/(1-albedo)", "log 1/(1-|g|)", "cv", "smooth dielectric", "absorber pass",
               "family")
HUBER = 0.5               # log units (x1.65): residuals beyond it weigh less (Huber, by iterative reweighting)
C_JOB_GRID = tuple(np.concatenate([[0.0], np.geomspace(1e-3, 1.0, 19)]))
C_RENDER_GRID = tuple(np.concatenate([[0.0], np.geomspace(0.03, 10.0, 21)]))


# --------------------------------------------------------------------------- features

def events(albedo_max, rr_depth):
    """``L``: scattering events a path can make before absorption or Russian roulette ends it."""
    a = np.minimum(np.asarray(albedo_max, np.float64), 1.0 - 1e-9)
    return np.minimum(1.0 / (1.0 - a), np.asarray(rr_depth, np.float64) + RR_TAIL)


def time_features(tau, albedo_max, rr_depth, mnee, family):
    """Regressors of ``log t_px`` (:data:`TIME_TERMS`), arrays broadcast."""
    x = np.log(np.maximum(np.asarray(tau, np.float64), 1e-6))
    cols = np.broadcast_arrays(np.ones_like(x), x, np.log(events(albedo_max, rr_depth)),
                               np.asarray(mnee, np.float64), np.asarray(family, np.float64))
    return np.stack(cols, axis=-1)


def noise_features(tau, albedo, g, cv, smooth, absorber, family):
    """Regressors of ``log v`` (:data:`NOISE_TERMS`), arrays broadcast."""
    x = np.log(np.maximum(np.asarray(tau, np.float64), 1e-6))
    a = np.minimum(np.asarray(albedo, np.float64), 1.0 - 1e-6)
    h = np.log(1.0 / (1.0 - np.minimum(np.abs(np.asarray(g, np.float64)), 0.999)))
    cols = np.broadcast_arrays(np.ones_like(x), x, np.log(1.0 / (1.0 - a)), h,
                               np.asarray(cv, np.float64), np.asarray(smooth, np.float64),
                               np.asarray(absorber, np.float64), np.asarray(family, np.float64))
    return np.stack(cols, axis=-1)


def mean_chord(mesh):
    """``4 V / S`` of a closed mesh (Cauchy: the mean chord of a convex body under uniform random lines)."""
    tri = np.asarray(mesh.triangles(), dtype=np.float64)
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1).sum()
    volume = abs(np.einsum("ij,ij->i", tri[:, 0], cross).sum()) / 6.0
    return 4.0 * volume / area


def medium_summary(scene):
    """Per channel over the voxels inside the mesh: mean sigma_t, mean and largest albedo, optical size
    (and ``tau_majorant``: the grid's largest sigma_t, with which delta tracking steps, times the chord);
    the mean chord, ``g``: the largest |g| over the voxels (Mitsuba's RGB variants use the mean of the
    channels' g), and the heterogeneity ``cv`` (largest channel's std/mean of sigma_t)."""
    from harness.scene.geometry import grid_inside

    m = scene.medium
    inside = grid_inside(scene.mesh, m.bbox_min, m.bbox_max, m.resolution)
    if not inside.any():
        inside = np.ones(inside.shape, dtype=bool)
    st_all = np.asarray(m.sigma_t, np.float64)[inside]
    st = st_all.mean(axis=0)
    al = np.asarray(m.albedo, np.float64)[inside]
    chord = mean_chord(scene.mesh)
    cv = float(np.max(st_all.std(axis=0) / np.maximum(st, 1e-12)))
    majorant = np.asarray(m.sigma_t, np.float64).reshape(-1, 3).max(axis=0)
    return {"sigma_t": st.tolist(), "albedo": al.mean(axis=0).tolist(), "albedo_max": al.max(axis=0).tolist(),
            "mean_chord": chord, "tau": (st * chord).tolist(), "tau_majorant": (majorant * chord).tolist(),
            "g": float(np.abs(np.asarray(m.g, np.float64)[inside].mean(axis=-1)).max()),
            "cv": cv}


def scene_row(summ, *, covered, passes, absorber, integrator, rr_depth, dielectric, family=False):
    """One scene's model inputs: the medium summary and how it is (or was) rendered.

    ``passes``: 1 (an RGB pass) or 3 (grey passes per channel); ``rr_depth`` one per pass;
    ``absorber``: an albedo-0 pass doubles the passes (an upper bound on its cost).
    """
    tau, amax, alb = (np.asarray(summ[k], np.float64) for k in ("tau", "albedo_max", "albedo"))
    tau_maj = np.asarray(summ.get("tau_majorant", tau), np.float64)
    rr = np.broadcast_to(np.asarray(rr_depth, np.float64), (passes,))
    if passes == 3:      # each grey pass tracks its own channel
        t_tau, t_amax = tau_maj, amax
    else:                # one RGB pass steps with the largest sigma_t and continues while any channel lives
        t_tau, t_amax = tau_maj.max(keepdims=True), amax.max(keepdims=True)
    return {"tau_pass": t_tau.tolist(), "albedo_max_pass": t_amax.tolist(), "rr_depth_pass": rr.tolist(),
            "passes": int(passes) * (2 if absorber else 1), "mnee": int(integrator == "mneevolpath"),
            "tau": float(np.median(tau)), "albedo": float(np.median(alb)), "g": float(summ.get("g", 0.0)),
            "cv": float(summ.get("cv", 0.0)), "dielectric": int(bool(dielectric)), "absorber": int(bool(absorber)),
            "family": int(family),
            "covered": int(covered)}


def t_pass(coef, row):
    """Seconds per sample per covered pixel of one pass (geometric mean over the scene's colour passes,
    which keeps ``log t_px`` linear in the passes' mean features, as :func:`fit_time` fits it)."""
    return float(np.exp(_time_X([row])[0] @ np.asarray(coef, np.float64)))


def v_sample(coef, row):
    """Relative variance of one sample (median over lit pixel-channels)."""
    X = noise_features(row["tau"], row["albedo"], row["g"], row["cv"], row["mnee"], row["absorber"], row["family"])
    return float(np.exp(X @ np.asarray(coef, np.float64)))


# --------------------------------------------------------------------------- fitting

def lstsq_log(X, q, weights=None, huber=HUBER, iterations=30):
    """Coefficients of ``log q`` on ``X`` (optionally weighted) by Huber regression (iteratively reweighted
    least squares; ``huber=None``: plain least squares), and the RMS residual. A regressor that is zero on
    every point gets coefficient 0 (the minimum-norm solution)."""
    y = np.log(np.asarray(q, np.float64))
    w0 = np.ones(len(y)) if weights is None else np.asarray(weights, np.float64)
    w = w0
    for _ in range(iterations if huber else 1):
        sw = np.sqrt(w)
        coef, *_ = np.linalg.lstsq(X * sw[:, None], y * sw, rcond=None)
        r = np.abs(y - X @ coef)
        w = w0 * np.minimum(1.0, huber / np.maximum(r, 1e-12)) if huber else w0
    return coef, float(np.sqrt(np.mean((y - X @ coef) ** 2)))


def _time_X(points):
    # A point's regressors: the mean over its passes' features, so log t_px stays linear in them.
    return np.stack([time_features(p["tau_pass"], p["albedo_max_pass"], p["rr_depth_pass"], p["mnee"],
                                   p["family"]).mean(axis=0) for p in points])


def fit_time(points, c_job_grid=C_JOB_GRID, c_render_grid=C_RENDER_GRID):
    """Fit ``c_job`` and the ``t_px`` coefficients to ``points`` (dicts with a :func:`scene_row`'s keys
    and ``seconds``, ``jobs``, ``samples`` = samples per pixel x covered pixels x passes); scenes weigh
    equally (``weight``). ``c_job`` minimises the Huber loss of the log error of the seconds. Returns
    ``(c_job, coef, rms)``, ``rms`` the weighted RMS log error of the seconds."""
    X = _time_X(points)
    s = np.array([p["seconds"] for p in points], np.float64)
    jobs = np.array([p["jobs"] for p in points], np.float64)
    renders = np.array([p["renders"] for p in points], np.float64)
    n = np.array([p["samples"] for p in points], np.float64)
    w = np.array([p.get("weight", 1.0) for p in points], np.float64)
    best = None
    for c in c_job_grid:
        for c_r in c_render_grid:
            rest = s - c * jobs - c_r * renders
            if np.any(rest <= 0.02 * s):
                continue
            coef, _ = lstsq_log(X, rest / n, w)
            pred = c * jobs + c_r * renders + n * np.exp(X @ coef)
            r = np.abs(np.log(pred / s))
            loss = float(np.sum(w * np.where(r < HUBER, 0.5 * r * r, HUBER * (r - 0.5 * HUBER))))
            if best is None or loss < best[4]:
                best = (float(c), float(c_r), coef, float(np.sqrt(np.sum(w * r * r) / w.sum())), loss)
    return best[:4]


def fit_noise(points):
    """Fit the ``v`` coefficients to ``points`` (a :func:`scene_row`'s keys and ``v``); ``(coef, rms)``."""
    X = noise_features(*(np.array([p[k] for p in points], np.float64)
                         for k in ("tau", "albedo", "g", "cv", "mnee", "absorber", "family")))
    w = np.array([p.get("weight", 1.0) for p in points], np.float64)
    return lstsq_log(X, [p["v"] for p in points], w)


def predict_run(model, row, target, K=8, rounds=2, speed=1.0):
    """Samples and seconds of a reference of ``row`` to ``target``: ``(spp_total, seconds_per_spp,
    final_seconds, render_seconds)`` on the model's cores times ``speed``."""
    v = v_sample(model["noise"]["coef"], row)
    per_seed = max(1, math.ceil(v / float(target) ** 2 / K))
    spp_s = row["covered"] * row["passes"] * t_pass(model["time"]["coef"], row) / speed
    c_job, c_render = float(model["time"]["c_job"]) / speed, float(model["time"]["c_render"]) / speed
    final = K * per_seed * spp_s + c_job * K * rounds * row["passes"]
    pilot = (PILOT_K * PILOT_SPP * spp_s + c_job * PILOT_K * PILOT_ROUNDS * row["passes"]
             + c_render * row["passes"])
    return K * per_seed, spp_s, final, final + pilot


def tail_factor(r_early, r_pilot, exponent, spp_ratio=PILOT_SPP / PILOT_EARLY_SPP):
    """How much more than ``N ~ 1/SE^2`` a heavy-tailed scene needs, from its pilot's two rounds.

    Between the pilot's first round (4 samples per seed) and the whole pilot (``spp_ratio`` times
    as many) the median relative SE falls by ``sqrt(spp_ratio)`` (2) where the samples' variance
    is finite and the seeds' SEs are already near their value. Heavy tails (a forward-peaked phase
    function, a rough dielectric) make few-sample SEs optimistic and the fall smaller: measured
    1.4 to 1.5 where the final render needed 2.25 times the pilot's samples, 1.94 to 2.04 where it
    needed none more (``harness/reference/cost_suite.json``). The factor is
    ``(sqrt(spp_ratio) / fall) ^ exponent``, at least 1 and at most 8, with ``exponent`` fitted on
    the suite (``benchmarks/bench_reference_cost.py --fit``, leave-one-scene-out in
    ``docs/reference_cost.md``). Limits: two points of a noise curve; a scene whose tail shows only
    beyond 16 samples per seed is not detected.
    """
    if not (np.isfinite(r_early) and np.isfinite(r_pilot) and r_early > 0 and r_pilot > 0) or exponent <= 0:
        return 1.0
    return float(np.clip((math.sqrt(spp_ratio) * r_pilot / r_early) ** exponent, 1.0, 8.0))


SUITE_FILE = Path(__file__).with_name("cost_suite.json")


def _sms_trials(integrator):
    """The largest ``sms_trials`` of a reference's integrator notes (one block, or one per channel)."""
    from harness.reference.mitsuba_scene import integrator_blocks

    return max(int(b.get("sms_trials", 0) or 0) for b in integrator_blocks(integrator))


def outside_the_fit(scene, suite=None):
    """What in ``scene``'s render lies outside the measured references the model was fitted on: a list of
    short phrases, empty where nothing does (today: a cap on specular manifold sampling above the largest
    measured; see the module's limits)."""
    suite = suite if suite is not None else json.loads(SUITE_FILE.read_text())
    fitted = max((_sms_trials(r.get("integrator", {})) for r in suite.get("refs", {}).values()), default=0)
    trials = int(getattr(scene.boundary, "sms_trials", 0) or 0)
    out = []
    if trials > fitted:
        out.append(f"sms_trials {trials} above the measured references' largest ({fitted}): the estimate is a floor")
    return out


def load_model(path=None):
    path = Path(path or MODEL_FILE)
    if not path.is_file():
        raise InputError(path, "file", "the reference cost model is missing",
                         "run .venv/bin/python benchmarks/bench_reference_cost.py --fit")
    return json.loads(path.read_text())


# --------------------------------------------------------------------------- the estimate

def estimate_reference(scene, target, workers=None, scheduler=None, model=None, coverage=None):
    """Predicted samples and wall time of ``scene``'s reference to ``target``, without rendering it.

    ``workers``: cores the render will use (None: this machine's serial renderer, all cores);
    with ``scheduler`` the cores of that cluster are counted. Returns a dict with a one-line
    ``summary``; ``predicted_spp_total x seconds_per_spp`` is the final render's sample cost,
    ``predicted_final_seconds`` adds its per-job cost, ``predicted_seconds`` the pilot and overhead.
    """
    from harness.reference import mitsuba_scene as ms

    model = model or load_model()
    if coverage is None:
        ms.use_variant(None)
        coverage = ms.coverage_mask(scene)
    from harness.metrics.coverage import FULL_COVERAGE

    covered = int((np.asarray(coverage) >= FULL_COVERAGE).sum())
    summ = medium_summary(scene)
    split = ms.channel_passes(scene.medium) != (None,)
    amax = np.asarray(summ["albedo_max"])
    rr = [ms.rr_depth_for(a) for a in amax] if split else [ms.rr_depth_for(amax.max())]
    integ = "mneevolpath" if ms.smooth_dielectric(scene.boundary) else "volpath"
    row = scene_row(summ, covered=covered, passes=3 if split else 1, absorber=ms.absorber_is_black(scene) is None,
                    integrator=integ, rr_depth=rr, dielectric=not scene.boundary.index_matched)
    cores_model = int(model["machine"]["cores"])
    cores, where = _cores_at_hand(workers, scheduler)
    speed = max(cores, 1) / max(cores_model, 1)
    spp_total, spp_s, final, render_s = predict_run(model, row, target, K=DEFAULT_K, speed=speed)
    overhead = float(model["overhead_s"]["serial"]) + (float(model["overhead_s"]["cluster_start"]) if workers else 0.0)
    seconds = render_s + overhead
    w, h = scene.camera.width, scene.camera.height
    from harness.progress import format_duration

    per_seed = spp_total // DEFAULT_K
    summary = (f"{scene.name} {w}x{h}: predicted {DEFAULT_K} seeds x {per_seed} spp ({spp_total} in all) "
               f"to reach {float(target):.2%}, about {format_duration(seconds)} {where} (cost model "
               f"{MODEL_FILE.name}, measured on {cores_model} cores, leave-one-scene-out error up to "
               f"x{model.get('loo', {}).get('worst_factor', float('nan')):.1f} on the suite; not rendered)")
    outside = outside_the_fit(scene) if ms.smooth_dielectric(scene.boundary) else []
    if outside:
        summary += "; outside the model's measurements: " + "; ".join(outside)
    return {"scene": scene.name, "size": [w, h], "target_rel_se": float(target), "covered_pixels": covered,
            "medium": summ, "channel_passes": 3 if split else 1, "passes": row["passes"], "integrator": integ,
            "rr_depth": rr, "seconds_per_spp": spp_s, "relative_variance_per_sample": v_sample(
                model["noise"]["coef"], row), "predicted_spp_total": spp_total, "predicted_spp_per_seed": per_seed,
            "predicted_final_seconds": final, "predicted_seconds": seconds, "cores": cores, "on": where,
            "model": str(MODEL_FILE), "outside_the_fit": outside, "summary": summary}


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
