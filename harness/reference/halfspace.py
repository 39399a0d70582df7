"""Single scattering in a homogeneous half-space under a flat smooth interface, in plain NumPy.

An independent route to the image that ``mneevolpath`` (:mod:`harness.reference.mnee`)
renders when it is limited to single scattering (``max_depth = 4``): nothing here uses
Mitsuba, the manifold walk or its Jacobian.

Setup: the medium fills ``y < 0`` (relative index ``eta`` > 1 to the vacuum above), a
point light of intensity ``I`` (W/sr, RGB) at height ``h > 0`` above the interface and a
pinhole camera above it. For a camera ray that meets the interface at ``P`` with cosine
``cos_c``, the pixel sees (radiance leaving a medium of index eta is divided by eta^2)

    L = T(cos_c) / eta^2 * int_0^inf exp(-sigma_t s) sigma_s p(cos_phase) I T(cos_o)
        exp(-sigma_t l) E(s) ds,

along the refracted ray ``x(s) = P + s d_t``, where for the point ``x(s)`` at depth ``z``
and horizontal distance ``rho`` from the light's foot:

* the refraction point toward the light solves ``rho = z tan(th_i) + h tan(th_o)`` with
  ``sin(th_o) = eta sin(th_i)`` (one-dimensional by symmetry; solved by bisection, the
  left side rising monotonically in ``th_i`` on ``[0, asin(1/eta))``);
* ``l = z / cos(th_i)`` is the path inside the medium, ``T = 1 - F`` the unpolarised
  Fresnel transmittance (:func:`fresnel_transmittance`);
* ``E(s)`` is the irradiance per unit intensity on a plane perpendicular to the refracted
  light ray, from the ray tube leaving the light in ``[th_o, th_o + d th_o] x [phi, phi +
  d phi]``: power ``I sin(th_o) d th_o d phi`` lands on the horizontal area ``rho d rho
  d phi`` at depth ``z``, so ``E = sin(th_o) / (rho cos(th_i) d rho / d th_o)`` with
  ``d rho / d th_o = h / cos^2(th_o) + z / cos^2(th_i) * cos(th_o) / (eta cos(th_i))``;
* ``p`` is Henyey-Greenstein with the cosine between the light's direction of travel at
  ``x(s)`` and ``-d_t`` (toward the camera).

**A slab above the half-space** (the chain of three interfaces): a layer of the
same medium between heights ``a`` and ``a + b`` (``0 < a``, ``a + b < h``) with air on both
sides. The light's path leaves the slab's top, crosses it, leaves its bottom, crosses the
air gap and enters the half-space, and every interface is parallel, so the angles in the
medium (``th_i``) and in the air (``th_o``) are the same at all three: the horizontal
distance is ``rho = (z + b) tan(th_i) + (h - b) tan(th_o)``, the path inside the medium
``(z + b) / cos(th_i)``, the Fresnel transmittance ``T(cos th_o)^3``, and the ray tube's
irradiance is the half-space's with ``z -> z + b`` and ``h -> h - b`` (the tube spreads
according to the length travelled in each medium only). The slab covers only part of the
plane (:data:`SLAB_SETUP`); :func:`slab_outside_share` says how much of the integral's
weight has its chain outside it (it must be negligible for the comparison to hold).
Internal reflections inside the slab are left out, as they are by ``mneevolpath``.

The integral over ``s`` is Gauss-Legendre in ``u = 1 - exp(-sigma_ref s)``; pixels are
averaged over ``sub x sub`` stratified rays (box filter, as the reference's film).
:func:`image` has switches that plant the errors the validation test must catch.
"""

import dataclasses

import numpy as np

from harness.reference.mitsuba_scene import camera_rays
from harness.scene import Boundary, Camera, Medium, PointLight, Scene, scene_hash
from harness.scene.geometry import BoxMesh, Mesh, build_mesh

