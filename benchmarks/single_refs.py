"""Mitsuba's single-scattering images of the S^(1) validation cases -> ``tests/data/single/<case>.npz``.

``python benchmarks/single_refs.py [--spp 256] [--seeds 8] [--cases A,B]`` renders each case of
:data:`CASES` with Mitsuba's path tracer cut after the first scattering vertex and writes the
mean image, its per-pixel standard error (``std / sqrt(seeds)`` over independent seeds) and the
pixel coverage (the share of each pixel's footprint that sees the mesh) as a small ``.npz``,
which ``tests/test_dipole_single.py`` and ``benchmarks/single_scattering.py`` read.

Single scattering in Mitsuba (``max_depth`` counts path segments, a null interface counts none,
a refraction one, :mod:`harness.reference.mnee`): index-matched ``volpath`` with ``max_depth = 2``
(camera -> scattering vertex -> light); behind a smooth dielectric ``mneevolpath`` with
``max_depth = 4`` (camera -> refraction -> scattering vertex -> manifold connection, two segments).
:func:`check_depths` renders one depth less (black) and one more (brighter) to confirm it.

A case is a suite scene with its medium made grey (``sigma_t``, ``albedo``) and ``g = 0.5``,
its boundary index-matched or a smooth dielectric of ``eta = 1.3``, its light in front of or
behind the object, a slab possibly made thicker, at :data:`SIZE` (:func:`case_scene`).
:func:`compare_case` measures GL's S^(1) against a case's image and bounds the estimator's known
approximations (``tests/test_dipole_single.py`` asserts it, ``benchmarks/single_scattering.py`` tabulates it);
:func:`flat_exact` is the estimator with the true refraction point on a slab.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

OUT = ROOT / "tests" / "data" / "single"
SIZE = 24
G = 0.5
FRONT = (0.6, 0.5, 2.4)
#: case -> (suite scene, eta, light position or None for the scene's own, sigma_t, albedo, thickness scale)
CASES = {
    "sphere_front_eta1": ("sphere_homogeneous", 1.0, None, 8.0, 0.95, 1.0),
    "sphere_front_eta13": ("sphere_homogeneous", 1.3, None, 8.0, 0.95, 1.0),
    "slab_back_eta1": ("backlit_slab", 1.0, None, 6.0, 0.95, 1.0),
    "slab_back_eta13": ("backlit_slab", 1.3, None, 6.0, 0.95, 1.0),
    "thick_front_eta1": ("backlit_slab", 1.0, FRONT, 6.0, 0.95, 3.0),
    "thick_front_eta13": ("backlit_slab", 1.3, FRONT, 6.0, 0.95, 3.0),
    "slab_front_eta1": ("backlit_slab", 1.0, FRONT, 6.0, 0.95, 1.0),
}


def case_scene(name):
    """The scene of case ``name`` (see the module docstring)."""
    from harness.scene import load_scene
    from harness.scene.load import Boundary, PointLight, scene_hash

    base, eta, light, sigma_t, albedo, thick = CASES[name]
    sc = load_scene(base).with_resolution(SIZE, SIZE)
    if thick != 1.0:                                   # the slab made thicker along z (the camera's axis)
        mesh = dataclasses.replace(sc.mesh, vertices=sc.mesh.vertices * np.array([1.0, 1.0, thick]))
        sc = dataclasses.replace(sc, mesh=mesh)
    m = sc.medium
    sc = sc.with_medium(sigma_t=np.full_like(m.sigma_t, sigma_t), albedo=np.full_like(m.albedo, albedo),
                        g=np.full_like(m.g, G))
    boundary = Boundary("index-matched") if eta == 1.0 else Boundary("dielectric", eta=eta, roughness=0.0)
    lights = sc.lights if light is None else (PointLight(tuple(light), sc.lights[0].intensity),)
    sc = dataclasses.replace(sc, name=name, boundary=boundary, lights=lights, content_hash="")
    return dataclasses.replace(sc, content_hash=scene_hash(sc))


def single_depth(scene):
    """Mitsuba's ``max_depth`` that keeps exactly the single-scattering paths of ``scene`` (module docstring)."""
    return 2 if scene.boundary.index_matched else 4


def render_single(scene, spp, seeds, max_depth=None):
    """``(mean, se)`` (H, W, 3) of Mitsuba at ``max_depth`` (default :func:`single_depth`) over ``seeds`` seeds."""
    from harness.reference import mitsuba_scene as ms

    mi = ms.use_variant()
    d = ms.build_scene_dict(scene, spp=spp, max_depth=single_depth(scene) if max_depth is None else max_depth)
    msc = mi.load_dict(d)
    imgs = np.stack([np.asarray(mi.render(msc, seed=1000 + k, spp=spp), np.float64)[..., :3] for k in range(seeds)])
    return imgs.mean(axis=0), imgs.std(axis=0, ddof=1) / np.sqrt(seeds)


