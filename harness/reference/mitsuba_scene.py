"""Build Mitsuba 3's description of a :class:`harness.scene.Scene` (the ground truth's input).

One function, :func:`build_scene_dict`, turns the validated scene object into a
``mi.load_dict`` dictionary. The choices it makes, and why:

=====================  ======================================================================
part                   Mitsuba plugin and settings
=====================  ======================================================================
object                 ``mi.Mesh`` from the scene's vertices, faces and vertex normals
interior medium        ``heterogeneous``; ``sigma_t`` and ``albedo`` are ``gridvolume`` from
                       the scene's ``(nz, ny, nx, 3)`` grids, ``scale = 1``, ``to_world`` =
                       translate(bbox_min) * scale(bbox_max - bbox_min): voxel ``(i, j, k)``
                       is centred at ``bbox_min + (idx + 0.5)/n * (bbox_max - bbox_min)``, the
                       convention of ``docs/conventions.md`` (tested in
                       ``tests/test_reference_validation.py``)
grid filter            ``nearest``: the reference sees exactly the scene's voxels, the same
                       piecewise-constant field the numpy checks integrate. Trilinear would
                       smooth the field and shift its values near the box faces.
phase function         stock ``hg`` when g is one constant, else ``gridhg``
                       (:mod:`harness.reference.phase`) with the channel mean of g
boundary               index-matched: ``null`` BSDF. Smooth dielectric (``roughness = 0``):
                       ``dielectric``, ``int_ior = eta``, ``ext_ior = 1``, exact (see
                       :data:`SMOOTH_DIELECTRIC_NOTE`). Rough dielectric: ``roughdielectric``,
                       GGX, ``alpha = roughness``, ``int_ior = eta``, ``ext_ior = 1`` (see
                       :data:`DIELECTRIC_NOTE`)
camera                 ``perspective``, ``fov_axis = "y"``, ``to_world = look_at(...)``,
                       ``hdrfilm`` RGB with a **box** filter (a pixel is the plain average over
                       its footprint, so seeds give independent, unweighted estimates)
sampler                ``independent`` (seeded per render)
integrator             ``volpath``, ``max_depth = -1`` (unbounded: no truncation bias),
                       ``rr_depth`` from the medium's largest albedo (:func:`rr_depth_for`, below);
                       a smooth dielectric boundary: ``mneevolpath``
                       (:mod:`harness.reference.mnee`, manifold next-event estimation through
                       the interface) with the same depths and :data:`MNEE_PARAMS`
colour channels        one pass per channel (σt and albedo of that channel on all three) when
                       σt differs between channels (:func:`channel_passes`, below)
lights                 ``point``, RGB intensity in W/sr; background black (no environment)
=====================  ======================================================================

Long paths: Russian roulette and spectral tracking
--------------------------------------------------
Both choices below were measured on ``marble_sphere`` (Jensen et al. 2001's marble, albedo
0.998-0.999, 263-360 mean free paths across) with ``benchmarks/bench_path_depth.py``.

* Russian roulette. Past ``rr_depth`` Mitsuba's ``volpath`` continues a path with probability
  ``q = min(max(throughput) * eta^2, 0.95)``: the 0.95 cap kills at least 5 % of the paths per
  bounce whatever the albedo, and divides the survivors' weight by 0.95, so a path of n bounces
  past ``rr_depth`` is sampled with probability 0.95^n and weight 1/0.95^n. Unbiased in
  expectation, but in a medium where most of the light has travelled hundreds to thousands of
  bounces the energy sits in events too rare to be sampled: with Mitsuba's default
  ``rr_depth = 5`` the marble came out 3.7-7.4 % dark (per channel), far outside its seed-to-seed
  standard error, which cannot see it. The harness therefore starts Russian roulette only where
  every path has lost most of its weight to absorption: ``rr_depth = ceil(ln(RR_WEIGHT) /
  ln(albedo_max))`` with ``RR_WEIGHT = 0.1`` (at least Mitsuba's 5; 230 for albedo 0.99, 2403 for
  the marble's red channel; :data:`RR_DEPTH_CAP` when the albedo is 1). On the marble, energy
  stopped changing (within 0.02 %) from a hard depth cap of 3000 up, and a cap of 1000 was 0.5 %
  dark: nothing is truncated that the reference's noise could show. On the suite's
  ``sphere_homogeneous`` (16 mean free paths across) the default and the rule agree within
  0.2 % and cost the same per unit of noise.
* Spectral tracking. With a σt that differs between channels, ``volpath`` samples distances with
  one (hero) channel and weights the other channels by ratios of coefficients, a product over
  every collision: for long paths it collapses to zero or explodes (on the marble the blue
  channel's energy stopped growing after 100 bounces while the red one's error grew to 19 %).
  Such a medium is rendered as three grey passes instead, each with one channel's σt and albedo,
  from which only that channel is kept; each pass is then an exact single-channel problem.
"""

