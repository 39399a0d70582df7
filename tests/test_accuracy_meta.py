"""Meta-tests of the accuracy tests: a deliberate error in the method must fail them, an
improvement must fail them too (with the accept command), and a change judged against
an independently re-seeded reference must get the same answer within its standard error.

``benchmarks/accuracy_sensitivity.py`` runs six deliberate errors over every case and the
unchanged renderer against 20 re-seeded references per scene; these are the cheap checks.
"""

import numpy as np
import pytest

from harness.regression.accuracy import cases, check_case, case_reference, small_scene
from harness.regression.baselines import BASELINE_DIR, committed_image, find_entry, read_baseline
from harness.regression.verdict import critical_value, image_change, judge_images
from harness.runs.params import config_label
from harness.runs.sweep import load_reference
from sslpv_gl.params import SSLPVParams

pytestmark = [pytest.mark.accuracy, pytest.mark.gl]
RESEEDED = BASELINE_DIR / "refs_reseeded"
TOL = dict(cases()[0][2])


@pytest.fixture()
def renderer(gl_renderer):
    return gl_renderer


def sabotage(renderer, monkeypatch, change):
    original = renderer.lpv_material

    def broken(scene, params):
        return change(dict(original(scene, params)))

    monkeypatch.setattr(renderer, "lpv_material", broken)


DOUBLE_ABSORPTION = lambda m: dict(m, sigma_lpv=m["sigma_lpv"] * 2)  # noqa: E731
NO_SCATTERING = lambda m: dict(m, sigma_s_prime=np.zeros_like(m["sigma_s_prime"]))  # noqa: E731


@pytest.mark.parametrize("scene,params,change,why", [
    ("absorbing_sphere", SSLPVParams(N=32, steps=32), DOUBLE_ABSORPTION, "doubled absorption"),
    ("two_lights", SSLPVParams(N=16, steps=8), NO_SCATTERING, "Eq. 3 scattering dropped"),
])
def test_deliberate_error_fails(renderer, monkeypatch, tmp_path, scene, params, change, why):
    clean = check_case(renderer, scene, params, TOL, artifacts=tmp_path)
    assert clean.verdict == "unchanged", clean.message()
    sabotage(renderer, monkeypatch, change)
    broken = check_case(renderer, scene, params, TOL, artifacts=tmp_path)
    assert broken.image.changed and broken.verdict in ("regression", "improvement"), \
        f"{why} went unnoticed:\n{broken.message()}"
    text = broken.message()
    print(text)
    for word in ("Delta", "SE", " z ", "threshold", "Bonferroni"):
        assert word in text
    # The failure leaves what a person needs: images, error map, and the accepting command.
    assert (broken.artifacts / "error_map.png").is_file()
    assert (broken.artifacts / "subsurface.exr").is_file() and (broken.artifacts / "store.sqlite").is_file()
    assert "sslpv-harness baselines update --scenes" in text


def speckled(img, seed=0):
    """``img`` times log-normal noise of mean 1 per pixel: worse in every error, same energy on average."""
    z = np.random.default_rng(seed).standard_normal(img.shape[:2] + (1,))
    return (img * np.exp(0.5 * z - 0.125)).astype(np.float32)


def test_an_improvement_fails_with_the_accept_command(renderer, tmp_path):
    """Against a committed image spoilt by strong per-pixel noise, today's render is an improvement."""
    scene, params = "thin_ring", SSLPVParams(N=16, steps=8)
    entry = find_entry(read_baseline(scene), [64, 64], params.as_dict())
    img, mask = committed_image(scene, entry)
    res = check_case(renderer, scene, params, TOL, artifacts=tmp_path, old=(speckled(img), mask))
    assert res.verdict == "improvement", res.message()
    assert "accept the improvement" in res.message() and "baselines update --scenes thin_ring" in res.message()


RESEEDED_SCENES = sorted(p.name for p in RESEEDED.iterdir()) if RESEEDED.is_dir() else []


def test_a_change_is_judged_alike_against_an_independent_reference(renderer, monkeypatch):
    """Doubled absorption at N = 16 on every re-seeded scene: against the committed reference
    and against an independently re-seeded one, Delta agrees within
    t * sqrt(SE_1^2 + SE_2^2) (Bonferroni over all comparisons) and the verdict is the same."""
    todo = [(s, p) for s, p, _ in cases() if s in RESEEDED_SCENES and p.N == 16]
    metrics = ("relmse", "si_relmse", "energy_ratio")
    t = critical_value(len(todo) * len(metrics))
    clean = {}
    for s, p in todo:
        clean[(s, config_label(p))] = renderer.render(small_scene(s), p)
    sabotage(renderer, monkeypatch, DOUBLE_ABSORPTION)
    worst = 0.0
    for s, p in todo:
        scene = small_scene(s)
        old = clean[(s, config_label(p))]
        new = renderer.render(scene, p)
        assert image_change(new.subsurface, old.subsurface, new.mask, old.mask).changed
        verdicts = []
        refs = [case_reference(scene), load_reference(RESEEDED / s, (64, 64))]
        both = [judge_images(s, config_label(p), "subsurface", new.subsurface, old.subsurface, r["subsurface"],
                             r["se"], r["mask"], TOL, len(todo) * len(metrics), k=r["K"], metrics=metrics)
                for r in refs]
        for a, b in zip(*both):
            z = (a.delta - b.delta) / np.hypot(a.se, b.se)
            worst = max(worst, abs(z))
            assert abs(z) <= t, f"{s} {config_label(p)} {a.metric}: Delta {a.delta:.4g} +- {a.se:.3g} against " \
                                f"the committed reference, {b.delta:.4g} +- {b.se:.3g} against the re-seeded one"
            verdicts.append((a.verdict, b.verdict))
        assert all(v[0] == v[1] or "changed-within-noise" in v for v in verdicts), verdicts
    print(f"largest |Delta_1 - Delta_2| / sqrt(SE_1^2 + SE_2^2) over {len(todo) * len(metrics)}: {worst:.2f} "
          f"(t = {t:.2f})")


def test_reseeded_references_exist():
    """The meta-test above must run on at least two scenes, not silently on none."""
    assert len(RESEEDED_SCENES) >= 2


def test_matrix_also_tables_add_cases_once():
    """[[also]] tables add further products to the accuracy matrix; a case already there is not repeated."""
    m = {"scenes": ["thin_ring"], "params": {"grid": [16], "steps": [8], "mapping": ["collision"]},
         "also": [{"grid": [16, 32], "steps": [8], "mapping": ["collision", "diffusion"], "skip": [2]}]}
    got = [(p.N, p.mapping, p.skip) for _, p, _ in cases(m)]
    assert got == [(16, "collision", 2), (16, "diffusion", 2), (32, "collision", 2), (32, "diffusion", 2)]