#: The validation setup: a camera looking down at the interface y = 0 at about 40 degrees, a
#: point light to the back left, a chromatic medium (sigma_t per colour, HG g = 0.3). The
#: half-space is a 12 x 4 x 12 box (a camera ray reaches depth 4 with transmittance <= e^-4 and
#: the light's path back adds as much again: the finite box changes the image by < 1e-6).
SETUP = {"origin": (0.0, 1.5, 1.8), "target": (0.0, 0.0, 0.0), "fov_y": 40.0,
         "light": (-1.2, 0.6, 1.0), "intensity": (2.0, 2.0, 2.0),
         "sigma_t": (1.0, 1.6, 2.4), "albedo": (0.8, 0.7, 0.6), "g": 0.3,
         "half_width": 6.0, "depth": 4.0}


#: The slab validation (three interfaces): the light moved up and toward the camera's side, a slab
#: of the same medium between y = 2.0 and 2.5 over z in [0, 6] (the camera at y = 1.5 below it
#: sees only the half-space; the camera rays the half-space reflects rise toward z < -0.2 and miss
#: it), brighter for the longer way.
SLAB_SETUP = dict(SETUP, light=(-1.2, 3.2, 3.0), intensity=(24.0, 24.0, 24.0), slab=(2.0, 0.5, 0.0, 6.0))


def _slab_box(setup):
    a, b, z0, z1 = setup["slab"]
    w = setup["half_width"]
    return build_mesh(BoxMesh(kind="box", size=[2 * w, b, z1 - z0], center=[0.0, a + b / 2, (z0 + z1) / 2]), None)


def validation_scene(eta, size=24, setup=SETUP):
    """The :data:`SETUP` half-space as a harness :class:`~harness.scene.Scene` behind a smooth dielectric.

    ``eta = 1`` gives the index-matched scene. The medium is a one-voxel constant grid
    (so the reference renders it as ``heterogeneous``, with null collisions and ratio
    tracking); the box is flat-shaded, its top face the interface.
    """
    w, depth = setup["half_width"], setup["depth"]
    mesh = build_mesh(BoxMesh(kind="box", size=[2 * w, depth, 2 * w], center=[0.0, -depth / 2, 0.0]), None)
    if "slab" in setup:       # one closed mesh of two components: one shape, one medium
        slab = _slab_box(setup)
        mesh = Mesh(np.concatenate([mesh.vertices, slab.vertices]),
                    np.concatenate([mesh.faces, slab.faces + len(mesh.vertices)]).astype(np.int32),
                    np.concatenate([mesh.normals, slab.normals]))
    cam = Camera(origin=setup["origin"], target=setup["target"], up=(0.0, 1.0, 0.0), fov_y_deg=setup["fov_y"],
                 width=int(size), height=int(size))

    def grid(v):
        return np.broadcast_to(np.asarray(v, np.float32), (1, 1, 1, 3)).copy()

    medium = Medium(np.full(3, -w), np.full(3, w), grid(setup["sigma_t"]), grid(setup["albedo"]),
                    grid([setup["g"]] * 3))
    boundary = Boundary("index-matched") if eta == 1.0 else Boundary("dielectric", float(eta), 0.0)
    scene = Scene(name="halfspace", path=None, units="cm", description="single-scattering validation half-space",
                  mesh=mesh, camera=cam, lights=(PointLight(setup["light"], setup["intensity"]),),
                  boundary=boundary, medium=medium)
    return dataclasses.replace(scene, content_hash=scene_hash(scene))


def setup_image(scene, setup=SETUP, **kwargs):
    """:func:`image` of a :func:`validation_scene` (its camera, light, eta and medium; ``setup``'s slab)."""
    m, light = scene.medium, scene.lights[0]
    if "slab" in setup:
        kwargs.setdefault("slab", setup["slab"][:2])
    return image(scene.camera, light.position, light.intensity, scene.boundary.eta, m.sigma_t[0, 0, 0],
                 m.albedo[0, 0, 0], float(m.g[0, 0, 0, 0]), **kwargs)


def fresnel_transmittance(cos_outside, eta):
    """1 - F for unpolarised light crossing a smooth interface, ``cos_outside`` on the vacuum side."""
    c = np.clip(np.abs(cos_outside), 0.0, 1.0)
    sin_t = np.sqrt(1.0 - c * c) / eta
    cos_t = np.sqrt(np.maximum(1.0 - sin_t * sin_t, 0.0))
    rs = (c - eta * cos_t) / (c + eta * cos_t)
    rp = (eta * c - cos_t) / (eta * c + cos_t)
    return 1.0 - 0.5 * (rs * rs + rp * rp)


