"""The cubemap gather (the thesis draft's real-time directional dipole, ``dipole_gl.cubemap``), pass by pass.

* the raster passes (light buffer, cube faces with their window depth) against a ray caster;
* the gather (``C^f`` at every covered face texel) and the combination (every covered pixel) against
  the NumPy twin, both kernels, on a two-light scene and behind a dielectric;
* a gather whose single dispatch would exceed llvmpipe's 65,535 loop iterations, against the twin;
* the render's self-check refusing a gather that is off by 1 %;
* the derived defaults of the fixes: eps_g finds every lit point in the light buffer, eps_b lets a face see
  every pixel whose best-aligned face is unoccluded;
* convergence to the dense gather of the same kernel as samples and frames grow.

Tolerances: GL (float32) against the twin (float64) ``max |GL - twin| <= 1e-4 max |twin|`` as in
``tests/test_dipole_gl.py``, over the points whose texel lookups are not within float32 rounding of a
texel edge (``ambiguous``, counted and bounded below 2 %).
"""

import numpy as np
import pytest

from harness.errors import InputError, ResultRefused
from harness.regression.accuracy import small_scene
from harness.scene import load_scene
from sslpv_gl.rsm import bounding_sphere, light_views
from dipole_gl import budget, cubemap, twin_cubemap
from dipole_gl.check_cubemap import check_cubemap
from dipole_gl.cubemap_geometry import cube_faces
from dipole_gl.medium import scene_material
from dipole_gl.params import DipoleParams
from tests.raster_precision import face_normals, interpolated_normals, plane_hits, split_offset, subpixel_bound
from tests.test_dipole_gl import RTOL, close

pytestmark = pytest.mark.gl

#: Share of points whose lookups sit within float32 rounding of a texel edge, at most.
AMBIGUOUS_MAX = 0.02


@pytest.fixture(scope="module")
def renderer(dipole_renderer):
    return dipole_renderer


def close_within(gl, ref, slack, label):
    """``|gl - ref| <= RTOL max |ref| + slack`` per point and colour (``slack``: what float32 picking a disc
    sample's neighbouring texel can change, :func:`dipole_gl.twin_cubemap.gather`)."""
    scale = float(np.abs(ref).max())
    assert scale > 0, f"{label}: the twin's result is empty"
    excess = np.abs(gl - ref) - slack
    print(f"{label}: max (|GL - twin| - slack) / max|twin| = {excess.max() / scale:.2e} (<= {RTOL}); "
          f"largest slack {slack.max() / scale:.1e}")
    assert excess.max() <= RTOL * scale, f"{label}: {excess.max():.3e} > {RTOL} * {scale:.3e}"


def _params(**kw):
    base = dict(gather="cubemap", cube_size=16, light_size=64, samples=24, frames=3, disc_radius=2.0)
    base.update(kw)
    return DipoleParams(**base)


def _axes(scene):
    centre = bounding_sphere(scene.mesh)[0]
    return [twin_cubemap.light_axis(light.position, centre) for light in scene.lights]


def _twin_gather(kernel, scene, raw, params, rows, cols):
    lb = raw["lb_pos"]
    views = light_views(scene)[0]
    return twin_cubemap.gather(kernel, raw["face_pos"][rows, cols, :3], raw["face_nrm"][rows, cols, :3], lb[..., :3],
                               raw["lb_nrm"][..., :3], lb[..., 3] > 0.5, scene.lights, views, _axes(scene),
                               scene_material(scene), scene.boundary.eta, params.samples, params.frames,
                               raw["disc_radius"], params.eps_g)


def _twin_combine(scene, raw, params):
    g = raw["gpos"][..., 3] > 0.5
    out = twin_cubemap.combine(raw["gpos"][g][:, :3], raw["gnrm"][g][:, :3], raw["face_pos"][..., 3] > 0.5,
                               raw["face_nrm"][..., 3], raw["accum"], raw["cube"], params.cube_size, raw["eps_c"],
                               raw["eps_b"], scene.camera.origin, scene.boundary.eta)
    return g, out


