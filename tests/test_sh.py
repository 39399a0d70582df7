"""Tests for sslpv_gl.sh: SH basis, Eq. 1 lobe, Sec. 4 matrices, Eq. 3, Eq. 5-7."""

import numpy as np
import pytest

from sslpv_gl import propagation_matrices as exported
from sslpv_gl.sh import (
    axial_mask,
    check_axial,
    apply_scattering,
    clamped_cosine_coeffs,
    face_sh_integrals,
    hemisphere_radiance,
    propagation_matrices,
    rotate_to_normal_c10,
    scatter_factors,
    sh_basis,
)


# ---------------------------------------------------------------- quadrature

def sphere_quadrature(n_theta=64, n_phi=128):
    """Directions and weights: Gauss-Legendre in cos(theta), uniform in phi."""
    mu, w_mu = np.polynomial.legendre.leggauss(n_theta)
    phi = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    m, p = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1 - m**2)
    dirs = np.stack([s * np.cos(p), s * np.sin(p), m], axis=-1).reshape(-1, 3)
    w = (w_mu[:, None] * np.full(n_phi, 2 * np.pi / n_phi)[None, :]).reshape(-1)
    return dirs, w


def frame(n):
    n = np.asarray(n, float) / np.linalg.norm(n)
    a = np.array([1.0, 0, 0]) if abs(n[0]) < 0.9 else np.array([0, 1.0, 0])
    t = np.cross(n, a)
    t /= np.linalg.norm(t)
    return t, np.cross(n, t), n


def hemisphere_quadrature(n, n_theta=64, n_phi=128):
    """Directions and weights over {w : n.w > 0}: GL in cos(theta) on [0, 1]."""
    mu, w_mu = np.polynomial.legendre.leggauss(n_theta)
    mu, w_mu = 0.5 * (mu + 1), 0.5 * w_mu
    phi = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    m, p = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1 - m**2)
    t, b, nn = frame(n)
    dirs = (s * np.cos(p))[..., None] * t + (s * np.sin(p))[..., None] * b + m[..., None] * nn
    w = (w_mu[:, None] * np.full(n_phi, 2 * np.pi / n_phi)[None, :]).reshape(-1)
    return dirs.reshape(-1, 3), w


def sh_eval(c, dirs):
    return sh_basis(dirs) @ c


# ------------------------------------------------------------------- sh_basis

class TestShBasis:
    def test_orthonormal_by_quadrature(self):
        dirs, w = sphere_quadrature()
        y = sh_basis(dirs)
        gram = (y * w[:, None]).T @ y
        np.testing.assert_allclose(gram, np.eye(4), atol=1e-12)

    def test_order_is_y_z_x(self):
        y = sh_basis(np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]]))
        k = np.sqrt(3 / (4 * np.pi))
        np.testing.assert_allclose(y[:, 1:], k * np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0]]),
                                   atol=1e-15)


# ---------------------------------------------------------- clamped cosine

class TestClampedCosine:
    def test_flux_is_pi(self):
        # int max(0, w_t.w) dw = pi = c00 * sqrt(4 pi)
        c = clamped_cosine_coeffs(np.array([0.3, -0.5, 0.8]))
        np.testing.assert_allclose(c[0] * np.sqrt(4 * np.pi), np.pi, rtol=1e-14)

    @pytest.mark.parametrize("d", [[0, 0, 1], [1, 0, 0], [0.3, -0.5, 0.8], [-0.6, 0.64, -0.48]])
    def test_matches_projection_by_quadrature(self, d):
        d = np.asarray(d, float) / np.linalg.norm(d)
        dirs, w = hemisphere_quadrature(d)  # integrand vanishes outside it
        lobe = np.maximum(0.0, dirs @ d)
        numeric = (sh_basis(dirs) * (w * lobe)[:, None]).sum(axis=0)
        np.testing.assert_allclose(clamped_cosine_coeffs(d), numeric, atol=1e-12)


# ------------------------------------------------------ propagation matrices

PAPER_PLUS_X = np.array([
    [0.167, 0, 0, -0.240],
    [0, 0.070, 0, 0],
    [0, 0, 0.070, 0],
    [-0.037, 0, 0, 0.062],
])


def permutation(i, j):
    p = np.eye(4)
    p[[i, j]] = p[[j, i]]
    return p