def check_depths(scene, spp=16):
    """Mean image at ``single_depth - 1``, ``single_depth`` and ``+ 1`` (the first must be 0)."""
    d = single_depth(scene)
    return [float(render_single(scene, spp, 2, max_depth=k)[0].mean()) for k in (d - 1, d, d + 1)]


def flat_exact(xo, cam, plane_z, outward, scene, mat, n_march=256):
    """S^(1) at exit points ``xo`` on a slab's face: the estimator with the true refraction point.

    The light ``y`` reaches ``x`` through the point of the plane ``z = plane_z`` (outward normal
    ``(0, 0, outward)``) where Snell's law holds (bisection on the horizontal distance), with the
    flat interface's irradiance, phase angle and path ``s'`` of that point; nodes beyond the slab's
    other face (the view ray has left the medium) give nothing. Same march (``n_march`` nodes).
    """
    from dipole_gl import single_twin
    from sslpv_gl.optics import fresnel_transmittance, refract

    eta = float(scene.boundary.eta)
    zf, zb = scene.mesh.vertices[:, 2].max(), scene.mesh.vertices[:, 2].min()
    n_o = np.array([0.0, 0.0, 1.0])
    wo = np.asarray(cam, float) - xo
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    d = refract(-wo, np.broadcast_to(n_o, xo.shape), eta)
    ss, st, g = single_twin.exit_material(mat, xo, np.broadcast_to(n_o, xo.shape))
    sref = st.min(axis=1)
    u = (np.arange(n_march) + 0.5) / n_march
    s = -np.log(1.0 - u)[None, :] / sref[:, None]
    wk = np.exp(-(st[:, None, :] - sref[:, None, None]) * s[..., None]) / (n_march * sref[:, None, None])
    x = xo[:, None, :] + s[..., None] * d[:, None, :]
    inside = (x[..., 2] <= zf + 1e-9) & (x[..., 2] >= zb)
    acc = np.zeros(x.shape[:2] + (3,))
    for light in scene.lights:
        y = np.asarray(light.position, float)
        h = np.abs(y[2] - plane_z)
        z = np.abs(x[..., 2] - plane_z)
        hv = x[..., :2] - y[:2]
        delta = np.linalg.norm(hv, axis=-1)
        lo, hi = np.zeros_like(delta), delta.copy()
        for _ in range(60):                                   # a/|ye| = eta (delta - a)/|ex|
            a = 0.5 * (lo + hi)
            f = a / np.hypot(a, h) - eta * (delta - a) / np.hypot(delta - a, z)
            lo, hi = np.where(f < 0, a, lo), np.where(f < 0, hi, a)
        a = 0.5 * (lo + hi)
        unit = hv / np.where(delta > 0, delta, 1.0)[..., None]
        e = np.concatenate([y[:2] + a[..., None] * unit, np.full(a.shape + (1,), plane_z)], axis=-1)
        d_e = np.linalg.norm(e - y, axis=-1)
        sp = np.linalg.norm(x - e, axis=-1)
        cos_e, cos_t = h / d_e, np.where(sp > 0, z / np.where(sp > 0, sp, 1.0), 1.0)
        lit = (np.sign(y[2] - plane_z) == outward) & inside
        spread = (d_e + sp / eta) * (d_e + sp * cos_e**2 / (eta * cos_t**2))
        E = fresnel_transmittance(cos_e, eta) * (cos_e / cos_t) / spread
        w12 = (x - e) / np.where(sp > 0, sp, 1.0)[..., None]
        cos_ph = np.sum(w12 * -d[:, None, :], axis=-1)
        term = np.asarray(light.intensity)[None, None] * E[..., None] * ss[:, None] * \
            single_twin.hg(cos_ph[..., None], g[:, None]) * np.exp(-st[:, None] * sp[..., None])
        acc += np.where(lit[..., None], term, 0.0)
    out = np.einsum("pkc,pkc->pc", wk, acc)
    return out * (fresnel_transmittance(wo @ n_o, eta) / eta**2)[:, None]


def inner_pixels(mask, coverage):
    """The compared pixels: two pixels inside the fully covered footprint (the march does not see where the
    view ray leaves the object; at a slab's edge it would run on into the air)."""
    from scipy.ndimage import binary_erosion

    return binary_erosion(mask & (coverage >= 1.0), np.ones((5, 5), bool))


