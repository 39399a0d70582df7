"""Paired metric differences and their standard errors (``harness.metrics.uncertainty``).

The gradients of the delta method against central finite differences; the standard
errors against the spread of the difference over many independently noisy references
of a known truth (K = 8 seeds per reference, channels correlated as in Mitsuba's RGB
variants).
"""

import numpy as np
import pytest

from harness.metrics import compute
from harness.metrics.uncertainty import GRADIENTS, badness, delta_method_se, paired_difference


def _images(rng, shape=(12, 12)):
    truth = rng.uniform(0.05, 1.0, shape + (3,))
    # per-pixel distortions, nearly the same in the three channels (as a change of SSLPV is)
    old = truth * rng.uniform(0.7, 1.3, shape + (1,)) * rng.uniform(0.97, 1.03, shape + (3,))
    new = truth * rng.uniform(0.8, 1.5, shape + (1,)) * rng.uniform(0.97, 1.03, shape + (3,))
    mask = rng.uniform(size=shape) < 0.8
    return truth, old, new, mask


@pytest.mark.parametrize("name", sorted(GRADIENTS))
def test_gradient_matches_finite_differences(name):
    rng = np.random.default_rng(3)
    y, x, _, m = _images(rng, (6, 6))
    g = GRADIENTS[name](x, y, m)
    h = 1e-6
    for p in [(0, 0, 0), (2, 3, 1), (5, 5, 2), (4, 1, 0)]:
        yp, ym = y.copy(), y.copy()
        yp[p] += h
        ym[p] -= h
        fd = (compute(name, x, yp, m).value - compute(name, x, ym, m).value) / (2 * h)
        assert g[p] == pytest.approx(fd, rel=1e-5, abs=1e-9), f"{name} at {p}: {g[p]} vs {fd}"
    assert np.all(g[~m] == 0.0)


def _noisy_reference(rng, truth, sigma, rho, k=8):
    """Mean and SE of ``k`` seeds whose channel noise has correlation ``rho``."""
    shared = rng.standard_normal((k,) + truth.shape[:2] + (1,))
    z = np.sqrt(rho) * shared + np.sqrt(1 - rho) * rng.standard_normal((k,) + truth.shape)
    seeds = truth + sigma * z
    return seeds.mean(0), seeds.std(0, ddof=1) / np.sqrt(k)


def _over_references(seed, name, rho, n, **kw):
    """``(Delta, result)`` of ``name`` for one pair of test images against ``n`` independently noisy references."""
    rng = np.random.default_rng(seed)
    truth, old, new, m = _images(rng, (12, 12))
    sigma = 0.05 * truth * np.sqrt(8)          # per-seed noise; the mean's SE is 5 % of the truth
    out = []
    for i in range(n):
        y, se = _noisy_reference(rng, truth, sigma, rho)
        out.append((paired_difference(name, new, old, y, se, m, seed=i, **kw), y, se, new, old, m))
    return out


@pytest.mark.parametrize("name", ["relmse", "si_relmse", "energy_ratio"])
@pytest.mark.parametrize("rho", [0.0, 1.0])
def test_delta_method_se_matches_the_spread_over_references(name, rho):
    """SE within 15 % of the true spread where the channels are fully correlated, and never
    below it by more than sampling error (the bound is conservative for any correlation)."""
    runs = _over_references(11, name, rho, 150, k=8)
    assert all(d.method == "delta" and np.isfinite(d.dof) and d.dof > 7 for d, *_ in runs)
    spread, se = float(np.std([d.delta for d, *_ in runs], ddof=1)), float(np.mean([d.se for d, *_ in runs]))
    print(f"{name} rho={rho}: spread of Delta {spread:.4g}, mean SE {se:.4g}, ratio {se / spread:.3f}")
    # 150 references: the spread is known to about +-5.8 % (1 sigma)
    assert se >= 0.88 * spread, f"{name}: SE {se:.4g} underestimates the spread {spread:.4g}"
    if rho == 1.0:
        assert se <= 1.15 * spread, f"{name}: SE {se:.4g} overestimates the spread {spread:.4g}"


def test_independent_channel_formula_would_underestimate():
    """The power of the test above: with correlated channels, sum_c g^2 se^2 is too small."""
    runs = _over_references(12, "relmse", 1.0, 100)
    naive = [np.sqrt((((GRADIENTS["relmse"](new, y, m) - GRADIENTS["relmse"](old, y, m)) * se) ** 2)[m].sum())
             for _, y, se, new, old, m in runs]
    assert np.mean(naive) < 0.7 * np.std([d.delta for d, *_ in runs], ddof=1)


def test_resampling_se_matches_the_spread_for_flip():
    runs = _over_references(5, "flip", 1.0, 20, draws=8)
    assert all(d.method == "resampling" and d.dof == 7 for d, *_ in runs)
    spread = float(np.std([d.delta for d, *_ in runs], ddof=1))
    se = float(np.sqrt(np.mean([d.se ** 2 for d, *_ in runs])))
    print(f"flip: spread of Delta {spread:.4g}, rms SE {se:.4g}, ratio {se / spread:.3f}")
    # 20 references: the spread itself is known to about +-16 % (1 sigma)
    assert 0.6 * spread <= se <= 1.5 * spread


def test_delta_is_the_change_in_badness():
    y = np.ones((4, 4, 3))
    se = np.full_like(y, 0.01)
    # energy ratio 0.8 -> 1.1: badness 0.2 -> 0.1, an improvement
    d = paired_difference("energy_ratio", 1.1 * y, 0.8 * y, y, se)
    assert d.delta == pytest.approx(-0.1) and d.old == pytest.approx(0.8) and d.new == pytest.approx(1.1)
    assert badness(0.8, 1.0) == pytest.approx(0.2)
    identical = paired_difference("relmse", 1.1 * y, 1.1 * y, y, se)
    assert identical.delta == 0.0 and identical.se == 0.0


def test_dof_by_welch_satterthwaite():
    g = np.zeros((2, 2, 3))
    g[0, 0] = 1.0
    se = np.ones((2, 2, 3))
    sd, dof = delta_method_se(g, se, None, k=8)
    assert sd == pytest.approx(3.0) and dof == pytest.approx(7.0)     # one pixel: its own K - 1
    g[:] = 1.0
    assert delta_method_se(g, se, None, k=8)[1] == pytest.approx(28.0)   # four equal pixels


def test_missing_or_bad_se():
    y = np.ones((4, 4, 3))
    with pytest.raises(ValueError, match="no per-pixel standard error"):
        paired_difference("relmse", y, y, y, None)
    with pytest.raises(ValueError, match="se shape"):
        paired_difference("relmse", y, y, y, np.ones((2, 2, 3)))
    with pytest.raises(ValueError, match="unknown metric"):
        paired_difference("psnr", y, y, y, y)
