"""The dipole kernels on a flat half-space (NumPy, no GPU): total diffuse reflectance and the dense gather's convergence.

Prints two tables and, with ``--write``, writes them to ``docs/benchmarks/dipole_plane.md``
(``benchmarks/page.py``; ``docs/dipole_rivals.md`` links to it):

A. Total diffuse reflectance at normal (and 60 degree) incidence: the standard dipole's closed form (Eq. K2) and
   its quadrature, and the directional dipole's ``pi int S_d dA`` (adaptive quadrature over rings of 720 angles).
   At eta != 1 both include the exit transmittance's normalisation (the directional dipole's ``1/(4 C_phi(1/eta))``
   cancels the hemispherical mean of ``T_21``; the standard dipole is given with ``(1 - F_dr(1/eta))``).
B. The dense gather's sampling of both kernels (the algorithm of ``gather_dense.comp``: midpoint rule
   on a triangle lattice of spacing h, with or without the near-field split at rho = 3h), relative error of the
   exit radiance against the kernel's exact plane integral, 4 random exit points per setting.

    .venv/bin/python benchmarks/dipole_plane.py [--write]
"""

import argparse

import numpy as np
from scipy.integrate import quad

from dipole_gl import kernels
from dipole_gl.sampling import N_PHI, NEAR_RADIUS, radial_nodes, window

Z = np.array([0.0, 0.0, 1.0])


def mat(alpha, eta):
    return kernels.material(np.array([alpha]), np.array([1.0 - alpha]), eta)      # sigma_t' = 1


def sd(xi, wi, m, kind="dirpole"):
    if kind == "dipole":
        return kernels.rd_dipole(np.linalg.norm(xi, axis=-1)[..., None], m)[..., 0] / np.pi
    return kernels.dirpole_sd(xi, np.broadcast_to(Z, xi.shape), np.broadcast_to(wi, xi.shape), np.zeros(3), Z, m)[..., 0]


def ring(r, wi, m, n_phi=720, kind="dirpole"):
    phi = 2 * np.pi * np.arange(n_phi) / n_phi
    xi = np.stack([r * np.cos(phi), r * np.sin(phi), np.zeros(n_phi)], axis=-1)
    return np.mean(sd(xi, wi, m, kind)) * 2 * np.pi * r


def plane_integral(wi, m, upto=80.0, kind="dirpole"):
    pts = [1e-4, 1e-3, 1e-2, 0.1, 1.0]
    return sum(quad(lambda r: ring(r, wi, m, kind=kind), a, b, limit=400)[0] for a, b in zip([0.0] + pts, pts + [upto]))


def direction(theta_deg):
    t = np.radians(theta_deg)
    return np.array([np.sin(t), 0.0, np.cos(t)])


def table_a(page):
    rows = []
    for eta in (1.0, 1.3):
        for alpha in (0.6, 0.9, 0.99, 0.999):
            m = mat(alpha, eta)
            t_out = 4 * m["c_phi_out"]                      # 1 - F_dr(1/eta): the exit transmittance's mean
            closed = float(kernels.rd_total(alpha, m["A"])) * t_out
            q = quad(lambda r: float(kernels.rd_dipole(r, m)[0]) * 2 * np.pi * r, 0, np.inf, limit=400)[0] * t_out
            d0 = np.pi * plane_integral(direction(0), m)
            d60 = np.pi * plane_integral(direction(60), m)
            rows.append([f"{eta:.1f}", f"{alpha:.3f}", f"{closed:.4f}", f"{q:.4f}", f"{d0:.4f}", f"{d60:.4f}"])
    page.heading("A. Total diffuse reflectance on a half-space (sigma_t' = 1)")
    page.table(["eta", "albedo", "dipole, closed form", "dipole, quadrature", "dirpole, 0 deg", "dirpole, 60 deg"], rows,
               note="At eta != 1 both include the exit transmittance's normalisation (module docstring).")


def lattice(h, L):
    n = int(L / h) + 2
    i, j = np.meshgrid(np.arange(-n, n), np.arange(-n, n))
    e1, e2 = np.array([h, 0.0]), np.array([h / 2, h * np.sqrt(3) / 2])
    base = i[..., None] * e1 + j[..., None] * e2
    pts = np.concatenate([(base + (e1 + e2) / 3).reshape(-1, 2), (base + 2 * (e1 + e2) / 3).reshape(-1, 2)])
    return pts, np.sqrt(3) / 4 * h * h


def near_field(wi, m, rho, kind):
    t, w = radial_nodes()
    phi = 2 * np.pi * np.arange(N_PHI) / N_PHI
    r = rho * t
    xi = np.stack([r[:, None] * np.cos(phi), r[:, None] * np.sin(phi), np.zeros((len(r), N_PHI))], axis=-1)
    return rho * np.sum(w * window(r, rho) * r * sd(xi, wi, m, kind).mean(axis=1) * 2 * np.pi)


def table_b(page, rng=np.random.default_rng(0)):
    rows = []
    for kind in ("dipole", "dirpole"):
        for alpha in (0.6, 0.99):
            m = mat(alpha, 1.0)
            L = min(80.0, 30.0 / float(m["sigma_tr"][0]))
            for theta in ((0,) if kind == "dipole" else (0, 60, 85)):     # the standard dipole ignores w_i
                wi = direction(theta)
                exact = plane_integral(wi, m, kind=kind)
                for h in (0.5, 1.0, 2.0):
                    pts, area = lattice(h, L)
                    rho = NEAR_RADIUS * h
                    near = near_field(wi, m, rho, kind)
                    plain, split = [], []
                    for _ in range(4):
                        p = pts - rng.uniform(0, h, 2)
                        p = p[np.linalg.norm(p, axis=1) < L]
                        xi = np.concatenate([p, np.zeros((len(p), 1))], axis=1)
                        v = sd(xi, wi, m, kind)
                        r = np.linalg.norm(p, axis=1)
                        plain.append(v.sum() * area / exact - 1)
                        split.append((near + np.sum(v * (1 - window(r, rho))) * area) / exact - 1)
                    fmt = lambda e: " ".join(f"{x:+.3f}" for x in e)                           # noqa: E731
                    rows.append([kind, f"{alpha:.2f}", theta, f"{h:.1f}", fmt(plain), fmt(split)])
    page.heading("B. The dense gather on a plane")
    page.table(["kernel", "albedo", "theta [deg]", "h / l", "midpoint only", "with near field (rho = 3h)"], rows,
               note="Relative error of the exit radiance against the kernel's exact plane integral, at 4 random "
                    "exit points per setting, eta = 1.")


def main(argv=None):
    from page import Page

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", action="store_true", help="write docs/benchmarks/dipole_plane.md")
    args = ap.parse_args(argv)
    page = Page("dipole_plane", "The dipole kernels on a flat half-space")
    table_a(page)
    table_b(page)
    page.finish(args.write)


if __name__ == "__main__":
    main()
