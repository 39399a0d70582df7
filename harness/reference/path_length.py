r"""How far the light travels inside a homogeneous sphere before the camera sees it: a photon tracer in NumPy.

Why it is here. SSLPV's propagation moves light by one cell per step: each step gathers a cell's
new radiance from its six face neighbours (Børlum et al. 2011, Sec. 3.2, after Kaplanyan and
Dachsbacher's LPV). After ``K`` steps the accumulated grid holds light that has crossed at most
``K`` cells. A lattice that models transport therefore delivers after ``K`` steps about the light
whose path inside the medium is at most ``K`` cells long; the rest needs more steps (or a lattice
that moves light faster than it travels, which is no longer a model of the medium). The truth's
**path-length distribution**, the share of the image's energy carried by paths of in-medium length
at most ``l``,

    F(l) = E(paths with length <= l) / E(all paths),                                        (P0)

therefore says how much of a scene's light a ``K``-step propagation can have delivered: ``F(K dx)``
at cell size ``dx``. :mod:`benchmarks.step_horizon` sets it beside SSLPV's own energy after ``K``
steps.

The scene: a homogeneous, index-matched sphere (a suite scene whose mesh is a sphere, with constant
``sigma_t``, albedo and ``g``), its point lights, its pinhole camera (``docs/conventions.md``).
Nothing here uses Mitsuba, the lattice or diffusion theory.

The estimator: light tracing with a next-event connection to the camera at every collision (particle
tracing, Veach 1997, Sec. 10.2), per colour channel:

* **Emission.** Each point light of intensity ``I`` emits ``n`` photons uniformly into the cone of
  directions that meets the sphere (half-angle ``asin(r / D)`` at distance ``D`` from the centre),
  each of power

      w0 = I Omega / n,   Omega = 2 pi (1 - cos theta_c).                                  (P1)

  Index-matched: a photon enters unrefracted where its ray meets the sphere.
* **Free flights** ``s = -ln(u) / sigma_t``. A flight longer than the distance to the surface leaves
  the sphere, and the photon is gone (nothing else is in the scene).
* **At a collision** ``x`` the camera at ``c`` receives the intensity scattered towards it,

      I_x = w albedo p_HG(omega . omega_c) exp(-sigma_t d_exit(x, omega_c)),                (P2)

  (collisions sampled with density ``sigma_t exp(-sigma_t s)``, so ``sigma_s / sigma_t`` = albedo),
  and the pixel ``j`` that ``x`` projects to gains, for a box filter over a film at unit distance,

      L_j += I_x / (|c - x|^2 A_pix cos^3 theta),                                          (P3)

  ``A_pix`` the film area of one pixel and ``theta`` the angle between the ray and the view axis
  (``d omega = cos^3 theta dA`` on the film). The connection's in-medium path length is the flights
  so far plus ``d_exit(x, omega_c)``.
* **Scattering.** ``w <- w albedo`` (implicit capture), a new direction from Henyey-Greenstein
  (:func:`harness.reference.random_walk.sample_hg`); Russian roulette below ``w0 / 1000`` (survive
  with probability 1/2 at twice the weight: unbiased).

Standard errors come from independent batches of photons (the ratio ``F`` by the delta method over
batch totals).

Validation (``tests/test_path_length.py``): the mean in-medium path length under uniform isotropic
incidence on a non-absorbing sphere is ``4 V / S = 4 r / 3`` whatever the scattering (the invariance
of Blanco and Fournier 2003, Bénichou et al. 2005); the image's energy against the committed Mitsuba
reference of ``backlit_sphere``; the projection (P3) against the camera's own rays.

Limits: a sphere only (the mesh is checked: its vertices must lie on one sphere and it must fill
:data:`ROUND` of it; the radius used is that of the sphere with the mesh's volume, so the faceted
icosphere's volume is kept); homogeneous
media only (a varying ``sigma_t``, albedo or ``g`` is refused); index-matched only (no refraction or
Fresnel); point lights only; the camera is outside the sphere. Single precision is never used.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from harness.errors import InputError
from harness.reference.mitsuba_scene import camera_frame
from harness.reference.random_walk import _turn, sample_hg

__all__ = ["PathLengths", "SphereScene", "sphere_scene", "constant_channels", "trace", "mean_path_isotropic", "hg", "project"]

#: Relative spread of the vertices' distances from their centroid that still counts as a sphere.
SPHERE_TOLERANCE = 1e-5
#: Least volume of the mesh, as a share of the sphere through its vertices (an icosphere of 3 subdivisions
#: has 0.991, of 4 0.998; a cube 0.368).
ROUND = 0.99
#: Relative spread of a medium grid that still counts as constant.
CONSTANT_TOLERANCE = 1e-6
#: Russian roulette below this fraction of a photon's emitted power.
ROULETTE = 1e-3


@dataclasses.dataclass(frozen=True)
class SphereScene:
    """What the tracer needs of a scene: the sphere, the medium per channel, lights and camera."""

    centre: np.ndarray          # (3,)
    radius: float               # of the sphere with the mesh's volume
    sigma_t: np.ndarray         # (3,)
    albedo: np.ndarray          # (3,)
    g: np.ndarray               # (3,)
    lights: tuple               # ((position (3,), intensity (3,)), ...)
    camera: object              # harness.scene.load.Camera


@dataclasses.dataclass(frozen=True)
class PathLengths:
    """One channel's tallies: the image, its energy over ``mask`` and the energy by path length.

    ``edges`` (scene units) bound ``hist``; ``hist[i]`` is the masked energy of paths with length in
    ``[edges[i], edges[i + 1])``, the last bin open above. ``share(l)`` is (P0).
    """

    image: np.ndarray           # (H, W)
    image_se: np.ndarray        # (H, W)
    energy: float               # sum over the mask
    energy_se: float
    edges: np.ndarray           # (B,)
    hist: np.ndarray            # (B,)
    batch_energy: np.ndarray    # (batches,)
    batch_hist: np.ndarray      # (batches, B)
    photons: int

    def share(self, length):
        """``F(length)`` (P0) and its standard error; ``length`` must be one of ``edges``."""
        i = int(np.searchsorted(self.edges, length))
        if i >= len(self.edges) or not np.isclose(self.edges[i], length):
            raise ValueError(f"{length} is not a bin edge")
        part = self.batch_hist[:, :i].sum(axis=1)
        return _ratio(part, self.batch_energy)


def _ratio(num, den):
    """Ratio of the means of per-batch ``num`` and ``den`` and its delta-method standard error."""
    num, den = np.asarray(num, float), np.asarray(den, float)
    r = num.mean() / den.mean()
    b = len(num)
    se = float(np.std(num - r * den, ddof=1) / math.sqrt(b) / den.mean()) if b > 1 else float("nan")
    return float(r), se


def hg(cos, g):
    """Henyey-Greenstein phase function per steradian, ``(1 - g^2) / (4 pi (1 + g^2 - 2 g cos)^1.5)``."""
    return (1.0 - g * g) / (4.0 * np.pi * (1.0 + g * g - 2.0 * g * cos) ** 1.5)


def constant_channels(grid, name, path, why="the path-length tracer models a homogeneous sphere"):
    """The one value per colour channel of the medium grid ``name``, or a one-line error (``why`` says what
    needs it constant) where it varies by more than :data:`CONSTANT_TOLERANCE`."""
    v = np.asarray(grid, np.float64).reshape(-1, 3)
    lo, hi = v.min(0), v.max(0)
    if np.any(hi - lo > CONSTANT_TOLERANCE * np.maximum(np.abs(hi), 1e-300)):
        raise InputError(path, f"medium.{name}", f"varies across the grid; {why}", "use a scene with a constant medium")
    return v[0].copy()


def sphere_scene(scene):
    """:class:`SphereScene` of a suite scene, or a one-line error naming what does not fit."""
    path = scene.path / "scene.toml" if scene.path is not None else scene.name
    if not scene.boundary.index_matched:
        raise InputError(path, "boundary.kind", f"is {scene.boundary.kind!r}; the path-length tracer has no "
                         "refraction", "use an index-matched scene")
    v = np.asarray(scene.mesh.vertices, np.float64)
    c = v.mean(axis=0)
    d = np.linalg.norm(v - c, axis=1)
    if d.max() - d.min() > SPHERE_TOLERANCE * d.mean():
        raise InputError(path, "mesh.kind", "is not a sphere (its vertices do not lie on one sphere)",
                         "use a scene whose mesh is a sphere")
    tri = v[np.asarray(scene.mesh.faces)] - c
    volume = abs(float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum())) / 6.0
    if volume < ROUND * 4.0 / 3.0 * np.pi * d.mean() ** 3:     # a cube's corners lie on a sphere too
        raise InputError(path, "mesh.kind", f"is not a sphere (its volume is {volume / (4.0 / 3.0 * np.pi * d.mean() ** 3):.3f} "
                         f"of the sphere through its vertices; at least {ROUND} is needed)",
                         "use a scene whose mesh is a sphere of 3 or more subdivisions")
    radius = (3.0 * volume / (4.0 * np.pi)) ** (1.0 / 3.0)
    lights = tuple((np.asarray(lt.position, np.float64), np.asarray(lt.intensity, np.float64))
                   for lt in scene.lights)
    for pos, _ in lights:
        if np.linalg.norm(pos - c) <= radius:
            raise InputError(path, "lights.position", "lies inside the sphere", "move the light outside")
    if np.linalg.norm(np.asarray(scene.camera.origin, np.float64) - c) <= radius:
        raise InputError(path, "camera.origin", "lies inside the sphere", "move the camera outside")
    med = scene.medium
    return SphereScene(c, radius, constant_channels(med.sigma_t, "sigma_t", path),
                       constant_channels(med.albedo, "albedo", path), constant_channels(med.g, "g", path), lights,
                       scene.camera)


def _exit(p, d, centre, radius):
    """Distance from ``p`` (inside) along unit ``d`` to the sphere's surface."""
    q = p - centre
    b = np.einsum("ij,ij->i", q, d)
    cc = np.einsum("ij,ij->i", q, q) - radius * radius
    return -b + np.sqrt(np.maximum(b * b - cc, 0.0))


