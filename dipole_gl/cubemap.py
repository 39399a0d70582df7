"""Host side of the cubemap gather: the thesis draft's real-time directional dipole (``002_...``, Ch. 4).

``gather = "cubemap"`` renders either kernel (the thesis builds it for the directional dipole
of Frisvad et al.; the standard dipole runs through the same passes at no extra cost):

.. list-table::
   :header-rows: 1

   * - stage
     - thesis
     - shaders
     - what
   * - ``lightbuffer``
     - Ch. 4.1, Step 1
     - ``rsm.vert/frag`` (SSLPV's RSM pass)
     - per light, positions and normals of the surface the light sees (``light_size``^2, one tile per
       light), with its world-to-texture matrix (the light's view-projection, :func:`sslpv_gl.rsm.light_view`)
   * - ``cubemap``
     - Ch. 4.1, Step 2 (Fig. 4.2)
     - ``rsm.vert``, ``cubemap_face.frag``
     - six orthographic faces centred on the bounding box (:func:`dipole_gl.cubemap_geometry.cube_faces`),
       ``cube_size``^2 each: exit points, normals and the depth cube (window depth)
   * - ``gather``
     - Ch. 4.1, Step 2 (Figs. 4.3-4.4, the sum for ``C^f``), Sec. 4.3.1
     - ``cubemap_gather.comp``
     - per face texel and light, ``k = samples`` points of a disc of world radius ``disc_radius``
       diffusion lengths (at most the bounding sphere's diameter) in the light buffer around the point closest to the light:
       ``C^f += sum L S (n.w) F_t dA``; ``frames`` rotations of the disc, accumulated
   * - ``combine``
     - Ch. 4.1, Step 3 (Fig. 4.5), Secs. 4.3.2-4.3.3
     - ``cubemap_combine.comp``
     - per camera pixel (the dense gather's G-buffer, :mod:`dipole_gl.gbuffer`, which also gives the
       direct reflection), the mean of ``C^f`` over the faces that see the point, times the exit Fresnel

``shadow`` and ``gbuffer`` are the dense gather's (the camera's exit points; the shadow maps only
serve the direct reflection off a dielectric boundary).

Progressive refinement (Ch. 4.1, "an algorithm that progressively improves"): frame ``f`` rotates
the disc by :func:`dipole_gl.cubemap_geometry.rotations`; while nothing moves the frames' sums are
averaged (``frames`` of them; the light buffer and the faces are drawn once). ``timings_ms["gather"]``
covers all frames; ``info["ms_per_frame"]`` is one rotation's gather plus the combination.

Loop budget: one invocation of ``cubemap_gather.comp`` loops over the lights and, per light, over its
dispatch's disc samples, ``L (1 + n (1 + c))`` iterations (``c`` = :data:`dipole_gl.budget.DIRPOLE_CALL_ITERATIONS`
for the directional dipole, 0 for the standard one); :func:`gather_chunk` sizes ``n`` to
:data:`dipole_gl.budget.ITERATION_BUDGET`, each frame runs ``ceil(k / n)`` dispatches. The combination's
loop is the six faces.

Limits: the light buffer holds only the surface the light sees first, so a disc sample is always lit
(no partial shadow-map visibility as the other gathers' 3 x 3 filter gives); the disc is truncated at
``disc_radius``; a cube texel is one exit point, shared by every camera pixel that reads it.
"""

from __future__ import annotations

import math
import time

import numpy as np

from harness.errors import InputError
from sslpv_gl import shaders as _sh
from sslpv_gl.rsm import gl_bytes

from . import budget, gbuffer
from .cubemap_geometry import cube_faces, offsets, rotations
from .glsl import DIRS, MAX_LIGHTS
from .gather import set_boundary
from .sampling import MAX_FRAME_PAIRS
from .twin_cubemap import light_axis

__all__ = ["STAGES", "build_face", "build_gather", "build_combine", "gather_chunk", "light_buffer", "draw_faces",
           "run_gather", "run_combine", "render", "read_raw", "disc_world_radius"]

STAGES = ("shadow", "gbuffer", "lightbuffer", "cubemap", "gather", "combine")


