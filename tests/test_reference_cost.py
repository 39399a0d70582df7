"""The reference cost model (harness/reference/cost.py): its fits recover what they are given, its
prediction adds up its parts, and the committed validation table comes from the committed data."""

import importlib.util
import json
import math
from pathlib import Path

import numpy as np
import pytest

from harness.reference import cost

ROOT = Path(__file__).resolve().parents[1]


def _bench():
    spec = importlib.util.spec_from_file_location("bench_reference_cost", ROOT / "benchmarks" /
                                                  "bench_reference_cost.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _rows(rng, n):
    """Synthetic scenes spanning every feature, half of them mneevolpath, a quarter family points."""
    rows = []
    for i in range(n):
        tau = rng.uniform(1, 300, 3)
        amax = rng.uniform(0.5, 0.999, 3)
        summ = {"tau": tau.tolist(), "tau_majorant": (tau * rng.uniform(1, 1.5)).tolist(),
                "albedo": (amax * 0.98).tolist(), "albedo_max": amax.tolist(), "g": rng.uniform(0, 0.9),
                "cv": rng.uniform(0, 0.4) * (i % 3 == 0)}
        split = i % 4 == 1
        rows.append(cost.scene_row(summ, covered=int(rng.integers(100, 4000)), passes=3 if split else 1,
                                   absorber=i % 5 == 2, integrator="mneevolpath" if i % 2 else "volpath",
                                   rr_depth=rng.integers(5, 2000, 3 if split else 1).tolist(),
                                   dielectric=i % 2 == 1, family=i % 4 == 3))
    return rows


TIME_TRUE = np.array([-13.0, 0.7, 0.45, 1.3, 1.6])
NOISE_TRUE = np.array([0.1, -0.05, 0.15, 1.5, -1.0, 1.2, 2.5, -0.4])


def test_time_fit_recovers_per_job_cost_and_coefficients():
    rng = np.random.default_rng(5)
    points = []
    for row in _rows(rng, 40):
        jobs = int(rng.integers(4, 60)) * row["passes"]
        samples = float(rng.uniform(64, 20000)) * row["covered"] * row["passes"]
        seconds = 0.05 * jobs + 0.3 * row["passes"] + samples * cost.t_pass(TIME_TRUE, row)
        points.append(dict(row, seconds=seconds, jobs=jobs, renders=row["passes"], samples=samples))
    c_job, c_render, coef, rms = cost.fit_time(points, c_job_grid=(0.0, 0.01, 0.05, 0.2),
                                               c_render_grid=(0.0, 0.3, 1.0))
    assert (c_job, c_render) == (0.05, 0.3)
    np.testing.assert_allclose(coef, TIME_TRUE, atol=1e-6)
    assert rms < 1e-6


def test_noise_fit_recovers_coefficients():
    rng = np.random.default_rng(6)
    points = [dict(row, v=cost.v_sample(NOISE_TRUE, row)) for row in _rows(rng, 40)]
    coef, rms = cost.fit_noise(points)
    np.testing.assert_allclose(coef, NOISE_TRUE, atol=1e-6)
    assert rms < 1e-6


def test_huber_fit_shrugs_off_one_outlier():
    rng = np.random.default_rng(7)
    X = np.column_stack([np.ones(30), rng.normal(size=30)])
    q = np.exp(X @ np.array([1.0, 0.5]))
    q[3] *= 50.0                                   # one scene rendered under some unknown condition
    robust, _ = cost.lstsq_log(X, q)
    plain, _ = cost.lstsq_log(X, q, huber=None)
    assert np.abs(robust - [1.0, 0.5]).max() < 0.02 < np.abs(plain - [1.0, 0.5]).max()


def test_prediction_adds_up_its_parts():
    """samples x pixels x passes x t_px, plus c_job per job and c_render per pass's kernel, by hand."""
    rng = np.random.default_rng(8)
    row = _rows(rng, 2)[1]                        # mneevolpath, one pass
    model = {"time": {"coef": TIME_TRUE.tolist(), "c_job": 0.5, "c_render": 2.0},
             "noise": {"coef": NOISE_TRUE.tolist()}}
    spp, spp_s, final, render_s = cost.predict_run(model, row, 0.03, K=8, rounds=3, speed=2.0)
    per_seed = math.ceil(cost.v_sample(NOISE_TRUE, row) / 0.03 ** 2 / 8)
    t = cost.t_pass(TIME_TRUE, row)
    assert spp == 8 * per_seed
    assert spp_s == pytest.approx(row["covered"] * row["passes"] * t / 2.0, rel=1e-12)
    assert final == pytest.approx(spp * spp_s + 0.5 / 2.0 * 8 * 3 * row["passes"], rel=1e-12)
    assert render_s == pytest.approx(final + 64 * spp_s + 0.5 / 2.0 * 4 * 2 * row["passes"] + 2.0 / 2.0 * row["passes"],
                                     rel=1e-12)


def test_committed_model_prices_the_dielectric_integrator_and_roulette():
    """The committed fit: mneevolpath costs more per sample than volpath in the same scene (measured 25-40x
    on skin_torus and its dielectric twin), and a longer Russian roulette costs more."""
    model = cost.load_model()
    base = cost.scene_row({"tau": [5.0] * 3, "albedo": [0.9] * 3, "albedo_max": [0.999] * 3}, covered=1000,
                          passes=1, absorber=False, integrator="volpath", rr_depth=[5], dielectric=False)
    mnee = dict(base, mnee=1)
    long_rr = dict(base, rr_depth_pass=[230.0])
    t = model["time"]["coef"]
    assert cost.t_pass(t, mnee) > 5 * cost.t_pass(t, base)
    assert cost.t_pass(t, long_rr) > 1.5 * cost.t_pass(t, base)
    assert model["time"]["c_job"] > 0


def test_estimate_keys_and_final_seconds(monkeypatch):
    """estimate_reference keeps its keys; predicted_spp_total x seconds_per_spp is the final render's
    sample cost, predicted_final_seconds adds the per-job cost (render.py's pilot compares with it)."""
    from harness.scene import load_scene

    scene = load_scene("two_lights").with_resolution(32, 32)
    cov = np.ones((32, 32))
    est = cost.estimate_reference(scene, 0.05, coverage=cov)
    for key in ("predicted_spp_total", "seconds_per_spp", "predicted_seconds", "predicted_final_seconds",
                "predicted_spp_per_seed", "summary", "covered_pixels", "channel_passes"):
        assert key in est
    model = cost.load_model()
    jobs_cost = model["time"]["c_job"] / (est["cores"] / model["machine"]["cores"]) * 8 * 2 * est["passes"]
    assert est["predicted_final_seconds"] == pytest.approx(
        est["predicted_spp_total"] * est["seconds_per_spp"] + jobs_cost, rel=1e-9)
    assert est["predicted_seconds"] > est["predicted_final_seconds"]
    assert "not rendered" in est["summary"]


def test_a_sampling_cap_beyond_the_measured_references_is_called_a_floor():
    """outside_the_fit reads each measured reference's cap, one block or one per channel; a scene that samples
    beyond the largest is named, and the estimate's one line says so; none of cost_suite.json's references
    sampled, so the scanned bunny (cap 4096) is outside it, and a scene without a dielectric says nothing."""
    import dataclasses

    from harness.scene import load_scene

    per_channel = {"refs": {"a": {"integrator": {c: {"type": "mneevolpath", "sms_trials": 256} for c in "RGB"}},
                            "b": {"integrator": {"type": "volpath"}}}}
    bunny = load_scene("bunny_dielectric")
    at = lambda n: dataclasses.replace(bunny, boundary=dataclasses.replace(bunny.boundary, sms_trials=n))  # noqa: E731
    assert cost.outside_the_fit(at(256), per_channel) == []
    assert cost.outside_the_fit(at(0), per_channel) == []
    assert cost.outside_the_fit(at(257), per_channel) == [
        "sms_trials 257 above the measured references' largest (256): the estimate is a floor"]
    assert "(0): the estimate is a floor" in cost.outside_the_fit(bunny)[0]
    small = bunny.with_resolution(16, 16)
    est = cost.estimate_reference(small, 0.04, coverage=np.ones((16, 16)))
    assert est["outside_the_fit"] and est["summary"].endswith("the estimate is a floor")
    plain = load_scene("two_lights").with_resolution(16, 16)
    assert cost.estimate_reference(plain, 0.05, coverage=np.ones((16, 16)))["outside_the_fit"] == []


def test_loo_row_is_recomputed_from_the_committed_references():
    """One row of docs/reference_cost.md and cost_model.json's LOO table, recomputed from the measured
    references (harness/reference/cost_suite.json, else baselines/refs) and the family points: the figures
    are the committed data's, not typed in."""
    bench = _bench()
    model = cost.load_model()
    cores = int(model["machine"]["cores"])
    fitted = {r["scene"] for r in model["loo"]["rows"]}          # the scenes the committed model was fitted on
    entries = [e for e in bench.load_refs(cores) if e["scene"] in fitted]
    assert {e["scene"] for e in entries} == fitted
    family = bench.family_entries(model["family_points"])
    i = [e["scene"] for e in entries].index("two_lights")
    meta = bench.measured_metas()[0].get("two_lights") or json.loads(
        (ROOT / "baselines" / "refs" / "two_lights" / "reference.json").read_text())
    loo = bench.fit_all(entries[:i] + entries[i + 1:], family)
    spp, seconds = bench.predict_entry(loo, entries[i], cores)
    row = next(r for r in model["loo"]["rows"] if r["scene"] == "two_lights")
    assert row["spp_measured"] == meta["spp_total"] and row["seconds_measured"] == meta["wall_seconds"]
    assert row["spp_loo"] == spp and row["seconds_loo"] == pytest.approx(seconds, rel=1e-9)
    doc = (ROOT / "docs" / "reference_cost.md").read_text()
    assert (f"| two_lights | {meta['target_rel_se']:.1%} | {meta['spp_total']} | {spp} | "
            f"{bench.factor(spp, meta['spp_total']):+.1f} | {meta['wall_seconds']:.1f} | {seconds:.1f} |") in doc


def test_tail_factor_is_one_where_the_noise_falls_as_one_over_root_n():
    """A second route: seeds of normal samples (finite variance) rendered at 4 and 16 samples per seed, over
    2000 pixels, give the median relative SE's fall that tail_factor expects (2), hence no correction; heavy
    tails (a Pareto with infinite variance) fall less and are corrected; a stated fall outside [1, 2] clips."""
    from harness.reference.noise import median_rel_se, seed_stats

    rng = np.random.default_rng(3)

    def fall(draw):
        s = draw((4, 16, 2000, 1, 1))                       # 4 seeds x 16 samples x 2000 pixels
        r4 = median_rel_se(*seed_stats(s[:, :4].mean(1)), np.ones((2000, 1, 1), bool))
        r16 = median_rel_se(*seed_stats(s.mean(1)), np.ones((2000, 1, 1), bool))
        return r4, r16

    r4, r16 = fall(lambda shape: rng.normal(1.0, 0.5, shape))
    assert r4 / r16 == pytest.approx(2.0, rel=0.05)
    assert cost.tail_factor(r4, r16, 2.42, 4.0) < 1.15
    r4, r16 = fall(lambda shape: rng.pareto(1.5, shape))
    assert r4 / r16 < 1.8 and cost.tail_factor(r4, r16, 2.42, 4.0) > 1.3
    assert cost.tail_factor(1.0, 1.0, 2.42, 4.0) == pytest.approx(2.0 ** 2.42)
    assert cost.tail_factor(3.0, 1.0, 2.42, 4.0) == 1.0 and cost.tail_factor(1.0, 1.0, 10.0, 4.0) == 8.0
    assert cost.tail_factor(float("nan"), 1.0, 2.42) == 1.0 and cost.tail_factor(2.0, 1.0, 0.0) == 1.0


def test_tail_exponent_is_the_fit_of_the_measured_references():
    """cost_model.json's exponent and its leave-one-out rows are recomputed from cost_suite.json."""
    bench = _bench()
    k, loo = bench.fit_tail(bench.measured_metas()[0])
    model = cost.load_model()
    assert model["pilot_tail"]["exponent"] == pytest.approx(k, rel=1e-12)
    assert [r[0] for r in model["pilot_tail"]["loo"]] == [r[0] for r in loo]
    assert np.allclose([r[3] for r in model["pilot_tail"]["loo"]], [r[3] for r in loo], rtol=1e-12)