def project(camera, x):
    """Pixel ``(ix, iy)`` (row 0 at the top; -1 outside the image) and ``cos theta`` of points ``x`` (n, 3).

    The inverse of the conventions' ray (``harness.reference.mitsuba_scene.camera_rays``).
    """
    o, fwd, right, up = camera_frame(camera)
    v = x - o
    z = v @ fwd
    t = math.tan(math.radians(camera.fov_y_deg) / 2.0)
    W, H = camera.width, camera.height
    with np.errstate(divide="ignore", invalid="ignore"):
        xn = (v @ right) / (z * t * (W / H))
        yn = (v @ up) / (z * t)
    px, py = (xn + 1.0) * 0.5 * W, (1.0 - yn) * 0.5 * H
    ok = (z > 0) & (px >= 0) & (px < W) & (py >= 0) & (py < H)
    ix = np.where(ok, np.floor(np.where(ok, px, 0)).astype(np.int64), -1)
    iy = np.where(ok, np.floor(np.where(ok, py, 0)).astype(np.int64), -1)
    return ix, iy, z / np.linalg.norm(v, axis=1)


def _emit(rng, n, light, centre, radius):
    """Entry points and directions of ``n`` photons from ``light`` uniform in the cone on the sphere; Omega."""
    axis = centre - light
    dist = np.linalg.norm(axis)
    axis = axis / dist
    cos_c = math.sqrt(1.0 - (radius / dist) ** 2)
    cos_t = 1.0 - rng.random(n) * (1.0 - cos_c)
    phi = 2.0 * np.pi * rng.random(n)
    d = np.stack(_turn(*(np.full(n, a) for a in axis), cos_t, phi), axis=1)
    q = light - centre
    b = d @ q
    t = -b - np.sqrt(np.maximum(b * b - (q @ q - radius * radius), 0.0))
    return light + t[:, None] * d, d, 2.0 * np.pi * (1.0 - cos_c)