def henyey_greenstein(cos_theta, g):
    """HG phase function of the cosine between the directions of travel before and after scattering."""
    return (1.0 - g * g) / (4.0 * np.pi * (1.0 + g * g - 2.0 * g * cos_theta) ** 1.5)


def refraction_angle(rho, z, h, eta, iterations=24):
    """Inside angle ``th_i`` with ``rho = z tan(th_i) + h tan(th_o)``, ``sin(th_o) = eta sin(th_i)``.

    The left side rises monotonically on ``[0, asin(1/eta))``: Newton's method inside a
    shrinking bracket (a bisection step whenever Newton would leave it).
    """
    lo = np.zeros_like(rho)
    hi = np.full_like(rho, np.arcsin(1.0 / eta) * (1 - 1e-12))
    th = np.arctan2(rho, z + eta * h) * 0 + 0.5 * hi
    for _ in range(iterations):
        s_o = eta * np.sin(th)
        c_o = np.sqrt(1.0 - s_o * s_o)
        f = z * np.tan(th) + h * s_o / c_o - rho
        df = z / np.cos(th) ** 2 + h * eta * np.cos(th) / c_o ** 3
        lo = np.where(f < 0, th, lo)
        hi = np.where(f < 0, hi, th)
        nxt = th - f / df
        th = np.where((nxt > lo) & (nxt < hi), nxt, 0.5 * (lo + hi))
    return th


def image(camera, light_pos, intensity, eta, sigma_t, albedo, g, sub=8, nodes=96, fresnel_light=True,
          geometry="tube", chunk=4096, slab=None, fresnel_count=None):
    """Single-scattering image (H, W, 3) of the half-space ``y < 0`` (see the module docstring).

    ``slab = (a, b)`` adds the slab between heights ``a`` and ``a + b`` (three interfaces).
    ``fresnel_light=False`` drops the Fresnel factor at the light's refraction,
    ``fresnel_count`` sets how many Fresnel factors the light's path gets (default 1, or 3
    with a slab) and ``geometry="straight"`` replaces the irradiance of the refracted ray
    tube by the inverse square of the straight distance to the light: the planted errors of
    the tests.
    """
    sigma_t = np.asarray(sigma_t, float)
    albedo = np.asarray(albedo, float)
    intensity = np.asarray(intensity, float)
    light = np.asarray(light_pos, float)
    h = light[1]
    if h <= 0:
        raise ValueError("halfspace.image: the light must lie above the interface (y > 0)")
    b = 0.0 if slab is None else float(slab[1])
    if slab is not None and not (0 < slab[0] and slab[0] + b < h):
        raise ValueError("halfspace.image: the slab must lie between the interface and the light")
    if fresnel_count is None:
        fresnel_count = 1 if slab is None else 3
    grid = (np.arange(sub) + 0.5) / sub
    offsets = np.stack(np.meshgrid(grid, grid, indexing="xy"), -1).reshape(-1, 2)
    o, d = camera_rays(camera, offsets)                        # (H, W, S, 3)
    H, W, S, _ = d.shape
    d = d.reshape(-1, 3)
    down = d[:, 1] < 0
    t_hit = np.where(down, -o[1] / np.where(down, d[:, 1], -1.0), np.nan)
    p_hit = np.where(down[:, None], o + np.nan_to_num(t_hit)[:, None] * d, 0.0)
    cos_c = -d[:, 1]
    # Refracted camera ray (normal +y): d_t = d / eta + (cos_c / eta - cos_t) n.
    cos_t = np.sqrt(np.maximum(1.0 - (1.0 - cos_c ** 2) / eta ** 2, 0.0))
    d_t = d / eta
    d_t[:, 1] += cos_c / eta - cos_t
    d_t /= np.linalg.norm(d_t, axis=1, keepdims=True)

    sigma_ref = sigma_t.min()
    xu, wu = np.polynomial.legendre.leggauss(nodes)
    u = 0.5 * (xu + 1.0)
    wu = 0.5 * wu
    s = -np.log1p(-u) / sigma_ref                               # (N,)
    ds_du = 1.0 / (sigma_ref * (1.0 - u))

    L = np.zeros((len(d), 3))
    for lo in range(0, len(d), chunk):                          # bounded memory: rays in chunks
        sl = slice(lo, lo + chunk)
        L[sl] = _along_rays(p_hit[sl], d_t[sl], s, ds_du * wu, light, h, eta, sigma_t, albedo, g, intensity,
                            fresnel_light, geometry, b, fresnel_count)
    L *= (fresnel_transmittance(cos_c, eta) / eta ** 2)[:, None]
    L[~down] = 0.0
    return L.reshape(H, W, S, 3).mean(axis=2)