import math

import numpy as np

from harness.errors import InputError
from harness.reference.llvm import ensure_libllvm

DEFAULT_VARIANT = "llvm_ad_rgb"
SUPPORTED_VARIANTS = ("llvm_ad_rgb", "cuda_ad_rgb", "scalar_rgb")
MAX_DEPTH = -1
RR_DEPTH = 5              # Mitsuba's default, the least rr_depth the rule below gives
RR_WEIGHT = 0.1           # Russian roulette starts once albedo_max ** depth <= this
RR_DEPTH_CAP = 1 << 16    # rr_depth for a non-absorbing medium (albedo 1): paths end by leaving it
GRID_FILTER = "nearest"

DIELECTRIC_NOTE = (
    "approximation: stock Mitsuba 3 cannot connect a point light through a smooth dielectric "
    "(delta light through a delta interface renders black), so the boundary is a GGX roughdielectric "
    "with alpha = boundary.roughness, int_ior = eta, ext_ior = 1; next-event estimation from medium "
    "vertices is disabled (sample_emitters=False) because the interface blocks it anyway "
    "(../shared/NOTES.md: same image, 4x faster)"
)
SMOOTH_DIELECTRIC_NOTE = (
    "exact: smooth dielectric (Mitsuba 'dielectric', int_ior = eta, ext_ior = 1) rendered with mneevolpath, "
    "volumetric path tracing plus manifold next-event estimation from every medium vertex to every point light "
    "through the interface (Hanika et al. 2015); not covered, and lost (the image can only be darker): "
    "connections crossing the interface more than once, further solutions of the constraint, failed walks "
    "(harness/reference/mnee.py)"
)
INDEX_MATCHED_NOTE = "exact: index-matched boundary rendered with a null BSDF"
#: Manifold-walk settings of the smooth-dielectric references, passed explicitly (recorded in reference.json).
MNEE_PARAMS = {"newton_iterations": 32, "newton_tolerance": 1e-5, "ratio_tracking_scale": 2.0}
RGB_G_NOTE = ("Mitsuba RGB variants trace one direction per path for all channels: the phase function uses "
              "the mean of the three channels of g")


# --------------------------------------------------------------------------- variant

def use_variant(variant=None):
    """Select a Mitsuba variant (default ``llvm_ad_rgb``), register ``gridhg``, return the module.

    Raises :class:`InputError` when the variant is unknown or cannot start on this
    machine (for example ``cuda_ad_rgb`` without an NVIDIA GPU).
    """
    variant = variant or DEFAULT_VARIANT
    if variant not in SUPPORTED_VARIANTS:
        raise InputError("variant", "variant", f"unsupported Mitsuba variant {variant!r}",
                         f"use one of: {', '.join(SUPPORTED_VARIANTS)}")
    if variant.startswith("llvm"):
        try:
            ensure_libllvm()
        except RuntimeError as exc:
            raise InputError("variant", variant, str(exc).split(";")[0], str(exc).split("; ", 1)[-1]) from exc
    import mitsuba as mi

    try:
        mi.set_variant(variant)
        if variant.startswith("cuda"):
            import drjit as dr

            if not dr.has_backend(dr.JitBackend.CUDA):
                raise RuntimeError("no CUDA device")
    except (ImportError, AttributeError, RuntimeError) as exc:
        raise InputError("variant", variant, f"is not available on this machine ({exc})",
                         "use variant llvm_ad_rgb (CPU), or run on a machine with an NVIDIA GPU and driver") from exc
    from . import mnee, phase

    phase.register()
    mnee.register()
    return mi


