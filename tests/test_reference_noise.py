"""harness.reference.noise.stack_agreement: two seed stacks of one image compared per lit channel.

The z of each channel is Welch's t statistic of the two samples of seeds, so scipy's ``ttest_ind`` (unequal
variances) is the second route; the image means' ratio and their difference's standard error are checked against
a direct computation from the per-seed means.
"""

import numpy as np
from scipy import stats

from harness.reference.noise import lit_mask, stack_agreement


def stacks(rng, k=8, shape=(12, 10), level=(1.0, 0.5, 0.02), noise=0.1, bias=(0.0, 0.0, 0.0)):
    mean = np.broadcast_to(np.asarray(level), shape + (3,))
    a = mean * (1 + np.asarray(bias)) * (1 + noise * rng.standard_normal((k,) + shape + (3,)))
    b = mean * (1 + noise * rng.standard_normal((k,) + shape + (3,)))
    return a, b


def test_z_is_welchs_t_and_the_image_means_are_the_stacks():
    rng = np.random.default_rng(1)
    a, b = stacks(rng)
    lit = np.ones(a.shape[1:], bool)
    ag = stack_agreement(a, b, lit)
    t = stats.ttest_ind(a, b, axis=0, equal_var=False).statistic
    np.testing.assert_allclose(ag["z"], t, rtol=1e-10)
    pa, pb = a.mean((1, 2)), b.mean((1, 2))
    np.testing.assert_allclose(ag["ratio"], pa.mean(0) / pb.mean(0), rtol=1e-12)
    se = np.sqrt(pa.var(0, ddof=1) / len(pa) + pb.var(0, ddof=1) / len(pb))
    np.testing.assert_allclose(ag["diff_se"], se, rtol=1e-12)
    assert ag["pixels"] == 120
    # Same distribution: Welch's t with ~14 degrees of freedom exceeds 4 with probability ~1e-3 per channel.
    assert ag["within"] >= 0.97


def test_only_lit_channels_are_judged_and_a_channel_without_an_se_agrees():
    rng = np.random.default_rng(2)
    a, b = stacks(rng, bias=(0.0, 0.0, 5.0))         # blue far off ...
    a[:, :, 0] = b[:, :, 0] = 1.0                     # ... and column 0 the same in every seed: SE 0
    lit = lit_mask(b.mean(0), np.ones(b.shape[1:3]))
    assert lit[..., 2].all() and lit[..., :2].all()   # blue at 2 % of red is lit (the limit is 1 %)
    assert stack_agreement(a, b, lit)["within"] == 12 / 120   # only column 0 agrees
    lit[..., 2] = False                               # blue not lit: only red and green are judged
    ag = stack_agreement(a, b, lit)
    assert np.isnan(ag["z"][..., 2]).all() and np.isnan(ag["z"][:, 0]).all()
    assert ag["within"] >= 0.97 and ag["pixels"] == 120


def test_a_three_percent_bias_beyond_the_noise_is_seen():
    """Power: 3 % too bright in green, with 1 % noise per seed, puts most pixels beyond 4 SE."""
    rng = np.random.default_rng(3)
    a, b = stacks(rng, k=16, noise=0.01, bias=(0.0, 0.03, 0.0))
    ag = stack_agreement(a, b, np.ones(a.shape[1:], bool))
    assert ag["within"] < 0.2
    assert abs(ag["ratio"][1] - 1.03) < 0.003 and abs(ag["diff"][1] / ag["diff_se"][1]) > 20
    a, b = stacks(rng, k=16, noise=0.01)
    assert stack_agreement(a, b, np.ones(a.shape[1:], bool))["within"] >= 0.97