class TestPropagationMatrices:
    def test_shape_dtype_and_copy(self):
        m = propagation_matrices()
        assert m.shape == (6, 4, 4) and m.dtype == np.float64
        m[:] = 0
        assert propagation_matrices()[0, 0, 0] != 0
        np.testing.assert_array_equal(exported(), propagation_matrices())

    def test_plus_minus_x_match_paper_to_three_decimals(self):
        m = propagation_matrices()
        minus_x = PAPER_PLUS_X.copy()
        minus_x[0, 3] *= -1
        minus_x[3, 0] *= -1
        np.testing.assert_allclose(m[0], PAPER_PLUS_X, atol=5e-4)
        np.testing.assert_allclose(m[1], minus_x, atol=5e-4)

    def test_y_and_z_are_permutations(self):
        # Sec. 4: swap the 4th row/column with the 2nd (y) or 3rd (z)
        m = propagation_matrices()
        for s, (i, j) in ((2, (3, 1)), (3, (3, 1)), (4, (3, 2)), (5, (3, 2))):
            p = permutation(i, j)
            np.testing.assert_allclose(m[s], p @ m[s % 2] @ p, atol=1e-13)

    def test_c00_row_is_one_sixth(self):
        # the five far faces of a cube subtend the shared face's 2 pi / 3 from
        # the source centre, so an isotropic source sends 1/6 of c00 per neighbour
        m = propagation_matrices()
        np.testing.assert_allclose(m[:, 0, 0], 1 / 6, rtol=1e-12)

    def test_quadrature_converged(self):
        np.testing.assert_allclose(propagation_matrices(24), propagation_matrices(64), atol=1e-13)

    def test_face_solid_angle_against_exact_formula(self):
        # the face opposite a source at +x, distance 1.5, is a centred 1x1 square:
        # Omega = 4 asin(sin a sin b), tan a = tan b = 0.5 / 1.5
        a = np.arctan(0.5 / 1.5)
        exact = 4 * np.arcsin(np.sin(a) ** 2)
        v = face_sh_integrals([1.0, 0, 0], axis=0, sign=-1)
        np.testing.assert_allclose(v[0] * np.sqrt(4 * np.pi), exact, rtol=1e-12)


# ------------------------------------------- matrices by an analytic route (1e-6)

def polygon_solid_angle(verts):
    """Solid angle of a planar convex polygon (vertices relative to the viewpoint), by the
    Van Oosterom-Strackee formula on a triangle fan."""
    total = 0.0
    a = verts[0]
    for b, c in zip(verts[1:-1], verts[2:]):
        la, lb, lc = (np.linalg.norm(v) for v in (a, b, c))
        num = abs(np.dot(a, np.cross(b, c)))
        den = la * lb * lc + np.dot(a, b) * lc + np.dot(a, c) * lb + np.dot(b, c) * la
        total += 2.0 * np.arctan2(num, den)
    return total


def polygon_vector_irradiance(verts):
    """``int_Omega w dw`` over a spherical polygon: (1/2) sum_edges theta_e u_e (Lambert / Arvo 1995),
    ``u_e`` the unit normal of the plane through the viewpoint and edge e, oriented into the polygon."""
    v = [p / np.linalg.norm(p) for p in verts]
    out = np.zeros(3)
    for a, b in zip(v, v[1:] + v[:1]):
        n = np.cross(a, b)
        out += 0.5 * np.arccos(np.clip(np.dot(a, b), -1.0, 1.0)) * n / np.linalg.norm(n)
    centre = np.mean(v, axis=0)
    return out if np.dot(out, centre) > 0 else -out     # the vertex order fixes only the sign


def analytic_matrices():
    """Sec. 4's sum'_f M_{f,d<-s}, every integral in closed form (no quadrature, no sslpv_gl.sh)."""
    y00, y1 = 1.0 / np.sqrt(4 * np.pi), np.sqrt(3 / (4 * np.pi))
    offsets = [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)]
    mats = np.zeros((6, 4, 4))
    for s, offset in enumerate(offsets):
        src = np.asarray(offset, float)                 # source centre; destination = unit cube at 0
        for axis in range(3):
            for sign in (1.0, -1.0):
                n_f = np.zeros(3)
                n_f[axis] = sign
                if np.array_equal(n_f, src):
                    continue                            # the face shared with the source
                u, w = [k for k in range(3) if k != axis]
                corners = []
                for cu, cw in ((-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)):
                    p = np.zeros(3)
                    p[axis], p[u], p[w] = 0.5 * sign, cu, cw
                    corners.append(p - src)
                omega = polygon_solid_angle(corners)
                vec = polygon_vector_irradiance(corners)
                gather = np.array([y00 * omega, y1 * vec[1], y1 * vec[2], y1 * vec[0]])   # (1, y, z, x)
                # int_{n.w>0} (n.w) y_lm dw: y00 * pi and y1 * (2 pi / 3) n, i.e. sqrt(pi)/2, sqrt(pi/3) n
                emit = np.array([y00 * np.pi, y1 * 2 * np.pi / 3 * n_f[1], y1 * 2 * np.pi / 3 * n_f[2],
                                 y1 * 2 * np.pi / 3 * n_f[0]])
                mats[s] += np.outer(emit, gather) / np.pi
    return mats