def _walk(rng, p, d, w, sphere, sigma_t, albedo, g, on_collision=None, w_min=0.0):
    """Free flights, collisions and scattering until every photon has left or died.

    ``on_collision(p, d, w, ell)`` is called at each collision before the photon scatters. Returns the
    in-medium path lengths and weights of the photons as they leave.
    """
    ell = np.zeros(len(w))
    out_l, out_w = [], []
    while len(w):
        s = -np.log1p(-rng.random(len(w))) / sigma_t
        dex = _exit(p, d, sphere.centre, sphere.radius)
        leave = s >= dex
        out_l.append(ell[leave] + dex[leave])
        out_w.append(w[leave])
        keep = ~leave
        p, d, w, ell, s = p[keep] + s[keep, None] * d[keep], d[keep], w[keep], ell[keep] + s[keep], s[keep]
        if on_collision is not None and len(w):
            on_collision(p, d, w, ell)
        w = w * albedo
        cos_t = sample_hg(g, rng.random(len(w)))
        d = np.stack(_turn(d[:, 0], d[:, 1], d[:, 2], cos_t, 2.0 * np.pi * rng.random(len(w))), axis=1)
        if w_min > 0.0:
            low = w < w_min
            if low.any():
                live = ~low | (rng.random(len(w)) < 0.5)
                w = np.where(low, 2.0 * w, w)
                p, d, w, ell = p[live], d[live], w[live], ell[live]
    return np.concatenate(out_l), np.concatenate(out_w)