def _on_its_texel(renderer, mesh, gl_pos, gl_nrm, hit, face, next_rays, size, what):
    """GL texels against their centres' hits: on the hit triangle's plane (float32), within sub-pixel precision of
    the hit in it, and with the mesh's normal at the texel's own position (``tests/raster_precision.py``).
    ``face``: the hit triangles; ``next_rays``: ``((origins, dirs), (origins, dirs))`` through the next texel
    centres along the texel axes."""
    n = face_normals(mesh, face)
    (o_r, d_r), (o_u, d_u) = next_rays
    off_plane, texels = split_offset(gl_pos, hit, n, plane_hits(o_r, d_r, hit, n), plane_hits(o_u, d_u, hit, n))
    bound = subpixel_bound(renderer.ctx)
    err_n = np.abs(gl_nrm - interpolated_normals(mesh, face, gl_pos)).max()
    print(f"{what}: {off_plane.max() / size.max():.2e} of the mesh size off the plane, {texels.max():.2e} texels "
          f"from the hit (bound {bound:.2e}), normal {err_n:.2e}")
    assert off_plane.max() <= 1e-4 * size.max(), f"{what}: position off the mesh"
    assert texels.max() <= bound, f"{what}: position {texels.max():.2e} texels from its centre's hit"
    assert err_n <= 1e-3, f"{what}: normal"


def test_raster_passes_match_a_ray_caster(renderer):
    """Light buffer (perspective from the light) and the six faces (orthographic, with z_tex): the first hit of
    each texel centre's ray; coverage may differ only on texels whose centre lies on a triangle's edge."""
    scene = load_scene("skin_torus").with_resolution(16, 16)
    params = _params(cube_size=16, light_size=32)
    raw = renderer.render(scene, "dipole", params, debug=True).debug
    views = light_views(scene)[0]
    size = scene.mesh.vertices.max(0) - scene.mesh.vertices.min(0)
    S = params.light_size
    # light buffer: texel centre (moved by di, dj texels) -> NDC -> a world point on the far plane -> ray from the light
    j, i = np.mgrid[0:S, 0:S]
    L = np.asarray(scene.lights[0].position, float)

    def ray(di=0, dj=0):
        ndc = np.stack([(i + 0.5 + di) / S * 2 - 1, (j + 0.5 + dj) / S * 2 - 1, np.ones_like(i, float),
                        np.ones_like(i, float)], -1)
        far = ndc.reshape(-1, 4) @ np.linalg.inv(views[0].view_proj).T
        d = far[:, :3] / far[:, 3:] - L
        return d / np.linalg.norm(d, axis=1, keepdims=True)
    pos, _, hit, _, tri = twin_cubemap.raycast(scene.mesh, L, ray(), faces=True)
    gl = raw["lb_pos"][:, :S].reshape(-1, 4)
    both = hit & (gl[:, 3] > 0.5)
    assert both.sum() > 100
    print(f"light buffer: {both.sum()} texels covered by both, {np.sum(hit != (gl[:, 3] > 0.5))} differ")
    assert np.sum(hit != (gl[:, 3] > 0.5)) <= 0.02 * both.sum()
    _on_its_texel(renderer, scene.mesh, gl[both, :3], raw["lb_nrm"][:, :S].reshape(-1, 4)[both, :3], pos[both],
                  tri[both], ((L, ray(1, 0)[both]), (L, ray(0, 1)[both])), size, "light buffer")
    # faces: orthographic rays from each face's window; z_tex against the depth of the texel's own position
    cube, N = raw["cube"], params.cube_size
    j, i = np.mgrid[0:N, 0:N]
    for f, face in enumerate(cube.faces):
        x = ((i + 0.5) / N * 2 - 1) * cube.half
        y = ((j + 0.5) / N * 2 - 1) * cube.half
        o = face.eye + x.reshape(-1, 1) * face.right + y.reshape(-1, 1) * face.up
        pos, _, hit, _, tri = twin_cubemap.raycast(scene.mesh, o, np.broadcast_to(face.dir, o.shape), faces=True)
        gp = raw["face_pos"][:, f * N:(f + 1) * N].reshape(-1, 4)
        gn = raw["face_nrm"][:, f * N:(f + 1) * N].reshape(-1, 4)
        both = hit & (gp[:, 3] > 0.5)
        assert np.sum(hit != (gp[:, 3] > 0.5)) <= 0.02 * both.sum() + 1, f"face {f}"
        step = 2.0 * cube.half / N
        ob = o[both]
        dirs = np.broadcast_to(face.dir, ob.shape)
        _on_its_texel(renderer, scene.mesh, gp[both, :3], gn[both, :3], pos[both], tri[both],
                      ((ob + step * face.right, dirs), (ob + step * face.up, dirs)), size, f"face {f}")
        # window depth: that of the texel's own position along the face's axis (its distance from the eye's plane)
        t_gl = np.einsum("ij,j->i", gp[both, :3] - face.eye, face.dir)
        z_tex = (2.0 * t_gl - (cube.far + cube.near)) / (cube.far - cube.near) * 0.5 + 0.5
        assert np.abs(gn[both, 3] - z_tex).max() <= 1e-5, f"face {f}: window depth"


