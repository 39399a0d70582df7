"""The ``transport`` mapping (sslpv_gl/material.py, Eq. (T1); docs/diffusion_mapping.md Sec. 11).

Two routes that do not use Eq. (9)'s perturbation formula, through which the mapping is defined:

* the spread of a point source after ``k`` steps, from powers of one step's Fourier symbol
  (Eq. (2), itself checked against ``twin.propagate`` in tests/test_lattice.py): its per-axis
  variance grows by ``2 D`` per step once the band-1 transients have died, and ``D`` must be the
  medium's ``l_tr / 3`` cells;
* the steady state's decay away from a source, ``exp(-kappa x)`` with ``exp(-sigma_lpv dx)
  Lambda(kappa) = 1`` (Eq. (13)), against diffusion theory's ``sigma_tr dx = sqrt(3 sigma_a
  sigma_t') dx``.
"""

import numpy as np
import pytest

from harness.errors import InputError
from sslpv_gl import lattice
from sslpv_gl.material import TRANSPORT_K1_MAX, map_material_full, transport_k1


def _spread_rate(k1, k=400, h=1e-3):
    """Growth of the per-axis variance of ``c00`` per step at step ``k``, from ``T(q)^k`` (Eq. (2))."""
    def log_f(q, n):
        T = lattice.symbol((q, 0.0, 0.0), k1)
        return np.log(np.linalg.matrix_power(T, n)[0, 0].real)

    def var(n):
        return -(log_f(h, n) + log_f(-h, n) - 2.0 * log_f(0.0, n)) / (h * h)

    return var(k + 1) - var(k)


@pytest.mark.parametrize("l_tr", [0.8, 2.0, 6.0, 15.0])
def test_lattice_spreads_as_fast_as_the_medium(l_tr):
    dx, albedo, g = 0.04, 0.99, 0.3
    sigma_t = 1.0 / (l_tr * dx * (1.0 - albedo * g))       # a reduced mean free path of l_tr cells
    k1 = float(transport_k1(sigma_t, albedo, g, dx))
    rate = _spread_rate(k1)
    print(f"l_tr {l_tr} cells: k1 {k1:.4f}, variance per step {rate:.5f}, 2 l_tr / 3 = {2 * l_tr / 3:.5f}")
    assert rate == pytest.approx(2.0 * l_tr / 3.0, rel=1e-3)
    if l_tr >= 2.0:                                       # the paper's k1 <= 1 cannot: D_lpv(1) = 0.2258
        assert 2.0 * lattice.d_lpv(1.0) < 0.7 * rate


def test_steady_state_decays_with_the_medium_diffusion_length():
    from scipy.optimize import brentq

    dx, g = 0.04, 0.3
    for sigma_t, albedo in ((6.0, 0.99), (6.0, 0.995), (20.0, 0.999)):
        m = map_material_full(sigma_t, albedo, g, dx, "transport")
        sig_dx, k1 = float(m["sigma_lpv"]) * dx, float(m["g"])
        kappa = brentq(lambda kap: lattice.sigma_dx_for_kappa(kap, k1) - sig_dx, 1e-6, 3.0)
        s_a, s_tp = sigma_t * (1 - albedo), sigma_t * (1 - albedo * g)
        want = np.sqrt(3.0 * s_a * s_tp) * dx
        coll = map_material_full(sigma_t, albedo, g, dx, "collision")
        k1_c = (1 - float(coll["sigma_s_prime"])) + float(coll["sigma_s_prime"]) * g
        kappa_c = brentq(lambda kap: lattice.sigma_dx_for_kappa(kap, k1_c) - float(coll["sigma_lpv"]) * dx, 1e-6, 3.0)
        print(f"sigma_t {sigma_t}, albedo {albedo}: lattice decay {kappa:.5f} per cell, diffusion theory "
              f"{want:.5f} (ratio {kappa / want:.4f}); the collision mapping's {kappa_c:.5f}")
        assert kappa == pytest.approx(want, rel=0.03)
        assert kappa_c > 1.2 * want                        # the test has something to detect


def test_k1_is_clipped_to_a_stable_lattice():
    # a nearly transparent cell and a vacuum cell: the largest k1; a dense one: the smallest
    k1 = transport_k1(np.array([1e-3, 0.0, 1e4]), 0.5, 0.0, 0.04)
    assert k1[0] == pytest.approx(TRANSPORT_K1_MAX) and k1[1] == pytest.approx(TRANSPORT_K1_MAX)
    assert k1[2] == pytest.approx(-1.0)
    c = lattice.constants()
    assert c.b * TRANSPORT_K1_MAX < c.a                    # the band-1 eigenvalue of a step stays below 1


@pytest.mark.parametrize("outside", ["vacuum", "material", "extrapolated"])
def test_transport_needs_an_outside_that_takes_light_out(outside):
    from sslpv_gl.params import SSLPVParams

    with pytest.raises(InputError) as err:
        SSLPVParams(mapping="transport", outside=outside)
    line = str(err.value)
    assert line.startswith("--outside: outside:") and "absorb" in line and "\n" not in line, line
    SSLPVParams(mapping="transport", outside="absorb")
    SSLPVParams(mapping="transport", outside="interior")