# --------------------------------------------------------------------------- pieces

def grid_to_world(bbox_min, bbox_max):
    """The unit cube -> the medium box: translate(bbox_min) * scale(bbox_max - bbox_min)."""
    import mitsuba as mi

    lo = [float(v) for v in bbox_min]
    ext = [float(b) - float(a) for a, b in zip(bbox_min, bbox_max)]
    return mi.ScalarTransform4f().translate(lo).scale(ext)


def grid_volume(grid, bbox_min, bbox_max, filter_type=GRID_FILTER):
    """A ``gridvolume`` dict for a ``(nz, ny, nx, C)`` array over the medium box."""
    import mitsuba as mi

    arr = np.ascontiguousarray(grid, dtype=np.float32)
    if arr.ndim != 4 or arr.shape[3] not in (1, 3):
        raise ValueError(f"grid_volume: expected (nz, ny, nx, 1|3), got {arr.shape}")
    return {"type": "gridvolume", "grid": mi.VolumeGrid(arr), "filter_type": filter_type,
            "to_world": grid_to_world(bbox_min, bbox_max)}


def phase_g_grid(medium):
    """The single-channel g grid handed to ``gridhg`` (channel mean) and the largest channel spread."""
    g = np.asarray(medium.g, dtype=np.float64)
    mean = g.mean(axis=3, keepdims=True)
    spread = float(np.abs(g - mean).max()) if g.size else 0.0
    return mean.astype(np.float32), spread


def phase_dict(medium, phase="auto", filter_type=GRID_FILTER):
    """``hg`` for a constant (grey) g, else ``gridhg``; ``phase`` forces ``"hg"`` or ``"gridhg"``."""
    g1, _ = phase_g_grid(medium)
    constant = bool(np.all(g1 == g1.flat[0]))
    if phase == "auto":
        phase = "hg" if constant else "gridhg"
    if phase == "hg":
        if not constant:
            raise ValueError("phase_dict: stock hg needs a constant g; use phase='gridhg'")
        return {"type": "hg", "g": float(g1.flat[0])}
    if phase == "gridhg":
        return {"type": "gridhg",
                "g": grid_volume(g1, medium.bbox_min, medium.bbox_max, filter_type)}
    raise ValueError(f"phase_dict: unknown phase {phase!r}; use auto, hg or gridhg")


def medium_dict(scene, albedo_override=None, phase="auto", filter_type=GRID_FILTER, sample_emitters=None):
    """The ``heterogeneous`` interior medium of the object.

    ``sample_emitters`` (next-event estimation from medium vertices) defaults to
    True for an index-matched and a smooth dielectric boundary (where ``mneevolpath``
    connects through the interface) and False for a rough dielectric one.
    """
    m = scene.medium
    albedo = m.albedo if albedo_override is None else np.broadcast_to(
        np.asarray(albedo_override, dtype=np.float32), m.albedo.shape)
    return {
        "type": "heterogeneous",
        "sigma_t": grid_volume(m.sigma_t, m.bbox_min, m.bbox_max, filter_type),
        "albedo": grid_volume(albedo, m.bbox_min, m.bbox_max, filter_type),
        "scale": 1.0,
        # NEE from inside a rough boundary is always occluded: skip it (see DIELECTRIC_NOTE).
        "sample_emitters": bool(not rough_dielectric(scene.boundary) if sample_emitters is None else sample_emitters),
        "phase": phase_dict(m, phase, filter_type),
    }


def smooth_dielectric(boundary):
    """A dielectric boundary with roughness 0: rendered exactly by ``mneevolpath``."""
    return not boundary.index_matched and float(boundary.roughness) == 0.0


