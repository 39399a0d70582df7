"""Where the dipole kernels depart from transport theory: both kernels against a random walk on a half-space.

A pencil beam of unit power enters an index-matched half-space of isotropic scatterers (``sigma_t' = 1``, so
distances are in reduced mean free paths) at normal and at 60 degree incidence. Transport theory's answer comes
from the analog random walk of ``harness/reference/random_walk.py`` (checked against Chandrasekhar's H-function
and the exact single-scattering results, ``tests/test_random_walk.py``) and, for the total, from the H-function
itself (``harness/reference/plane_albedo.py``). The kernels are those of ``dipole_gl/kernels.py``: the standard
dipole's ``R_d(r)`` (Jensen et al. 2001) and the directional dipole's ``pi S_d`` (Frisvad et al. 2014), each
averaged over the walk's bins before it is divided by the walk's exitance.

Writes ``docs/benchmarks/kernel_transport.md`` and ``docs/figures/kernel_transport.{svg,png}`` with ``--write``::

    python benchmarks/kernel_transport.py [--photons 2000000] [--seed 1] [--write]

A few minutes on a shared 2-core machine at the default photon count (the walks at albedo 0.999 take most of it).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.optimize import brentq

from dipole_gl import kernels
from harness.errors import InputError
from harness.reference import plane_albedo as pa
from harness.reference import random_walk as rw

sys.path.insert(0, str(Path(__file__).resolve().parent))
from page import ROOT, Page  # noqa: E402

ALBEDOS = (0.5, 0.9, 0.99, 0.999)
THETAS = (0.0, 60.0)
EDGES = np.array([0.0, 0.25, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 16.0, 24.0])
#: A ratio whose walk has a relative standard error above this is left out of the tables.
MAX_REL_SE = 0.1
FIGURE = ROOT / "docs" / "figures" / "kernel_transport"


def medium(alpha):
    return kernels.material(np.array([alpha]), np.array([1.0 - alpha]), 1.0)      # sigma_t' = 1, eta = 1


def plane_total(f, alpha, panels=48, nodes=16, n_phi=64):
    """``int f r dr dphi`` over the plane: geometric Gauss-Legendre panels in r from 1e-6 to 40 diffusion lengths."""
    s = float(np.sqrt(3.0 * (1.0 - alpha)))
    edges = np.concatenate([[0.0], np.geomspace(1e-6, max(60.0, 40.0 / s), panels)])
    x, w = np.polynomial.legendre.leggauss(nodes)
    t, w = 0.5 * (x + 1.0), 0.5 * w
    r = (edges[:-1, None] + np.diff(edges)[:, None] * t).ravel()
    wr = (np.diff(edges)[:, None] * w).ravel()
    phi = 2.0 * np.pi * (np.arange(n_phi) + 0.5) / n_phi
    vals = f(r[:, None], phi[None, :])
    return float(np.sum(vals.mean(axis=1) * 2.0 * np.pi * r * wr))


def run_walks(photons, seed):
    walks, seconds = {}, {}
    for alpha in ALBEDOS:
        for theta in THETAS:
            t0 = time.perf_counter()
            walks[alpha, theta] = rw.walk(alpha, theta_deg=theta, n_photons=photons, seed=seed, r_edges=EDGES)
            seconds[alpha, theta] = time.perf_counter() - t0
            print(f"walk alpha' {alpha}, {theta:g} deg: {seconds[alpha, theta]:.1f} s", file=sys.stderr, flush=True)
    return walks, seconds


def totals_table(page, walks):
    rows = []
    for alpha in ALBEDOS:
        m = medium(alpha)
        std = float(kernels.rd_total(alpha, m["A"]))
        for theta in THETAS:
            mu0 = np.cos(np.radians(theta))
            w = walks[alpha, theta]
            tot, tot_se = w.reflectance("all")
            mult, mult_se = w.reflectance("multiple")
            exact = float(pa.plane_albedo(mu0, alpha))
            exact_mult = exact - pa.single_scattering_albedo(mu0, alpha)
            dirp = plane_total(kernels.plane_directional(m, theta), alpha)
            rows.append([f"{alpha:g}", f"{theta:g}", f"{tot:.4f} ± {tot_se:.4f}", f"{exact:.4f}",
                         f"{(tot - exact) / tot_se:+.1f}", f"{mult:.4f} ± {mult_se:.4f}", f"{exact_mult:.4f}",
                         f"{std:.4f}", f"{dirp:.4f}", f"{std / exact_mult:.3f}", f"{dirp / exact_mult:.3f}"])
    page.table(["α′", "θ (deg)", "walk: all orders", "1 − H(μ0)√(1 − α′)", "z", "walk: orders ≥ 2",
                "exact: orders ≥ 2", "standard dipole (K2)", "directional dipole", "standard / exact ≥ 2",
                "directional / exact ≥ 2"], rows,
               note="*walk*: the random walk's total diffuse reflectance ± its standard error; *z*: (walk − H) / SE. "
                    "*exact: orders ≥ 2*: the plane albedo minus the exact single-scattering albedo (Eq. S of "
                    "`plane_albedo.py`), the part that a diffusion kernel models. The standard dipole's total is "
                    "its closed form and does not depend on incidence; the directional dipole's is its plane "
                    "integral by quadrature.")


def ratio_cells(model, value, se):
    cells = []
    for mo, v, s in zip(model, value, se):
        if v <= 0 or s / v > MAX_REL_SE:
            cells.append("–")
        else:
            q = mo / v
            cells.append(f"{q:.3f} ± {q * s / v:.3f}")
    return cells


def ratio_table(page, walks, kind, theta, sector):
    """Rows: annuli; columns: albedos; cells: kernel / walk (orders >= 2) averaged over the bin."""
    cols = []
    for alpha in ALBEDOS:
        m = medium(alpha)
        w = walks[alpha, theta]
        sec = {"ring": None, "forward": rw.FORWARD, "backward": w.backward}[sector]
        phi = (0.0, 2.0 * np.pi) if sec is None else w.sector_edges(sec)
        f = kernels.plane_standard(m) if kind == "standard" else kernels.plane_directional(m, theta)
        value, se = w.exitance("multiple", sec)
        cols.append(ratio_cells(rw.bin_mean(f, EDGES, phi, nodes=16), value, se))
    rows = [[f"{a:g} – {b:g}"] + [c[i] for c in cols] for i, (a, b) in enumerate(zip(EDGES[:-1], EDGES[1:]))]
    page.table(["r (mfp)"] + [f"α′ = {a:g}" for a in ALBEDOS], rows)
    return cols


def tested_table(page, walks, alpha=0.999, lo=12.0, hi=24.0):
    """Kernel / walk (orders >= 2) in one annulus [lo, hi] (a union of the walk's bins), as the test judges it."""
    i0, i1 = int(np.searchsorted(EDGES, lo)), int(np.searchsorted(EDGES, hi))
    if EDGES[i0] != lo or EDGES[i1] != hi:
        raise ValueError(f"tested_table: [{lo}, {hi}] is not a union of the bins {EDGES}")
    rows = []
    for kind, theta in (("standard", 0.0), ("directional", 0.0), ("directional", 60.0)):
        m, w = medium(alpha), walks[alpha, theta]
        p = w.counts[rw.MULTIPLE, :, i0:i1].sum() / w.n_photons
        area = np.pi * (hi * hi - lo * lo)
        value, se = p / area, np.sqrt(p * (1.0 - p) / w.n_photons) / area
        f = kernels.plane_standard(m) if kind == "standard" else kernels.plane_directional(m, theta)
        model = float(rw.bin_mean(f, np.array([lo, hi]), nodes=16)[0])
        rows.append([kind, f"{theta:g}", f"{value:.4e} ± {se:.1e}", f"{model:.4e}",
                     f"{model / value:.4f} ± {model / value * se / value:.4f}"])
    page.table(["kernel", "θ (deg)", "walk, orders ≥ 2 (per mfp²)", "kernel", "kernel / walk"], rows,
               note=f"α′ = {alpha:g}, the annulus {lo:g}–{hi:g} mfp.")


def single_share_table(page, walks):
    rows = []
    for i, (a, b) in enumerate(zip(EDGES[:-1], EDGES[1:])):
        row = [f"{a:g} – {b:g}"]
        for alpha in ALBEDOS:
            allv, se = walks[alpha, 0.0].exitance("all")
            one, _ = walks[alpha, 0.0].exitance("single")
            row.append(f"{one[i] / allv[i]:.3f}" if allv[i] > 0 and se[i] <= MAX_REL_SE * allv[i] else "–")
        rows.append(row)
    page.table(["r (mfp)"] + [f"α′ = {a:g}" for a in ALBEDOS], rows)


def figure(walks, cross, out):
    """The figure as ``out.svg`` and ``out.png`` (returns the PNG's path)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.4))
    ax = axes[0]
    q = np.geomspace(1e-4, 0.7, 30)                    # 1 - alpha'
    alphas = 1.0 - q
    for theta, ls in ((0.0, "-"), (60.0, "--")):
        mu0 = np.cos(np.radians(theta))
        ax.plot(q, [pa.plane_albedo(mu0, a) for a in alphas], "k" + ls, label=f"transport, all orders, {theta:g}°")
        ax.plot(q, [pa.plane_albedo(mu0, a) - pa.single_scattering_albedo(mu0, a) for a in alphas], color="0.55",
                ls=ls, label=f"transport, orders ≥ 2, {theta:g}°")
        ax.plot(q, [plane_total(kernels.plane_directional(medium(a), theta), a) for a in alphas], color="tab:red",
                ls=ls, label=f"directional dipole, {theta:g}°")
        for alpha in ALBEDOS:
            v, s = walks[alpha, theta].reflectance("all")
            ax.errorbar([1.0 - alpha], [v], [s], fmt="o" if theta == 0 else "s", color="k", ms=4, mfc="none")
    ax.plot(q, kernels.rd_total(alphas, 1.0), color="tab:blue", label="standard dipole (any incidence)")
    ax.axhline(1.0, color="0.3", lw=0.6)
    ax.axvline(1.0 - cross, color="tab:red", lw=0.6, ls=":")
    ax.set_xscale("log")
    ax.invert_xaxis()
    ax.set_xlabel("1 − α′  (markers: the random walk)")
    ax.set_ylabel("total diffuse reflectance")
    ax.legend(fontsize=7)
    mid = np.sqrt(EDGES[1:] * EDGES[:-1])
    mid[0] = 0.5 * EDGES[1]
    for ax, theta in zip(axes[1:], THETAS):
        for alpha, colour in zip(ALBEDOS, ("tab:olive", "tab:green", "tab:purple", "tab:brown")):
            m, w = medium(alpha), walks[alpha, theta]
            value, se = w.exitance("multiple")
            ok = (value > 0) & (se < MAX_REL_SE * np.maximum(value, 1e-300))
            for f, ls, name in ((kernels.plane_standard(m), "-", "standard"),
                                (kernels.plane_directional(m, theta), "--", "directional")):
                ratio = rw.bin_mean(f, EDGES, nodes=16) / np.where(ok, value, np.nan)
                ax.plot(mid[ok], ratio[ok], ls, color=colour, marker="o", ms=3, label=f"{name}, α′ = {alpha:g}")
        ax.axhline(1.0, color="0.3", lw=0.6)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("r (reduced mean free paths)")
        ax.set_ylabel("kernel / random walk (orders ≥ 2), whole annulus")
        ax.set_title(f"incidence {theta:g}°")
        ax.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    for ext in ("svg", "png"):
        tmp = out.with_name(f".{out.name}.{ext}.tmp")
        fig.savefig(tmp, format=ext, dpi=110, bbox_inches="tight", metadata={"Date": None} if ext == "svg" else None)
        os.replace(tmp, out.with_suffix(f".{ext}"))
    plt.close(fig)
    return out.with_suffix(".png")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photons", type=int, default=2_000_000, help="photons per walk, >= 10000 (default 2000000)")
    ap.add_argument("--seed", type=int, default=1, help="the walks' seed, >= 0 (default 1)")
    ap.add_argument("--write", action="store_true", help="write the page and the figure under docs/")
    args = ap.parse_args(argv)
    try:
        if args.photons < 10_000:
            raise InputError("--photons", "photons", f"{args.photons} is too few for the tables",
                             "pass at least 10000")
        if args.seed < 0:
            raise InputError("--seed", "seed", f"{args.seed} is negative", "pass a seed >= 0")
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None

    page = Page("kernel_transport", "The dipole kernels against transport theory on a half-space")
    walks, seconds = run_walks(args.photons, args.seed)
    cross = brentq(lambda a: plane_total(kernels.plane_directional(medium(a), 0.0), a) - 1.0, 0.9, 0.999, xtol=1e-6)
    page.para(
        "A pencil beam of unit power enters an index-matched half-space of isotropic scatterers at the origin, "
        "at normal and at 60° incidence (travelling towards +x); `σt′ = 1`, so every distance is in reduced mean "
        "free paths (mfp). Transport theory's answer is the analog random walk of "
        "`harness/reference/random_walk.py` "
        f"({args.photons:,} photons per albedo and incidence, seed {args.seed}; "
        f"{sum(seconds.values()):.0f} s for the {len(seconds)} walks) and, for the total, Chandrasekhar's "
        "H-function (`harness/reference/plane_albedo.py`). The kernels are those of `dipole_gl/kernels.py` at "
        "η = 1: the standard dipole's `R_d(r)` and the directional dipole's `π S_d`, the exitance per unit area "
        "per unit power that each predicts, averaged over the same bins as the walk's tallies.")
    page.heading("Total diffuse reflectance")
    totals_table(page, walks)
    page.para(
        "The directional dipole returns more light than enters above α′ = "
        f"{cross:.4f} at normal incidence (its plane integral crosses 1 there, found by bisection): its real source "
        "sits at the point of entry, where the P1 fluence is large. This is the model as published "
        "(`docs/dipole_rivals.md`, Sec. 2), not a flaw of the implementation.")
    out = FIGURE if args.write else Path(tempfile.mkdtemp()) / FIGURE.name       # docs/ only with --write
    page.figure(figure(walks, cross, out), "total diffuse reflectance against albedo; kernel over walk against distance")
    page.para(
        "Left: total diffuse reflectance against 1 − α′ (high albedo to the right; dotted: where the directional "
        "dipole's total at normal incidence crosses 1). Middle and right: each "
        "kernel's exitance over the walk's multiple-scattering exitance in whole annuli, against the distance "
        "from the point of entry (solid: standard dipole; dashed: directional dipole).")
    page.heading("Exitance R(r): kernel / walk, whole annuli")
    page.para(
        "Each cell is the kernel's mean exitance over the annulus divided by the walk's exitance of orders ≥ 2 in "
        "it (the dipoles model multiple scattering only), ± the standard error that the walk gives the ratio. "
        f"A cell whose walk has a relative standard error above {MAX_REL_SE:g} is left out (–).")
    for kind in ("standard", "directional"):
        for theta in THETAS:
            if kind == "standard" and theta:
                page.para("**Standard dipole**, 60° incidence (the model ignores the direction of incidence):")
            else:
                page.para(f"**{kind.capitalize()} dipole**, {theta:g}° incidence:")
            ratio_table(page, walks, kind, theta, "ring")
    page.heading("Exitance at 60°: along and against the plane of incidence")
    page.para(
        "The same ratio in the quarter of each annulus centred on the beam's direction of travel (*forward*, "
        "azimuth within ±45° of +x) and on the opposite side (*backward*). The directional dipole is built to "
        "follow this asymmetry; the standard dipole is radially symmetric.")
    for kind in ("standard", "directional"):
        for sector in ("forward", "backward"):
            page.para(f"**{kind.capitalize()} dipole**, 60°, {sector}:")
            ratio_table(page, walks, kind, 60.0, sector)
    page.heading("How much of the walk's exitance is single scattering")
    page.para("The share of orders = 1 in the walk's exitance per annulus, normal incidence (the kernels leave it "
              "out; an image rendered with the diffusion term alone lacks it); – where the walk's relative standard "
              f"error exceeds {MAX_REL_SE:g}:")
    single_share_table(page, walks)
    page.heading("Where the kernels are tested")
    page.para(
        "`tests/test_dipole_transport.py` requires each kernel within 5 % (plus 4.5 of the walk's standard errors) "
        "of the walk in the annulus 12–24 mfp from the point of entry at α′ = 0.999: the standard dipole at normal "
        "incidence, the directional dipole at normal and 60° incidence. The same annulus here, with this page's "
        "photons:")
    tested_table(page, walks)
    page.para(
        "The tables above show how far each kernel departs elsewhere: near the source, at lower albedo "
        "(diffusion's decay constant `σtr = √(3(1 − α′))` is not transport's), and, for the standard dipole, at "
        "oblique incidence.")
    page.finish(args.write)


if __name__ == "__main__":
    main()