def _along_rays(p_hit, d_t, s, weights, light, h, eta, sigma_t, albedo, g, intensity, fresnel_light, geometry,
                b=0.0, fresnel_count=1):
    """The integral over s of the in-scattered light for refracted rays ``p_hit + s d_t`` (R, 3) -> (R, 3).

    ``b``: the slab's thickness (the chain through three interfaces: ``z -> z + b``, ``h -> h - b``)."""
    x = p_hit[:, None, :] + s[None, :, None] * d_t[:, None, :]  # (R, N, 3)
    z = -x[..., 1] + b
    h = h - b
    foot = x[..., [0, 2]] - light[[0, 2]]
    rho = np.linalg.norm(foot, axis=-1)
    th_i = refraction_angle(rho, z, h, eta)
    sin_i, cos_i = np.sin(th_i), np.cos(th_i)
    sin_o = eta * sin_i
    cos_o = np.sqrt(np.maximum(1.0 - sin_o ** 2, 0.0))
    path_in = z / cos_i
    if geometry == "tube":
        drho = h / cos_o ** 2 + z / cos_i ** 2 * cos_o / (eta * cos_i)
        e_perp = sin_o / (np.maximum(rho, 1e-300) * cos_i * drho)
    elif geometry == "straight":
        e_perp = 1.0 / np.sum((x - light) ** 2, axis=-1)
    else:
        raise ValueError(f"halfspace.image: unknown geometry {geometry!r}")
    # Direction of travel of the refracted light at x(s): away from the light's foot, downward.
    e_h = foot / np.maximum(rho, 1e-300)[..., None]
    travel = np.stack([sin_i * e_h[..., 0], -cos_i, sin_i * e_h[..., 1]], axis=-1)
    cos_phase = np.einsum("rnk,rk->rn", travel, -d_t)
    phase = henyey_greenstein(cos_phase, g)
    t_light = fresnel_transmittance(cos_o, eta) ** fresnel_count if fresnel_light else np.ones_like(cos_o)
    geo = phase * t_light * e_perp * weights[None, :]           # (R, N)
    out = np.empty((len(p_hit), 3))
    for c in range(3):
        att = np.exp(-sigma_t[c] * (s[None, :] + path_in))
        out[:, c] = (geo * att).sum(axis=1) * sigma_t[c] * albedo[c] * intensity[c]
    return out


