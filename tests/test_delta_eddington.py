"""``phase_scaling = "delta-eddington"`` (:func:`sslpv_gl.material.delta_eddington`) against independent routes.

* Quadrature: the Henyey-Greenstein phase function's first two Legendre moments (g and g^2,
  computed here by integrating HG itself, not from the closed form) equal those of the scaled
  function f delta + (1 - f) P1(g*), the forward peak plus the two-band lobe the lattice carries.
* Transport invariants: absorption sigma_a and reduced scattering sigma_s (1 - g) are kept, so the
  ``diffusion`` mapping, a function of them only, gives the same material with and without it.
* The setting: default the paper's (none), a bad value is one line, a calibrated file fitted without
  it refuses a render with it.
"""

import numpy as np
import pytest
from scipy.integrate import quad

from harness.errors import InputError
from sslpv_gl.material import delta_eddington, lpv_material
from sslpv_gl.params import SSLPVParams


def hg(mu, g):
    return 0.5 * (1 - g * g) / (1 + g * g - 2 * g * mu) ** 1.5        # normalised over mu in [-1, 1]


def legendre_moment(g, n):
    p = {1: lambda m: m, 2: lambda m: 0.5 * (3 * m * m - 1)}[n]
    return quad(lambda m: hg(m, g) * p(m), -1, 1, points=[1.0], limit=400, epsabs=1e-12)[0]


@pytest.mark.parametrize("g", [0.3, 0.8, 0.9, 0.95])
def test_scaled_phase_function_keeps_the_first_two_moments(g):
    _, _, g_s = delta_eddington(1.0, 0.9, g)
    f = g * g
    # f delta(mu - 1) + (1 - f) (1 + 3 g* mu) / 2: moment 1 = f + (1 - f) g*, moment 2 = f (the P1 lobe has none)
    assert f + (1 - f) * float(g_s) == pytest.approx(legendre_moment(g, 1), abs=1e-8)
    assert f == pytest.approx(legendre_moment(g, 2), abs=1e-8)


def test_absorption_and_reduced_scattering_are_kept():
    rng = np.random.default_rng(1)
    st, a, g = rng.uniform(0.5, 40, 200), rng.uniform(0.1, 0.999, 200), rng.uniform(-0.5, 0.97, 200)
    st_s, a_s, g_s = delta_eddington(st, a, g)
    np.testing.assert_allclose(st_s * (1 - a_s), st * (1 - a), rtol=1e-12)            # sigma_a
    np.testing.assert_allclose(st_s * a_s * (1 - g_s), st * a * (1 - g), rtol=1e-12)  # sigma_s (1 - g)
    back = g <= 0
    np.testing.assert_array_equal(st_s[back], st[back])                               # no forward peak to remove
    assert np.all(st_s[~back] < st[~back]) and np.all(g_s[~back] < g[~back])


class _Medium:
    def __init__(self, g):
        n = 4
        self.bbox_min, self.bbox_max = np.zeros(3), np.ones(3)
        self.sigma_t = np.full((n, n, n, 3), [20.0, 30.0, 45.0], np.float32)
        self.albedo = np.full((n, n, n, 3), [0.99, 0.95, 0.9], np.float32)
        self.g = np.full((n, n, n, 3), g, np.float32)


def test_diffusion_mapping_is_unchanged_and_collision_is_not():
    med = _Medium(0.9)
    for mapping, same in (("diffusion", True), ("collision", False)):
        a = lpv_material(med, None, 8, mapping)
        b = lpv_material(med, None, 8, mapping, phase_scaling="delta-eddington")
        close = all(np.allclose(a[k], b[k], rtol=2e-6) for k in ("sigma_lpv", "sigma_s_prime", "g", "radiance_scale"))
        assert close == same, mapping


def test_the_setting():
    assert SSLPVParams().phase_scaling == "none"
    with pytest.raises(InputError, match="phase_scaling: unknown phase_scaling 'delta'"):
        SSLPVParams(phase_scaling="delta")


def test_a_calibration_fitted_without_it_refuses_it():
    from harness.paths import REPO

    path = REPO / "baselines" / "calibrated" / "collision" / "calibrated.toml"
    ok = SSLPVParams(mapping=f"calibrated:{path}", N=32, steps=32, skip=2)
    ok.resolved()
    with pytest.raises(InputError, match="phase_scaling"):
        SSLPVParams(mapping=f"calibrated:{path}", N=32, steps=32, skip=2, phase_scaling="delta-eddington")
