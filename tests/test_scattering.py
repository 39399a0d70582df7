"""Eq. 2 / Eq. 3 (Sec. 3.2.2) by an independent route: Henyey-Greenstein applied on the sphere.

The paper's scattering model, Eq. 2,

    I_sc(w) = (1 - s') I(w) + s' int_4pi p_HG(w . w') I(w') dw',

is evaluated here by plain numerical integration, with no spherical-harmonic
algebra: a two-band lobe ``I`` (the clamped-cosine coefficients of Eq. 1 for a tilted
direction, and an arbitrary two-band function) is sampled on the sphere, the HG
integral is done for every outer direction with Gauss-Legendre nodes in the cosine
to ``w`` (where HG peaks) and uniform nodes in azimuth, and ``I_sc`` is projected
back onto the four real SH of Sec. 4 (typed below from the paper, not imported).

Eq. 3 says the result is ``k_l c_lm`` with ``k_l = (1 - s') + s' g^l``. The test
compares the projection with what each implementation actually applies, for
g in {-0.5, 0, 0.3, 0.8}:

* ``sslpv_gl.sh.apply_scattering`` (the one shared function);
* the NumPy twin: one ``twin.propagate`` step with identity "matrices" and no
  absorption hands a neighbour exactly ``S(s) c`` of its source;
* the GL renderer: one ``propagate.comp`` step hands a neighbour ``M_s S(s) c``
  (the uploaded ``u_M``); solving with ``M_s`` gives back what the shader applied,
  per colour; and the per-cell factor textures that ``upload_material`` wrote
  (``h k1 emit``) are read back and compared with ``h`` times the quadrature's k1.

Tolerances: quadrature and twin 1e-9 (float64); GL 2e-5 of the lobe's size (fp32,
amplified by ``M_s^-1``, whose condition number is ~30).
"""

import functools

import numpy as np
import pytest

from sslpv_gl import twin
from sslpv_gl.sh import SOURCE_OFFSETS, apply_scattering, propagation_matrices

G_VALUES = (-0.5, 0.0, 0.3, 0.8)
#: sigma_s' per colour: a different weight of Eq. 2's two terms in each channel
SP_RGB = (1.0, 0.6, 0.25)
TILT = np.array([0.48, -0.36, 0.8])              # unit: the lobe's direction


def basis(w):
    """The paper's real SH, Sec. 4: (1/sqrt(4 pi), sqrt(3/(4 pi)) (y, z, x))."""
    k = np.sqrt(3.0 / (4.0 * np.pi))
    return np.stack([np.full(w.shape[:-1], 1.0 / np.sqrt(4.0 * np.pi)), k * w[..., 1], k * w[..., 2],
                     k * w[..., 0]], axis=-1)


@functools.lru_cache(maxsize=8)
def gauss_legendre(n):
    """Gauss-Legendre nodes and weights on [-1, 1], computed once per n (an n x n eigenproblem)."""
    return np.polynomial.legendre.leggauss(n)


def hg(mu, g):
    """Henyey-Greenstein, normalised to 1 over the sphere."""
    return (1.0 - g * g) / (4.0 * np.pi * (1.0 + g * g - 2.0 * g * mu) ** 1.5)


def sphere_nodes(n_mu, n_phi):
    mu, wmu = gauss_legendre(n_mu)
    phi = (np.arange(n_phi) + 0.5) * 2.0 * np.pi / n_phi
    m, p = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1.0 - m * m)
    dirs = np.stack([s * np.cos(p), s * np.sin(p), m], axis=-1).reshape(-1, 3)
    return dirs, np.repeat(wmu, n_phi) * (2.0 * np.pi / n_phi)


def eq2_projected(c, sp, g, n_outer=(12, 24), n_inner=(200, 8)):
    """SH coefficients of Eq. 2's I_sc for the two-band function ``c`` (4,), by quadrature."""
    c = np.asarray(c, dtype=np.float64)
    w, w_wt, i_w, scattered = _hg_integral(tuple(c), float(g), n_outer, n_inner)
    i_sc = (1.0 - sp) * i_w + sp * scattered
    return (basis(w) * (w_wt * i_sc)[:, None]).sum(axis=0)