def smooth_suite_scenes():
    """The names of the suite's scenes behind a smooth dielectric boundary (:func:`smooth_dielectric`)."""
    from harness.scene import list_scenes, load_scene

    return [n for n in list_scenes() if smooth_dielectric(load_scene(n).boundary)]


def rough_dielectric(boundary):
    """A dielectric boundary with roughness > 0: the GGX approximation of :data:`DIELECTRIC_NOTE`."""
    return not boundary.index_matched and float(boundary.roughness) > 0.0


def bsdf_dict(boundary):
    if boundary.index_matched:
        return {"type": "null"}
    if smooth_dielectric(boundary):
        return {"type": "dielectric", "int_ior": float(boundary.eta), "ext_ior": 1.0}
    return {"type": "roughdielectric", "distribution": "ggx", "alpha": float(boundary.roughness),
            "int_ior": float(boundary.eta), "ext_ior": 1.0}


def absorber_is_black(scene):
    """Why the albedo-0 image is exactly zero for ``scene`` (no surface light reaches the camera), or None.

    Point lights and a black background: a null boundary reflects nothing, and a smooth
    dielectric reflects a delta light only into a set of directions of measure zero, so
    without scattering in the medium no light reaches the pinhole camera.
    """
    if scene.boundary.index_matched:
        return "index-matched null boundary, black background, point lights only"
    if smooth_dielectric(scene.boundary):
        return ("smooth dielectric: the specular reflection of a point light is never seen by a pinhole camera; "
                "black background, point lights only")
    return None


def mitsuba_mesh(mesh, bsdf=None, interior=None, name="object"):
    """An ``mi.Mesh`` with the scene's positions, faces and vertex normals (and optional BSDF/medium)."""
    import mitsuba as mi

    props = mi.Properties()
    if bsdf is not None:
        props["bsdf"] = mi.load_dict(bsdf)
    if interior is not None:
        props["interior"] = mi.load_dict(interior)
    out = mi.Mesh(name, len(mesh.vertices), len(mesh.faces), props, has_vertex_normals=True)
    params = mi.traverse(out)
    params["vertex_positions"] = mi.Float(np.ascontiguousarray(mesh.vertices, np.float32).ravel())
    params["faces"] = mi.UInt32(np.ascontiguousarray(mesh.faces, np.uint32).ravel())
    params["vertex_normals"] = mi.Float(np.ascontiguousarray(mesh.normals, np.float32).ravel())
    params.update()
    return out


def sensor_dict(camera, spp=1):
    import mitsuba as mi

    return {
        "type": "perspective",
        "fov_axis": "y",
        "fov": float(camera.fov_y_deg),
        "to_world": mi.ScalarTransform4f().look_at(origin=list(map(float, camera.origin)),
                                                   target=list(map(float, camera.target)),
                                                   up=list(map(float, camera.up))),
        "film": {"type": "hdrfilm", "width": int(camera.width), "height": int(camera.height),
                 "pixel_format": "rgb", "component_format": "float32", "rfilter": {"type": "box"}},
        "sampler": {"type": "independent", "sample_count": int(spp)},
    }


def light_dicts(lights):
    return {f"light_{i}": {"type": "point", "position": list(map(float, lt.position)),
                           "intensity": {"type": "rgb", "value": list(map(float, lt.intensity))}}
            for i, lt in enumerate(lights)}


def rr_depth_for(albedo_max, weight=RR_WEIGHT):
    """Depth at which Russian roulette starts: the first ``n`` with ``albedo_max ** n <= weight``.

    A path that has scattered ``n`` times carries at most ``albedo_max ** n`` of its weight, so
    Mitsuba's capped roulette (survival <= 0.95 per bounce) only ever shortens paths that have
    already lost all but ``weight`` of it (see the module docstring). At least :data:`RR_DEPTH`;
    :data:`RR_DEPTH_CAP` for ``albedo_max >= 1``.
    """
    a = float(albedo_max)
    if not a < 1.0:
        return RR_DEPTH_CAP
    if a <= 0.0:
        return RR_DEPTH
    return int(min(RR_DEPTH_CAP, max(RR_DEPTH, math.ceil(math.log(weight) / math.log(a)))))