def build_face(ctx, warnings):
    prog = _sh.program(ctx, "rsm.vert", "cubemap_face.frag", dirs=DIRS)
    _sh.check_uniforms(prog, ["u_view_proj"], "cubemap_face", warnings)
    return prog


def build_gather(ctx, kernel, warnings):
    prog = _sh.compute(ctx, "cubemap_gather.comp", {"MAX_LIGHTS": MAX_LIGHTS,
                                                    "KERNEL_DIRPOLE": int(kernel == "dirpole")}, dirs=DIRS)
    names = ["u_face_size", "u_lb_size", "u_n_lights", "u_samples", "u_first", "u_end", "u_phi", "u_weight",
             "u_disc_radius", "u_eps_g", "u_eta", "u_light_pos", "u_light_I", "u_light_vp", "u_light_axis",
             "u_tan_half", "u_sp", "u_sa", "u_bbox_min", "u_bbox_size", "u_res"]
    names += ["u_st", "u_c_phi", "u_c_e", "u_c_phi_out", "u_A_dir"] if kernel == "dirpole" else ["u_A"]
    _sh.check_uniforms(prog, names, f"cubemap_gather[{kernel}]", warnings)
    for unit, name in enumerate(("u_sp", "u_sa", "u_st")):
        if name in prog:
            prog[name].value = unit
    for unit, name in ((3, "u_face_pos"), (4, "u_face_nrm"), (5, "u_lb_pos"), (6, "u_lb_nrm")):
        if name in prog:
            prog[name].value = unit
    return prog


def build_combine(ctx, warnings):
    prog = _sh.compute(ctx, "cubemap_combine.comp", dirs=DIRS)
    _sh.check_uniforms(prog, ["u_face_size", "u_size", "u_centre", "u_half", "u_near", "u_far", "u_eye", "u_right",
                              "u_up", "u_dir", "u_eps_c", "u_eps_b", "u_eta", "u_cam_pos"], "cubemap_combine",
                       warnings)
    for unit, name in ((3, "u_face_pos"), (4, "u_face_nrm"), (5, "u_gpos"), (6, "u_gnrm"), (7, "u_grefl")):
        if name in prog:
            prog[name].value = unit
    return prog


