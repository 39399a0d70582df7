"""Both dipole kernels (``dipole_gl.kernels``) against transport theory where diffusion claims to hold.

The independent route is the analog random walk of ``harness.reference.random_walk`` (itself checked
against Chandrasekhar's H-function and the exact single-scattering results in ``tests/test_random_walk.py``):
a pencil beam of unit power into an index-matched half-space, isotropic scattering, ``sigma_t' = 1``.

The regime: reduced albedo 0.999, exit points 12 to 24 reduced mean free paths from the point of entry
(one annulus), normal incidence for the standard dipole (it ignores the direction of incidence), normal and
60 degree incidence for the directional dipole. There the exitance of each kernel, averaged over the annulus
(``bin_mean``; ``R_d`` for the standard dipole, ``pi S_d`` for the directional one), over the walk's exitance of
scattering orders >= 2, must lie within
``DELTA`` = 5 % of the walk's plus 4.5 of the walk's standard errors. 5 % is the accuracy this test claims for
diffusion theory there; ``benchmarks/kernel_transport.py`` measures the departures with many more photons
(``docs/benchmarks/kernel_transport.md``), and everywhere else (near the source, lower albedo, the sectors
along and against the plane of incidence), where they are larger. With 4e5 photons per walk the window is
about 8 % of the exitance: an error of a kernel smaller than that is beyond this test.

About 10 s on one core (two walks at albedo 0.999).
"""

import numpy as np
import pytest

from dipole_gl import kernels
from harness.reference import random_walk as rw

ALBEDO = 0.999
EDGES = np.array([12.0, 24.0])
PHOTONS = 400_000
DELTA = 0.05
Z = 4.5


@pytest.fixture(scope="module")
def walks():
    return {theta: rw.walk(ALBEDO, theta_deg=theta, n_photons=PHOTONS, seed=27, r_edges=EDGES) for theta in (0.0, 60.0)}


@pytest.fixture(scope="module")
def medium():
    return kernels.material(np.array([ALBEDO]), np.array([1.0 - ALBEDO]), 1.0)          # sigma_t' = 1, eta = 1


def check(kernel, walk, what):
    value, se = walk.exitance("multiple")          # the dipoles model orders >= 2 (order 1 is < 1e-5 of it here)
    model = rw.bin_mean(kernel, EDGES)
    ratio, rel_se = model / value, se / value
    print(f"{what}: kernel / walk = {ratio[0]:.4f} +- {rel_se[0]:.4f}")
    assert np.all(np.abs(ratio - 1.0) <= DELTA + Z * rel_se), (
        f"{what}: kernel / walk {np.round(ratio, 4)} outside 1 +- ({DELTA} + {Z} x {np.round(rel_se, 4)})")


def test_standard_dipole_far_from_the_source(walks, medium):
    check(kernels.plane_standard(medium), walks[0.0], "standard dipole, normal incidence")


@pytest.mark.parametrize("theta", [0.0, 60.0])
def test_directional_dipole_far_from_the_source(walks, medium, theta):
    check(kernels.plane_directional(medium, theta), walks[theta], f"directional dipole, {theta} deg")