def channel_passes(medium):
    """``(None,)`` for a medium whose σt is the same in every channel, else ``(0, 1, 2)``.

    ``None`` is one RGB pass; ``c`` is a grey pass with channel ``c``'s σt and albedo on all
    three channels, of which only channel ``c`` is kept (spectral tracking is unstable for
    long paths; module docstring).
    """
    st = np.asarray(medium.sigma_t)
    return (None,) if np.all(st == st[..., :1]) else (0, 1, 2)


def grey_medium_scene(scene, channel):
    """``scene`` with channel ``channel``'s σt and albedo copied to all three channels."""
    m = scene.medium
    return scene.with_medium(sigma_t=np.repeat(m.sigma_t[..., channel:channel + 1], 3, axis=3),
                             albedo=np.repeat(m.albedo[..., channel:channel + 1], 3, axis=3))


def integrator_dict(scene, albedo_override=None, channel=None, max_depth=MAX_DEPTH, rr_depth=None, part=None):
    """The integrator of ``scene`` (a pass's albedo override and colour channel): ``volpath``, or
    ``mneevolpath`` with :data:`MNEE_PARAMS` behind a smooth dielectric; ``rr_depth`` defaults to
    :func:`rr_depth_for` the pass's largest albedo. ``part`` splits a scene with specular manifold
    sampling into two images whose sum has the whole's expectation: ``"rest"`` (sampling off) and
    ``"sampled"`` (only the sampled solutions' light, ``sms_only``); None renders the whole."""
    if part not in (None, "rest", "sampled"):
        raise ValueError(f"integrator_dict: part = {part!r} must be None, 'rest' or 'sampled'")
    if rr_depth is None:
        if albedo_override is not None:
            a = float(np.max(albedo_override))
        else:
            alb = np.asarray(scene.medium.albedo)
            a = float(alb.max() if channel is None else alb[..., channel].max())
        rr_depth = rr_depth_for(a)
    d = {"type": "volpath", "max_depth": int(max_depth), "rr_depth": int(rr_depth)}
    if smooth_dielectric(scene.boundary):
        d = {**d, "type": "mneevolpath", **MNEE_PARAMS, "max_crossings": int(scene.boundary.max_crossings)}
        if scene.boundary.sms_trials and part != "rest":   # specular manifold sampling (mnee_sms)
            d.update(sms_trials=int(scene.boundary.sms_trials), sms_chains=str(scene.boundary.sms_chains))
            if part == "sampled":
                d["sms_only"] = True
    if part == "sampled" and "sms_only" not in d:
        raise ValueError("integrator_dict: part = 'sampled' needs a smooth dielectric with [boundary] sms_trials > 0")
    return d