def load_reference(name):
    """The committed Mitsuba single-scattering image of case ``name`` (``mean``, ``se``, ``coverage``)."""
    return np.load(OUT / f"{name}.npz")


def compare_case(renderer, name):
    """GL's S^(1) against Mitsuba on case ``name``, with the estimator's approximations bounded by refinement.

    Returns ``ratio`` (of the image means over :func:`inner_pixels`), ``se`` (its standard error from the
    reference's seeds), the bounds ``march`` (64 against 256 nodes, twin), ``atlas`` (1024^2 against
    2048^2 texels), ``pixel`` (the pixel centre against the mean of 2 x 2 centres) and ``line`` (at
    ``eta != 1`` on a slab: the twin against :func:`flat_exact`; 0 otherwise), ``tolerance``
    ``= 3 se + march + atlas + pixel + line``, ``within2``/``within3`` (the share of pixels with
    ``|GL - ref| <= k se``), ``pixels``.
    """
    from dipole_gl import single_twin
    from dipole_gl.medium import scene_material
    from dipole_gl.params import DipoleParams

    ref = load_reference(name)
    sc = case_scene(name)
    res = renderer.render(sc, "dipole", DipoleParams(terms="single"), debug=True)
    d = res.debug
    sel = inner_pixels(res.mask, ref["coverage"])
    m_ref = float(ref["mean"][sel].mean())
    se = float(np.sqrt(np.sum(ref["se"][sel].astype(np.float64) ** 2)) / sel.sum() / m_ref)
    m_gl = float(res.subsurface[sel].mean())
    mat = scene_material(sc)
    args = (d["position"][sel], d["normal"][sel], sc.camera.origin, d["atlas"], d["views"], sc.lights, mat,
            sc.boundary.eta, 1024)
    fine = single_twin.single_scattering(*args, n_march=256).mean()
    march = abs(single_twin.single_scattering(*args).mean() / fine - 1.0)
    a2 = renderer.render(sc, "dipole", DipoleParams(terms="single", shadow_size=2048))
    atlas = abs(m_gl / a2.subsurface[sel].mean() - 1.0)
    W, H = sc.camera.width, sc.camera.height
    sup = renderer.render(sc.with_resolution(2 * W, 2 * H), "dipole", DipoleParams(terms="single"))
    box = sup.subsurface.reshape(H, 2, W, 2, 3).mean(axis=(1, 3))
    pixel = abs(m_gl / box[sel].mean() - 1.0)
    line = 0.0
    if sc.boundary.eta != 1.0 and CASES[name][0] == "backlit_slab":      # the straight line to the light
        zf, zb = sc.mesh.vertices[:, 2].max(), sc.mesh.vertices[:, 2].min()
        front = sc.lights[0].position[2] > zf
        exact = flat_exact(d["position"][sel], sc.camera.origin, zf if front else zb, 1 if front else -1, sc, mat)
        line = abs(fine / exact.mean() - 1.0)
    z = np.abs(res.subsurface[sel] - ref["mean"][sel]) / np.maximum(ref["se"][sel], 1e-30)
    return {"ratio": m_gl / m_ref, "se": se, "march": float(march), "atlas": float(atlas), "pixel": float(pixel),
            "line": float(line), "tolerance": 3.0 * se + march + atlas + pixel + line,
            "within2": float(np.mean(z <= 2.0)), "within3": float(np.mean(z <= 3.0)), "pixels": int(sel.sum())}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--check-depths", action="store_true", help="print the mean at one depth less and more")
    args = ap.parse_args(argv)
    from harness.reference.mitsuba_scene import coverage_mask

    OUT.mkdir(parents=True, exist_ok=True)
    for name in args.cases.split(","):
        sc = case_scene(name)
        t = time.perf_counter()
        if args.check_depths:
            print(name, "mean at depth d-1, d, d+1:", check_depths(sc), flush=True)
        mean, se = render_single(sc, args.spp, args.seeds)
        cov = coverage_mask(sc)
        np.savez_compressed(OUT / f"{name}.npz", mean=mean.astype(np.float32), se=se.astype(np.float32),
                            coverage=cov.astype(np.float32), spp=args.spp, seeds=args.seeds,
                            max_depth=single_depth(sc))
        full = cov >= 1.0
        print(f"{name}: {time.perf_counter() - t:.1f} s, mean {mean[full].mean():.5g}, "
              f"median rel SE {np.median(se[full] / np.maximum(mean[full], 1e-30)):.3g}", flush=True)


if __name__ == "__main__":
    main()