@functools.lru_cache(maxsize=64)
def _hg_integral(c, g, n_outer, n_inner):
    """Outer nodes, weights, I(w) and int p(w.w') I(w') dw' at every outer node w."""
    c = np.asarray(c)
    w, w_wt = sphere_nodes(*n_outer)                  # outer directions and weights
    mu, mu_wt = gauss_legendre(n_inner[0])
    phi = (np.arange(n_inner[1]) + 0.5) * 2.0 * np.pi / n_inner[1]
    # a frame (t, b, w) about each outer direction
    helper = np.where(np.abs(w[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    t = np.cross(w, helper)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    b = np.cross(w, t)
    s = np.sqrt(1.0 - mu * mu)
    # w' = mu w + s (cos phi t + sin phi b), shape (outer, mu, phi, 3)
    wp = (mu[None, :, None, None] * w[:, None, None, :]
          + s[None, :, None, None] * (np.cos(phi)[None, None, :, None] * t[:, None, None, :]
                                      + np.sin(phi)[None, None, :, None] * b[:, None, None, :]))
    i_wp = basis(wp) @ c                             # I(w') at the inner nodes
    weights = (mu_wt * hg(mu, g))[:, None] * (2.0 * np.pi / n_inner[1])
    scattered = np.einsum("omp,mp->o", i_wp, weights)   # int p(w.w') I(w') dw'
    return w, w_wt, basis(w) @ c, scattered


def lobes():
    k0, k1 = np.sqrt(np.pi) / 2.0, np.sqrt(np.pi / 3.0)   # clamped-cosine zonal coefficients (003_...)
    clamped = np.array([k0, k1 * TILT[1], k1 * TILT[2], k1 * TILT[0]])
    arbitrary = np.array([0.9, -0.45, 0.3, 0.62])
    return {"clamped_cosine": clamped, "arbitrary": arbitrary}


@pytest.fixture(scope="module")
def numeric():
    """Quadrature result for every (lobe, g, colour): (3, 4) per (lobe, g)."""
    return {(name, g): np.array([eq2_projected(c, sp, g) for sp in SP_RGB])
            for name, c in lobes().items() for g in G_VALUES}


class TestQuadrature:
    def test_converged(self):
        c = lobes()["clamped_cosine"]
        a = eq2_projected(c, 1.0, 0.8)
        b = eq2_projected(c, 1.0, 0.8, n_outer=(16, 32), n_inner=(300, 5))
        np.testing.assert_allclose(a, b, atol=1e-12)

    def test_hg_normalised_and_mean_cosine_g(self):
        mu, w = gauss_legendre(200)
        for g in G_VALUES:
            assert 2 * np.pi * np.sum(w * hg(mu, g)) == pytest.approx(1.0, abs=1e-12)
            assert 2 * np.pi * np.sum(w * mu * hg(mu, g)) == pytest.approx(g, abs=1e-12)


class TestEq3:
    """What each implementation applies equals Eq. 2 integrated on the sphere."""

    @pytest.mark.parametrize("lobe", sorted(lobes()))
    @pytest.mark.parametrize("g", G_VALUES)
    def test_shared_function(self, numeric, lobe, g):
        c = lobes()[lobe]
        got = np.array([apply_scattering(c, sp, g) for sp in SP_RGB])
        err = np.abs(got - numeric[(lobe, g)]).max()
        assert err <= 1e-9, f"sh.apply_scattering, g={g}, {lobe} lobe: off by {err:.2e} from Eq. 2 on the sphere"

    @pytest.mark.parametrize("lobe", sorted(lobes()))
    @pytest.mark.parametrize("g", G_VALUES)
    def test_twin_applies_it(self, numeric, lobe, g):
        c = lobes()[lobe]
        c0, sp, gg = _single_source(c, g)
        eye = np.broadcast_to(np.eye(4), (6, 4, 4))
        prop, _ = twin.propagate(c0, np.zeros_like(sp), sp, gg, 0.1, steps=1, skip=0, matrices=eye)
        for s, offset in enumerate(SOURCE_OFFSETS):
            x, y, z = 1 - offset                     # the neighbour whose source at +offset is the centre
            err = np.abs(prop[z, y, x] - numeric[(lobe, g)]).max()
            assert err <= 1e-9, (f"twin, g={g}, {lobe} lobe, source offset {offset}: applies Eq. 3 off by {err:.2e} "
                                 "from Eq. 2 on the sphere")


@pytest.mark.gl
class TestEq3InGL:
    @pytest.mark.parametrize("g", G_VALUES)
    def test_propagate_comp_applies_it(self, gl_renderer, numeric, g):
        c = lobes()["clamped_cosine"]
        c0, sp, gg = _single_source(c, g, N=4)
        mat = {"sigma_lpv": np.zeros_like(sp), "sigma_s_prime": sp, "g": gg}
        prop, _ = gl_renderer.propagate(c0, mat, 0.1, 1, 0, "fp32")
        mats = propagation_matrices()
        scale = np.abs(c).max()
        for s, offset in enumerate(SOURCE_OFFSETS):
            x, y, z = 1 - offset
            if min(x, y, z) < 0:
                continue
            applied = np.linalg.solve(mats[s], prop[z, y, x].astype(np.float64).T).T   # S(s) c per colour
            err = np.abs(applied - numeric[("clamped_cosine", g)]).max() / scale
            assert err <= 2e-5, f"g={g}, source offset {offset}: GL applies Eq. 3 off by {err:.2e} of the lobe"

    def test_uploaded_factor_textures(self, gl_renderer):
        """The per-cell textures propagate.comp reads hold h * k1 (k1 from the quadrature), for every g.

        ``upload_material`` writes ``h k1 emit`` (steps 2..K) and ``h k1`` (step 1); with
        no sink cells both must be ``exp(-sigma dx / 2) ((1 - s') + s' k1_HG(g))``.
        """
        N, dx = 4, 0.1
        rng = np.random.default_rng(4)
        sp = rng.uniform(0.0, 1.0, (N, N, N, 3))
        gg = np.resize(np.array(G_VALUES), (N, N, N, 3))             # every g in every channel
        sigma = rng.uniform(0.0, 5.0, (N, N, N, 3))
        mat = {"sigma_lpv": sigma, "sigma_s_prime": sp, "g": gg}
        gl_renderer.propagate(np.zeros((N, N, N, 3, 4)), mat, dx, 1, 0, "fp32")
        with gl_renderer.ctx:
            textures = gl_renderer._grid(N, "fp32").material        # the renderer's own grid
            read = [np.frombuffer(t.read(), dtype=np.float32).reshape(N, N, N, 4)[..., :3] for t in textures]
        # the band-1 factor of HG alone (s' = 1) by quadrature: c = (0, 0, 1, 0) scatters to (0, 0, k1, 0)
        k1_hg = {g: eq2_projected(np.array([0.0, 0.0, 1.0, 0.0]), 1.0, g)[2] for g in G_VALUES}
        h = np.exp(-0.5 * sigma * dx)
        want = h * ((1.0 - sp) + sp * np.vectorize(k1_hg.get)(gg))
        for index, what in ((1, "h k1 emit"), (3, "h k1"), (0, "h")):
            expect = h if index == 0 else want
            err = float(np.max(np.abs(read[index] - expect) / (np.abs(expect) + 1e-7)))
            assert err <= 2e-6, f"material[{index}] ({what}) differs from the quadrature's by {err:.2e} (relative)"


def _single_source(c, g, N=3):
    """A grid with ``c`` in the cell (1, 1, 1) for every colour, s' per colour from SP_RGB, constant g."""
    c0 = np.zeros((N, N, N, 3, 4))
    c0[1, 1, 1] = c
    sp = np.broadcast_to(np.array(SP_RGB), (N, N, N, 3)).copy()
    gg = np.full((N, N, N, 3), float(g))
    return c0, sp, gg