def area_light_limit(position, intensity, radius, max_depth):
    """``build_scene_dict`` options that replace the scene's point light by a sphere light of ``radius`` at
    ``position`` with the same power (radiance ``I / (pi r^2)``), rendered by ``volpath`` at ``max_depth`` with the
    medium's next-event estimation off: as ``radius`` falls its image tends to the point light's, the
    validation's area-light limit. Limits: one light; a sphere that does not intersect the object."""
    radiance = (np.asarray(intensity, float) / (np.pi * radius * radius)).tolist()
    bulb = {"type": "sphere", "center": [float(c) for c in position], "radius": radius,
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": radiance}}}
    return {"lights": False, "extra_emitters": {"bulb": bulb}, "sample_emitters": False,
            "integrator": {"type": "volpath", "max_depth": max_depth}}


def build_scene_dict(scene, albedo_override=None, spp=1, extra_emitters=None, lights=True,
                     phase="auto", filter_type=GRID_FILTER, max_depth=MAX_DEPTH, rr_depth=None,
                     sample_emitters=None, channel=None, integrator=None, part=None):
    """Mitsuba ``load_dict`` dictionary for ``scene`` (the variant must be set: :func:`use_variant`).

    ``albedo_override`` replaces the albedo grid (0 gives the pure absorber whose
    image is subtracted to isolate subsurface light); ``extra_emitters`` maps
    names to emitter/shape dicts added as they are (validation scenes use area
    or environment emitters); ``lights=False`` drops the scene's point lights;
    ``sample_emitters`` overrides the medium's next-event estimation (validation).
    ``rr_depth`` defaults to :func:`rr_depth_for` the medium's (or the pass's) largest albedo;
    ``channel`` (0, 1, 2) makes the grey pass of that channel (:func:`channel_passes`);
    ``integrator`` replaces the integrator dict of :func:`integrator_dict` (validation); ``part`` is
    :func:`integrator_dict`'s (one of the two images of a split specular manifold sampling).
    The seed is not part of the scene: it is passed to ``mi.render``.
    """
    integrator = integrator or integrator_dict(scene, albedo_override, channel, max_depth, rr_depth, part)
    if channel is not None:
        scene = grey_medium_scene(scene, channel)
    d = {
        "type": "scene",
        "integrator": integrator,
        "sensor": sensor_dict(scene.camera, spp),
        "object": mitsuba_mesh(scene.mesh, bsdf_dict(scene.boundary),
                               medium_dict(scene, albedo_override, phase, filter_type, sample_emitters)),
    }
    if lights:
        d.update(light_dicts(scene.lights))
    for key, value in (extra_emitters or {}).items():
        if key in d:
            raise ValueError(f"build_scene_dict: extra emitter name {key!r} is already used")
        d[key] = value
    return d


def scene_notes(scene):
    """Facts about the approximations made for ``scene``, for ``reference.json``."""
    _, spread = phase_g_grid(scene.medium)
    b = scene.boundary
    note = (INDEX_MATCHED_NOTE if b.index_matched else SMOOTH_DIELECTRIC_NOTE if smooth_dielectric(b)
            else DIELECTRIC_NOTE)
    split = channel_passes(scene.medium)
    return {
        "boundary": b.kind,
        "boundary_eta": float(b.eta),
        "boundary_roughness": float(b.roughness),
        "boundary_note": note,
        "phase_note": RGB_G_NOTE,
        "g_channel_spread": spread,
        "grid_filter": GRID_FILTER,
        "integrator": (integrator_dict(scene) if split == (None,) else
                       {"RGB"[c]: integrator_dict(scene, channel=c) for c in split}),
        "channel_passes": ("one RGB pass" if split == (None,) else
                           "one grey pass per channel (sigma_t differs between channels; spectral tracking "
                           "is unstable for long paths)"),
        "rr_note": (f"Russian roulette from depth ceil(ln({RR_WEIGHT}) / ln(albedo_max)) (at least {RR_DEPTH}): "
                    "Mitsuba's survival cap of 0.95 per bounce under-samples long paths in high-albedo media "
                    "(harness/reference/mitsuba_scene.py)"),
        # What `[mesh] repair = "close-holes"` changed in the scene's mesh (None: the mesh as given).
        "mesh_repair": getattr(scene.mesh, "repair", None),
    }


def integrator_blocks(integrator):
    """A reference's ``integrator`` notes (:func:`scene_notes`) as a list of blocks: the one block of an RGB pass,
    or the R, G and B blocks of one grey pass per channel."""
    return [integrator[c] for c in "RGB"] if set(integrator) == set("RGB") else [integrator]


# --------------------------------------------------------------------------- camera rays and mask

def camera_frame(camera):
    """``(origin, forward, right, up)`` of the conventions' look-at (``docs/conventions.md``): right = forward x up,
    true up = right x forward, all unit vectors."""
    o = np.asarray(camera.origin, float)
    fwd = np.asarray(camera.target, float) - o
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, np.asarray(camera.up, float))
    right /= np.linalg.norm(right)
    return o, fwd, right, np.cross(right, fwd)