@pytest.mark.parametrize("name", ["two_lights", "layered_dielectric"])
@pytest.mark.parametrize("kernel", ["dipole", "dirpole"])
def test_gather_and_combination_match_twin(renderer, name, kernel):
    """Every covered face texel's C^f (three rotations) and every covered pixel, GL against the twin."""
    scene = load_scene(name).with_resolution(16, 16)
    params = _params()
    res = renderer.render(scene, kernel, params, debug=True)
    raw = res.debug
    rows, cols = np.nonzero(raw["face_pos"][..., 3] > 0.5)
    ref, amb, slack = _twin_gather(kernel, scene, raw, params, rows, cols)
    print(f"{name} {kernel}: {amb.sum()} of {len(amb)} face texels ambiguous, {np.any(slack > 0, 1).sum()} with slack")
    assert amb.mean() <= AMBIGUOUS_MAX
    close_within(raw["accum"][rows, cols][~amb], ref[~amb], slack[~amb], f"{name} {kernel} cubemap gather")
    g, (lum, count, pamb) = _twin_combine(scene, raw, params)
    assert pamb.mean() <= AMBIGUOUS_MAX
    assert np.all(count > 0), "a covered pixel that no face sees"
    close(raw["sub_raw"][g][~pamb, :3], lum[~pamb], f"{name} {kernel} cubemap combination")
    assert res.info["check"]["max_rel_diff"] <= 1e-4