def gather_chunk(kernel, n_lights, iteration_budget=budget.ITERATION_BUDGET):
    """Disc samples per dispatch: ``L (1 + n (1 + c)) <= budget`` (see the module docstring)."""
    per = 1 + (budget.DIRPOLE_CALL_ITERATIONS if kernel == "dirpole" else 0)
    n = (iteration_budget // max(n_lights, 1) - 1) // per
    if n < 1:
        raise ValueError(f"one disc sample of {n_lights} lights needs more than {iteration_budget} iterations")
    return int(n)


def read_raw(tex):
    """A texture as (height, width, 4) float32 in GL's layout (row 0 at the bottom), as the twin takes it."""
    return np.frombuffer(tex.read(), dtype="f4").reshape(tex.height, tex.width, 4)


def light_buffer(ctx, prog, vao, targets, scene, views, size):
    """Step 1: positions, normals (and SSLPV's texel flux, unused) of each light's view, side by side."""
    n = len(scene.lights)
    t = targets.get("cubemap_light", (size * n, size), 3)
    t.begin(ctx, (size * n, size))
    for i, (light, view) in enumerate(zip(scene.lights, views)):
        t.fbo.viewport = (i * size, 0, size, size)
        prog["u_view_proj"].write(gl_bytes(view.view_proj))
        _sh.set_uniform(prog, "u_intensity", tuple(map(float, light.intensity)))
        _sh.set_uniform(prog, "u_tan_half", (view.tan_half, view.tan_half))
        _sh.set_uniform(prog, "u_viewport", (float(i * size), 0.0, float(size), float(size)))
        vao.render(ctx.TRIANGLES)
    return t


def draw_faces(ctx, prog, vao, targets, cube, size):
    """Step 2's raster: the six orthographic faces side by side (face ``f`` in columns ``f N .. f N + N - 1``)."""
    t = targets.get("cubemap_faces", (6 * size, size), 2)
    t.begin(ctx, (6 * size, size))
    for f, face in enumerate(cube.faces):
        t.fbo.viewport = (f * size, 0, size, size)
        prog["u_view_proj"].write(gl_bytes(face.view_proj))
        vao.render(ctx.TRIANGLES)
    return t


def _light_uniforms(prog, scene, views, centre):
    pos = np.zeros((MAX_LIGHTS, 3), "f4")
    inten = np.zeros((MAX_LIGHTS, 3), "f4")
    axes = np.zeros((MAX_LIGHTS, 3), "f4")
    tan = np.zeros(MAX_LIGHTS, "f4")
    vps = np.tile(np.eye(4), (MAX_LIGHTS, 1, 1))
    for i, (light, view) in enumerate(zip(scene.lights, views)):
        pos[i], inten[i], vps[i], tan[i] = light.position, light.intensity, view.view_proj, view.tan_half
        axes[i] = light_axis(light.position, centre)
    for name, data in (("u_light_pos", pos.tobytes()), ("u_light_I", inten.tobytes()), ("u_light_vp", gl_bytes(vps)),
                       ("u_light_axis", axes.tobytes()), ("u_tan_half", tan.tobytes())):
        if name in prog:
            prog[name].write(data)


def run_gather(prog, kernel, faces_t, lb_t, medium, scene, views, centre, face_size, lb_size, samples, frames,
               disc_radius, eps_g):
    """Step 2's gather over ``frames`` rotations -> ``(accum buffer (6 N N vec4, C^f), dispatches)``."""
    ctx = prog.ctx
    accum = ctx.buffer(reserve=6 * face_size * face_size * 16)
    accum.clear()
    accum.bind_to_storage_buffer(0)
    medium.use(prog)
    faces_t.textures[0].use(3)
    faces_t.textures[1].use(4)
    lb_t.textures[0].use(5)
    lb_t.textures[1].use(6)
    _light_uniforms(prog, scene, views, centre)
    set_boundary(prog, float(scene.boundary.eta))
    for name, value in (("u_face_size", face_size), ("u_lb_size", lb_size), ("u_n_lights", len(scene.lights)),
                        ("u_samples", samples), ("u_weight", 1.0 / frames), ("u_disc_radius", float(disc_radius)),
                        ("u_eps_g", float(eps_g)), ("u_eta", float(scene.boundary.eta))):
        _sh.set_uniform(prog, name, value)
    pieces = budget.chunks(samples, gather_chunk(kernel, len(scene.lights)))
    for phi in rotations(frames):
        _sh.set_uniform(prog, "u_phi", float(phi))
        for first, end in pieces:
            _sh.set_uniform(prog, "u_first", first)
            _sh.set_uniform(prog, "u_end", end)
            prog.run((6 * face_size + 7) // 8, (face_size + 7) // 8)
            ctx.memory_barrier()
    return accum, frames * len(pieces)


def run_combine(prog, accum, faces_t, gb, out, scene, cube, face_size, eps_c, eps_b):
    """Step 3 into ``out`` (subsurface, full) from the camera's G-buffer ``gb``; ``eps_c``/``eps_b`` in world units."""
    cam = scene.camera
    accum.bind_to_storage_buffer(0)
    faces_t.textures[0].use(3)
    faces_t.textures[1].use(4)
    for unit, t in zip((5, 6, 7), gb.textures[:3]):
        t.use(unit)
    out.textures[0].bind_to_image(0, read=False, write=True)
    out.textures[1].bind_to_image(1, read=False, write=True)
    for name, attr in (("u_eye", "eye"), ("u_right", "right"), ("u_up", "up"), ("u_dir", "dir")):
        if name in prog:
            prog[name].write(np.array([getattr(f, attr) for f in cube.faces], "f4").tobytes())
    for name, value in (("u_face_size", face_size), ("u_size", (cam.width, cam.height)),
                        ("u_centre", tuple(map(float, cube.centre))), ("u_half", cube.half), ("u_near", cube.near),
                        ("u_far", cube.far), ("u_eps_c", float(eps_c)), ("u_eps_b", float(eps_b)),
                        ("u_eta", float(scene.boundary.eta)), ("u_cam_pos", tuple(map(float, cam.origin)))):
        _sh.set_uniform(prog, name, value)
    prog.run((cam.width + 7) // 8, (cam.height + 7) // 8)
    prog.ctx.memory_barrier()


def disc_world_radius(disc_radius, diffusion_length, bounding_radius):
    """The disc's world radius: ``disc_radius`` diffusion lengths, at most the bounding sphere's diameter (a wider
    disc only adds samples that miss the object; without absorption the diffusion length is infinite)."""
    r = disc_radius * diffusion_length if math.isfinite(diffusion_length) else math.inf
    return float(min(r, 2.0 * bounding_radius))


def render(r, scene, kernel, params, mat, medium, views, shadow_tex, centre, radius, timer, debug=False):
    """The cubemap gather's frame for :class:`dipole_gl.renderer.DipoleRenderer` ``r`` (its programs, mesh
    and targets) -> ``(sub, full, mask, work, info, debug dict or None)``; images top row first."""
    from .check_cubemap import check_cubemap

    cam, ctx = scene.camera, r.ctx
    W, H, L = cam.width, cam.height, len(scene.lights)
    N, S, k, F = params.cube_size, params.light_size, params.samples, params.frames
    cube = cube_faces(scene.mesh.vertices)
    eps_c, eps_b = offsets(cube, N, params.eps_c, params.eps_b)
    disc_radius = disc_world_radius(params.disc_radius, mat.diffusion_length, radius)
    if 6 * N * N * L * k > MAX_FRAME_PAIRS:
        raise InputError("--samples", "samples", f"the cubemap gather would pair {6 * N * N:,} face texels with "
                         f"{k:,} disc samples and {L} lights (over {MAX_FRAME_PAIRS:,} per frame)",
                         "lower --samples or --cube-size")
    gb = r._gbuffer_pass(scene, views, shadow_tex, params.shadow_size, centre, radius, timer)
    with timer.stage("lightbuffer"):
        prog = r._program(("rsm",))
        lb = light_buffer(ctx, prog, r._mesh_vao(scene, prog, "rsm"), r._targets, scene, views, S)
    with timer.stage("cubemap"):
        prog = r._program(("cube_face",))
        faces_t = draw_faces(ctx, prog, r._mesh_vao(scene, prog, "cube_face"), r._targets, cube, N)
    t0 = time.perf_counter()
    with timer.stage("gather"):
        accum, dispatches = run_gather(r._program(("cube_gather", kernel)), kernel, faces_t, lb, medium, scene, views,
                                       centre, N, S, k, F, disc_radius, params.eps_g)
    out = r._targets.get("dipole_cubemap_out", (W, H), 2)
    t1 = time.perf_counter()
    with timer.stage("combine"):
        run_combine(r._program(("cube_combine",)), accum, faces_t, gb, out, scene, cube, N, eps_c, eps_b)
    t2 = time.perf_counter()
    sub = gbuffer.read(out.textures[0], W, H)
    full = gbuffer.read(out.textures[1], W, H)
    mask = gbuffer.read(gb.textures[0], W, H)[..., 3] > 0.5
    raw = {"face_pos": read_raw(faces_t.textures[0]), "face_nrm": read_raw(faces_t.textures[1]),
           "lb_pos": read_raw(lb.textures[0]), "lb_nrm": read_raw(lb.textures[1]),
           "accum": np.frombuffer(accum.read(), "f4").reshape(N, 6 * N, 4)[..., :3].copy(),
           "gpos": read_raw(gb.textures[0]), "gnrm": read_raw(gb.textures[1]), "sub_raw": read_raw(out.textures[0]),
           "cube": cube, "disc_radius": disc_radius, "eps_c": eps_c, "eps_b": eps_b}
    accum.release()
    texels = int((raw["face_pos"][..., 3] > 0.5).sum())
    info = {"cube_size": N, "light_size": S, "samples": k, "frames": F, "disc_radius_world": disc_radius,
            "eps_g_texels": params.eps_g, "eps_c_world": eps_c, "eps_b_world": eps_b, "face_texels": texels,
            "dispatches": dispatches, "ms_per_frame": ((t1 - t0) / F + (t2 - t1)) * 1e3}
    info["check"] = check_cubemap(kernel, scene, mat, views, raw, params)
    work = {"gbuffer": W * H, "lightbuffer": S * S * L, "cubemap": 6 * N * N, "gather": texels * L * k * F,
            "combine": W * H}
    return sub, full, mask, work, info, (raw if debug else None)