def camera_rays(camera, offsets=((0.5, 0.5),)):
    """Origins (3,) and unit directions (H, W, S, 3) through pixel positions ``(px + u, py + v)``.

    Follows ``docs/conventions.md``: right = forward x up, NDC y up, row 0 at the top.
    """
    o, fwd, right, up = camera_frame(camera)
    W, H = camera.width, camera.height
    t = np.tan(np.radians(camera.fov_y_deg) / 2.0)
    uv = np.asarray(offsets, float)
    px = np.arange(W)[None, :, None] + uv[None, None, :, 0]
    py = np.arange(H)[:, None, None] + uv[None, None, :, 1]
    x = (px / W * 2.0 - 1.0) * t * (W / H)
    y = (1.0 - py / H * 2.0) * t
    d = fwd + x[..., None] * right + y[..., None] * up
    return o, d / np.linalg.norm(d, axis=-1, keepdims=True)


def coverage_mask(scene, sub=4):
    """Fraction of each pixel's footprint that sees the mesh, (H, W) float32 in [0, 1].

    ``sub`` x ``sub`` stratified rays per pixel (conventions' camera math), traced
    with ``mi.Scene.ray_intersect`` against the mesh alone. The variant must be set.
    """
    import mitsuba as mi

    g = (np.arange(sub) + 0.5) / sub
    offsets = np.stack(np.meshgrid(g, g, indexing="xy"), -1).reshape(-1, 2)
    o, d = camera_rays(scene.camera, offsets)
    H, W, S, _ = d.shape
    flat = d.reshape(-1, 3).astype(np.float32)
    mscene = mi.load_dict({"type": "scene", "object": mitsuba_mesh(scene.mesh)})
    ray = mi.Ray3f(mi.Point3f(*[mi.Float(np.full(len(flat), v, np.float32)) for v in o]),
                   mi.Vector3f(*[mi.Float(flat[:, k]) for k in range(3)]))
    hit = np.asarray(mscene.ray_intersect(ray).is_valid(), dtype=bool)
    return hit.reshape(H, W, S).mean(axis=2).astype(np.float32)


def render_seeds(mi, scene_dict, seeds, spp):
    """Render the Mitsuba scene dict once per seed: the (seeds, H, W, C) float64 stack and the render seconds."""
    import time

    mscene = mi.load_dict(scene_dict)
    t = time.perf_counter()
    out = np.stack([np.asarray(mi.render(mscene, seed=int(s), spp=spp), dtype=np.float64) for s in seeds])
    return out, time.perf_counter() - t


def render_in_passes(mi, scene, seeds, spp, integrator=None):
    """``scene`` rendered as the reference renders it (:func:`channel_passes`), per seed: one RGB pass, or in a
    chromatic medium one grey pass per channel of which that channel is kept. ``integrator``: settings added to the
    scene's integrator (``stats``, ``max_crossings``). Returns the (seeds, H, W, 3 + AOVs) float64 stack and the
    render seconds. AOVs of a split render: the passes' mean (counts), except a channel's lost light
    (``mnee_lost_r/g/b``, :data:`harness.reference.mnee.STATS_AOVS`), which is taken from its own pass.

    Limits: for comparisons (the eta -> 1 tests and benchmarks); the reference itself renders through
    :mod:`harness.reference.jobs`, which also splits specular manifold sampling into a pass of its own."""
    passes, out, seconds = channel_passes(scene.medium), None, 0.0
    for c in passes:
        d = build_scene_dict(scene, channel=c)
        d["integrator"].update(integrator or {})
        a, t = render_seeds(mi, d, seeds, spp)
        seconds += t
        if c is None:
            return a, seconds
        if out is None:
            out = np.zeros_like(a)
        out[..., c] = a[..., c]
        out[..., 3:] += a[..., 3:] / len(passes)                 # counts: the mean over the passes
        if a.shape[-1] > 3:                                      # a channel's lost light: from its own pass
            from harness.reference.mnee import STATS_AOVS

            lost = [3 + STATS_AOVS.index(f"mnee_lost_{k}") for k in "rgb"]
            out[..., lost] -= a[..., lost] / len(passes)
            out[..., lost[c]] += a[..., lost[c]]
    return out, seconds