@pytest.mark.parametrize("kernel", ["dipole", "dirpole"])
def test_gather_beyond_the_loop_limit_matches_twin(renderer, kernel):
    """40,000 disc samples and two lights: one dispatch per frame would run ``2 (1 + 40,000 (1 + c))`` loop
    iterations per invocation, past llvmpipe's 65,535 whether it counts the kernel's colour loop (c = 3) or not
    (it was measured to count it once, ``dipole_gl.budget``); a disc of 0.3 diffusion lengths keeps the last
    (outermost) samples' share large, so a truncated sum shows."""
    scene = load_scene("two_lights").with_resolution(16, 16)
    params = _params(cube_size=8, light_size=64, samples=40_000, frames=1, disc_radius=0.3)
    assert 2 * (1 + params.samples) > budget.LLVMPIPE_LOOP_LIMIT
    res = renderer.render(scene, kernel, params, debug=True)
    raw = res.debug
    rows, cols = np.nonzero(raw["face_pos"][..., 3] > 0.5)
    pick = np.random.default_rng(1).permutation(len(rows))[:6]
    ref, amb, slack = _twin_gather(kernel, scene, raw, params, rows[pick], cols[pick])
    close_within(raw["accum"][rows[pick], cols[pick]][~amb], ref[~amb], slack[~amb], f"{kernel} gather of 40,000 samples")
    assert res.info["dispatches"] == -(-params.samples // cubemap.gather_chunk(kernel, 2))


def test_self_check_refuses_a_gather_off_by_one_percent(renderer):
    scene = load_scene("sphere_homogeneous").with_resolution(16, 16)
    params = _params(samples=8, frames=1)
    res = renderer.render(scene, "dirpole", params, debug=True)
    raw = dict(res.debug)
    views = light_views(scene)[0]
    check_cubemap("dirpole", scene, scene_material(scene), views, raw, params)        # as rendered: accepted
    raw["accum"] = raw["accum"] * 1.01
    with pytest.raises(ResultRefused, match="cubemap gather"):
        check_cubemap("dirpole", scene, scene_material(scene), views, raw, params)


@pytest.mark.parametrize("name,size", [("sphere_homogeneous", 128), ("skin_torus", 96)])
def test_default_depth_bias_lets_a_face_see_every_pixel(renderer, name, size):
    """The default eps_b (``dipole_gl.cubemap_geometry``): every covered pixel that its best-aligned face sees
    (the face whose axis is closest to the normal, within 54.7 degrees; its orthographic ray reaches the
    point unoccluded, by the ray caster) is combined from at least one face, at cube resolutions where a
    face texel is smaller than a camera pixel's footprint. A point that only grazing faces see (inside the
    torus's hole) is not covered by the derivation and may get no face: counted, a limit of six axis views."""
    scene = load_scene(name).with_resolution(32, 32)
    params = _params(cube_size=size, samples=1, frames=1)
    raw = renderer.render(scene, "dipole", params, debug=True).debug
    g, (_, count, _) = _twin_combine(scene, raw, params)
    x = raw["gpos"][g][:, :3].astype(np.float64)
    n = raw["gnrm"][g][:, :3].astype(np.float64)
    cube = raw["cube"]
    best = np.argmax(np.stack([-(n @ face.dir) for face in cube.faces], axis=1), axis=1)
    seen = np.zeros(len(x), bool)
    for f, face in enumerate(cube.faces):
        o = x - ((x - face.eye) @ face.dir)[:, None] * face.dir             # the ray's origin on the face's plane
        _, _, hit, t = twin_cubemap.raycast(scene.mesh, o, np.broadcast_to(face.dir, o.shape))
        seen |= (best == f) & hit & (t >= (x - face.eye) @ face.dir - 1e-4 * cube.half)
    print(f"{name}: visible faces per pixel {np.bincount(count.astype(int))}; best face occluded: {np.sum(~seen)}")
    assert seen.mean() > 0.9
    assert np.all(count[seen] > 0)


@pytest.mark.parametrize("name", ["sphere_homogeneous", "skin_torus"])
def test_default_eps_g_finds_every_lit_point_in_the_light_buffer(renderer, name):
    """The default eps_g (``dipole_gl.cubemap_geometry``): every face texel that the light reaches (facing it, the
    segment to the light unoccluded, by the ray caster) finds a covered light-buffer texel at its disc's centre,
    holding a point within a few texels of itself; without the fix (eps_g = 0) points on the light's silhouette
    miss."""
    scene = load_scene(name).with_resolution(16, 16)
    params = _params(cube_size=24, light_size=64, samples=1, frames=1)
    raw = renderer.render(scene, "dipole", params, debug=True).debug
    rows, cols = np.nonzero(raw["face_pos"][..., 3] > 0.5)
    x = raw["face_pos"][rows, cols, :3].astype(np.float64)
    n = raw["face_nrm"][rows, cols, :3].astype(np.float64)
    L = np.asarray(scene.lights[0].position, np.float64)
    to = L - x
    dist = np.linalg.norm(to, axis=1)
    _, _, hit, t = twin_cubemap.raycast(scene.mesh, x + 1e-4 * dist[:, None] * n, to / dist[:, None])
    lit = (np.sum(to * n, axis=1) > 0) & ~(hit & (t < dist))
    view = light_views(scene)[0][0]
    axis = _axes(scene)[0]
    S = params.light_size
    lb = raw["lb_pos"][:, :S]
    misses = {}
    for eps in (params.eps_g, 0.0):
        uv, found, depth, _ = twin_cubemap.closest_point(x[lit], n[lit], L, view, axis, lb[..., :3], lb[..., 3] > 0.5,
                                                         eps)
        misses[eps] = int(np.sum(~found))
        if eps == params.eps_g:
            texel = 2.0 * view.tan_half * ((x[lit] - L) @ axis) / S
            tc = np.clip(np.floor(uv * S).astype(int), 0, S - 1)
            d = lb[tc[:, 1], tc[:, 0], :3] - x[lit]
            ray = (x[lit] - L) / np.linalg.norm(x[lit] - L, axis=1, keepdims=True)
            side = np.linalg.norm(d - np.sum(d * ray, axis=1, keepdims=True) * ray, axis=1) / texel
            print(f"{name}: {lit.sum()} lit face texels; x_o^T within {side[found].max():.2f} texels across the ray")
            assert side[found].max() <= np.sqrt(0.5) + params.eps_g + 0.1      # half a diagonal plus the move
    print(f"{name}: misses with eps_g = {params.eps_g}: {misses[params.eps_g]}, with 0: {misses[0.0]}")
    assert misses[params.eps_g] == 0
    assert misses[0.0] > 0


def _rel_mse(a, b, mask):
    return float(np.mean((a[mask] - b[mask]) ** 2) / np.mean(b[mask] ** 2))


def test_converges_to_the_dense_gather(renderer):
    """relMSE against the dense gather of the same kernel falls as the disc samples grow; the frames' rotations
    converge to their own limit (the disc's rings averaged over angle: rotation leaves the radial rule's error,
    so at few samples more frames do not approach the dense gather, docs/dipole_rivals.md)."""
    scene = small_scene("sphere_homogeneous").with_resolution(24, 24)
    dense = renderer.render(scene, "dipole", DipoleParams(spacing=1.0))
    img = {}
    for k, frames in ((16, 1), (16, 4), (16, 32), (64, 4), (256, 4)):
        res = renderer.render(scene, "dipole", _params(cube_size=48, light_size=128, samples=k, frames=frames,
                                                       disc_radius=4.0))
        img[k, frames] = res.subsurface
        mask = res.mask & dense.mask
    errs = {key: _rel_mse(v, dense.subsurface, mask) for key, v in img.items()}
    to_limit = {f: _rel_mse(img[16, f], img[16, 32], mask) for f in (1, 4)}
    print("relMSE against dense:", errs, "against 32 frames:", to_limit)
    assert to_limit[4] < 0.5 * to_limit[1]            # the rotations average out
    assert errs[64, 4] < 0.5 * errs[16, 4] and errs[256, 4] < 0.5 * errs[64, 4]        # the samples
    assert errs[256, 4] < 0.01


def test_bad_values_are_one_line():
    with pytest.raises(InputError, match="must be an integer"):
        DipoleParams(gather="cubemap", samples=0)
    with pytest.raises(InputError, match="belongs to gather=cubemap"):
        DipoleParams(gather="dense", frames=4)
    with pytest.raises(InputError, match="must be a number"):
        DipoleParams(gather="cubemap", eps_b=-1.0)
    assert cube_faces(np.eye(3)).half > 0