def slab_outside_share(scene, setup=SLAB_SETUP, sub=2, nodes=32):
    """Share of the single-scattering integral whose chain crosses the slab's planes outside its footprint.

    The crossing of the slab's bottom at height ``a`` lies ``z tan(th_i) + a tan(th_o)``
    from ``x(s)`` toward the light's foot (and its top farther on); a chain outside the slab's
    ``z`` range (``SLAB_SETUP["slab"][2:]``) is not the three-interface chain of :func:`image`.
    Weighted by the attenuation of the first channel.
    """
    a, b, z0, z1 = setup["slab"]
    light = np.asarray(setup["light"], float)
    eta = scene.boundary.eta
    grid = (np.arange(sub) + 0.5) / sub
    o, d = camera_rays(scene.camera, np.stack(np.meshgrid(grid, grid, indexing="xy"), -1).reshape(-1, 2))
    d = d.reshape(-1, 3)
    d = d[d[:, 1] < 0]
    p = o + (-o[1] / d[:, 1])[:, None] * d
    cos_c = -d[:, 1]
    cos_t = np.sqrt(1.0 - (1.0 - cos_c ** 2) / eta ** 2)
    d_t = d / eta
    d_t[:, 1] += cos_c / eta - cos_t
    d_t /= np.linalg.norm(d_t, axis=1, keepdims=True)
    st = float(np.min(setup["sigma_t"]))
    u = (np.arange(nodes) + 0.5) / nodes
    s = -np.log1p(-u) / st
    x = p[:, None, :] + s[None, :, None] * d_t[:, None, :]
    z = -x[..., 1]
    foot = x[..., [0, 2]] - light[[0, 2]]
    rho = np.linalg.norm(foot, axis=-1)
    th_i = refraction_angle(rho, z + b, light[1] - b, eta)
    th_o = np.arcsin(eta * np.sin(th_i))
    toward = -foot / np.maximum(rho, 1e-300)[..., None]
    out = np.zeros(z.shape, bool)
    for run in (z * np.tan(th_i) + a * np.tan(th_o), (z + b) * np.tan(th_i) + a * np.tan(th_o)):
        zc = x[..., 2] + toward[..., 1] * run
        out |= (zc < z0) | (zc > z1)
    w = np.exp(-st * (z + b) / np.cos(th_i))
    return float((w * out).sum() / w.sum())


def reflected_irradiance(points, light_pos, intensity, eta, sigma_t, thickness, fresnel="reflect", ceiling=None):
    """Irradiance per point (P, 3) at ``points`` (P, 3) inside a slab ``-thickness < y < 0`` (flat smooth
    faces, air above and below) from a point light above it, along the light path that enters the top
    face, reflects off the bottom face inside and reaches the point (the photon label ``ER``); with
    ``ceiling = H`` (the flat lower face ``y = H`` of another dielectric part above the light), along the path
    that reflects off that face outside, then enters the top face (``rE``).

    The bottom face mirrors the point to depth ``2 thickness - z``: the path is the half-space's single
    refraction to the mirror point (every angle in the medium is the same at both faces), so the ray
    tube's irradiance is the half-space's at that depth (module docstring) times the Fresnel
    transmittance at the top, the Fresnel reflectance at the bottom (the same angles, so ``1 - T``:
    below the critical angle inside), and the transmittance along ``(2 thickness - z) / cos th_i``.
    The ceiling mirrors the light instead, to height ``2 H - h``: the half-space's single refraction from
    the mirrored light, times the Fresnel reflectance at the ceiling, whose angle in air is the top face's
    (``1 - T`` again). Another route to the value of ``mneevolpath``'s reflection chains ``("R", "T")``
    and ``("T", "r")`` (:mod:`harness.reference.mnee_sms`). ``fresnel = "transmit"`` plants the error of a
    reflection weighted by the transmittance.
    """
    pts = np.asarray(points, float)
    light = np.asarray(light_pos, float)
    if ceiling is None:
        h = light[1]
        z = 2.0 * thickness + pts[:, 1]                        # the mirror point's depth
    else:
        h = 2.0 * float(ceiling) - light[1]                    # the mirrored light's height
        z = -pts[:, 1]
    rho = np.linalg.norm(pts[:, [0, 2]] - light[[0, 2]], axis=1)
    th_i = refraction_angle(rho, z, h, eta)
    sin_i, cos_i = np.sin(th_i), np.cos(th_i)
    cos_o = np.sqrt(np.maximum(1.0 - (eta * sin_i) ** 2, 0.0))
    drho = h / cos_o ** 2 + z / cos_i ** 2 * cos_o / (eta * cos_i)
    e_perp = eta * sin_i / (np.maximum(rho, 1e-300) * cos_i * drho)
    t = fresnel_transmittance(cos_o, eta)
    bottom = 1.0 - t if fresnel == "reflect" else t
    att = np.exp(-np.asarray(sigma_t, float)[None, :] * (z / cos_i)[:, None])
    return (np.asarray(intensity, float)[None, :] * (e_perp * t * bottom)[:, None]) * att