class TestMatricesAnalytic:
    """The six matrices against closed-form solid angles and vector irradiances, to 1e-6 and better."""

    def test_every_entry(self):
        ours, exact = propagation_matrices(), analytic_matrices()
        err = np.abs(ours - exact).max()
        print(f"propagation matrices vs closed form: max |difference| {err:.2e}")
        worst = tuple(int(i) for i in np.unravel_index(np.argmax(np.abs(ours - exact)), ours.shape))
        assert err <= 1e-10, (f"propagation matrix {worst[0]} entry {worst[1:]}: {ours[worst]:.9f}, closed form "
                              f"{exact[worst]:.9f} (max |difference| {err:.2e})")

    def test_face_integrals(self):
        # one face seen obliquely: the source at +x, the destination's +y face
        corners = [np.array(p) - np.array([1.0, 0, 0]) for p in
                   ([-0.5, 0.5, -0.5], [0.5, 0.5, -0.5], [0.5, 0.5, 0.5], [-0.5, 0.5, 0.5])]
        v = face_sh_integrals([1.0, 0, 0], axis=1, sign=1)
        vec = polygon_vector_irradiance(corners)
        np.testing.assert_allclose(v[0], polygon_solid_angle(corners) / np.sqrt(4 * np.pi), atol=1e-12)
        np.testing.assert_allclose(v[1:], np.sqrt(3 / (4 * np.pi)) * vec[[1, 2, 0]], atol=1e-12)

    def test_closed_form_solid_angle_formula(self):
        # the centred square of the existing exact check: 4 asin(sin^2 a), tan a = 1/3
        corners = [np.array([-1.5, y, z]) for y, z in ((-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5))]
        a = np.arctan(0.5 / 1.5)
        assert polygon_solid_angle(corners) == pytest.approx(4 * np.arcsin(np.sin(a) ** 2), rel=1e-13)


class TestAxialPattern:
    """``propagate.comp`` multiplies by six entries of each matrix (``sh.AXIAL_PATTERN``); the rest are 0."""

    def test_closed_form_has_the_pattern(self):
        exact = analytic_matrices()          # an independent route: closed-form solid angles and irradiances
        off = np.abs(np.where(axial_mask(), 0.0, exact)).max()
        on = np.abs(exact[axial_mask()]).min()
        print(f"closed-form matrices: largest entry outside the pattern {off:.1e}, smallest inside {on:.4f}")
        assert off <= 1e-14 and on > 0.03

    def test_quadrature_matrices_pass_the_check(self):
        check_axial(propagation_matrices())

    def test_check_refuses_another_structure(self):
        M = propagation_matrices()
        M[4, 2, 3] = 1e-6                    # a z source coupling c10 to c11: not axial
        with pytest.raises(ValueError, match=r"propagation matrix 4 has entry \(2, 3\)"):
            check_axial(M)
        with pytest.raises(ValueError, match="outside the axial pattern"):
            check_axial(M[[2, 1, 0, 3, 4, 5]])     # +y's matrix in the +x slot


# ----------------------------------------------------------- Eq. 3 scattering

class TestScattering:
    def test_g_zero_keeps_c00_scales_band1(self):
        c = np.array([1.3, 0.2, -0.4, 0.7])
        out = apply_scattering(c, 0.35, 0.0)
        np.testing.assert_allclose(out, [1.3, 0.2 * 0.65, -0.4 * 0.65, 0.7 * 0.65], rtol=1e-15)

    def test_factors(self):
        k = scatter_factors(np.array([0.0, 0.5, 1.0]), np.array([0.3, 0.3, -0.2]))
        np.testing.assert_allclose(k, [[1, 1], [1, 0.65], [1, -0.2]], rtol=1e-15)


# ------------------------------------------------------ Eq. 6 and Eq. 5 / 7

COEFFS = np.array([0.9, 0.31, -0.22, 0.47])
NORMALS = [[0, 0, 1], [0.48, -0.6, 0.64], [-1, 0, 0], [0.1, 0.2, -0.97]]


class TestNormalFrame:
    @pytest.mark.parametrize("n", NORMALS)
    def test_rotate_c10_matches_projection(self, n):
        n = np.asarray(n, float) / np.linalg.norm(n)
        dirs, w = sphere_quadrature()
        f = sh_eval(COEFFS, dirs)
        y10_n = np.sqrt(3 / (4 * np.pi)) * (dirs @ n)
        np.testing.assert_allclose(rotate_to_normal_c10(COEFFS, n), np.sum(w * f * y10_n),
                                   atol=1e-12)

    @pytest.mark.parametrize("n", NORMALS)
    def test_hemisphere_radiance_matches_eq5_integral(self, n):
        n = np.asarray(n, float) / np.linalg.norm(n)
        area = 0.37
        dirs, w = hemisphere_quadrature(n)
        numeric = np.sum(w * sh_eval(COEFFS, dirs)) / (area * np.pi)
        np.testing.assert_allclose(hemisphere_radiance(COEFFS, n, area), numeric, rtol=1e-12)