def trace(sphere, channel, edges, photons=1 << 17, batches=16, seed=0, mask=None):
    """Light-trace one colour ``channel`` of ``sphere``: :class:`PathLengths` (Eqs. P1-P3).

    ``edges`` are path lengths (scene units, ascending, from 0); ``photons`` per light in all,
    split into ``batches`` independent batches; ``mask`` (H, W) bool selects the pixels whose
    energy is tallied (None: all).
    """
    cam = sphere.camera
    H, W = cam.height, cam.width
    edges = np.asarray(edges, np.float64)
    mask = np.ones((H, W), bool) if mask is None else np.asarray(mask, bool)
    t = math.tan(math.radians(cam.fov_y_deg) / 2.0)
    a_pix = (2.0 * t * (W / H) / W) * (2.0 * t / H)
    o = np.asarray(cam.origin, np.float64)
    st, al, gg = float(sphere.sigma_t[channel]), float(sphere.albedo[channel]), float(sphere.g[channel])
    per = max(1, photons // batches)
    images = np.zeros((batches, H * W))
    hists = np.zeros((batches, len(edges)))
    rng = np.random.default_rng(np.random.SeedSequence([seed, channel]))
    for b in range(batches):
        def tally(p, d, w, ell, b=b):
            v = o - p
            dist = np.linalg.norm(v, axis=1)
            wc = v / dist[:, None]
            de = _exit(p, wc, sphere.centre, sphere.radius)
            ix, iy, cos = project(cam, p)
            ok = ix >= 0
            val = w * al * hg(np.einsum("ij,ij->i", d, wc), gg) * np.exp(-st * de) / (dist * dist * a_pix * cos ** 3)
            flat = iy[ok] * W + ix[ok]
            images[b] += np.bincount(flat, weights=val[ok], minlength=H * W)
            inside = mask.ravel()[flat]
            k = np.clip(np.searchsorted(edges, (ell + de)[ok][inside], side="right") - 1, 0, len(edges) - 1)
            hists[b] += np.bincount(k, weights=val[ok][inside], minlength=len(edges))

        for pos, inten in sphere.lights:
            p, d, omega = _emit(rng, per, pos, sphere.centre, sphere.radius)
            w0 = float(inten[channel]) * omega / per
            _walk(rng, p, d, np.full(per, w0), sphere, st, al, gg, on_collision=tally, w_min=ROULETTE * w0)
    images = images.reshape(batches, H, W)
    batch_energy = images[:, mask].sum(axis=1)
    return PathLengths(image=images.mean(0), image_se=images.std(0, ddof=1) / math.sqrt(batches),
                       energy=float(batch_energy.mean()),
                       energy_se=float(batch_energy.std(ddof=1) / math.sqrt(batches)),
                       edges=edges, hist=hists.mean(0), batch_energy=batch_energy, batch_hist=hists,
                       photons=per * batches)


def mean_path_isotropic(radius, sigma_t, g, photons=1 << 16, seed=0):
    """Mean in-medium path length (and its SE) of photons entering a non-absorbing sphere uniformly and
    isotropically (uniform points, cosine-weighted inward directions); ``4 r / 3`` by the invariance."""
    rng = np.random.default_rng(seed)
    n = int(photons)
    z = 1.0 - 2.0 * rng.random(n)
    phi = 2.0 * np.pi * rng.random(n)
    r_xy = np.sqrt(1.0 - z * z)
    normal = np.stack([r_xy * np.cos(phi), r_xy * np.sin(phi), z], axis=1)
    cos_t = np.sqrt(rng.random(n))                                  # cosine-weighted about the inward normal
    d = np.stack(_turn(-normal[:, 0], -normal[:, 1], -normal[:, 2], cos_t, 2.0 * np.pi * rng.random(n)), axis=1)
    sphere = SphereScene(np.zeros(3), float(radius), None, None, None, (), None)
    ell, _ = _walk(rng, radius * normal, d, np.ones(n), sphere, float(sigma_t), 1.0, float(g))
    return float(ell.mean()), float(ell.std(ddof=1) / math.sqrt(n))
