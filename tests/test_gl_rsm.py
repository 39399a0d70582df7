"""The reflective shadow maps (``rsm.vert/frag``, Sec. 3.1) against the mesh's own geometry.

For sampled texels of each light's injection RSM, and of its tile of the
shadow-map atlas, the ray from the light through the texel centre (the light's
view-projection inverted) is intersected with the mesh's triangles in float64
(Moller-Trumbore). At the nearest hit:

* the texel's world position must be the hit point, up to what the rasteriser's sub-pixel precision
  explains (``tests/raster_precision.py``): on the hit triangle's plane (within ``2e-5`` of the mesh's
  size: float32 interpolation across one triangle, measured at most 4e-6 on llvmpipe and on an NVIDIA
  H200), and within ``sqrt(2) * 2**-GL_SUBPIXEL_BITS`` texels of the hit in that plane (measured at most
  3.3e-4 texels on llvmpipe and 2.5e-3 on the H200, against 5.5e-3 at 8 bits);
* the injection RSM's normal must be the mesh's own vertex normals interpolated at
  the texel's own position and normalised, outward (``|n_GL - n| <= 1e-4``;
  measured 5e-6 on llvmpipe; a flipped normal is off by 2);
* a texel is valid exactly where its ray hits the mesh.

The scenes: the suite's sphere (smooth normals) and torus (a hole, and normals that
differ from the radial direction).
"""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from harness.scene import load_scene
from tests.raster_precision import face_normals, interpolated_normals, plane_hits, split_offset, subpixel_bound
from sslpv_gl.params import SSLPVParams
from sslpv_gl.rsm import light_views

pytestmark = pytest.mark.gl

SIZE = 64
SAMPLES = 400


def texel_rays(view_proj, size, rows, cols, origin):
    """Unit directions from the light through texel centres (``rows`` counted from the top)."""
    inv = np.linalg.inv(view_proj)
    x = (cols + 0.5) / size * 2 - 1
    y = (size - 1 - rows + 0.5) / size * 2 - 1            # GL rows count from the bottom
    clip = np.stack([x, y, np.zeros_like(x), np.ones_like(x)], axis=-1)
    p = clip @ inv.T
    p = p[:, :3] / p[:, 3:4]
    d = p - origin
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def intersect(mesh, origin, dirs, hint=None, radius=None):
    """Nearest hit of each ray: (t, face, barycentrics (u, v, w)); t = inf where it misses.

    With ``hint`` (points near the expected hits), only triangles whose centroid lies
    within ``radius`` of the hint are tested, else all of them.
    """
    tri = mesh.vertices[mesh.faces]                       # (F, 3, 3)
    tree = cKDTree(tri.mean(axis=1)) if hint is not None else None
    t_best = np.full(len(dirs), np.inf)
    f_best = np.full(len(dirs), -1)
    bary = np.zeros((len(dirs), 3))
    for i, d in enumerate(dirs):
        cand = np.asarray(tree.query_ball_point(hint[i], radius)) if tree is not None else np.arange(len(tri))
        if cand.size == 0:
            continue
        a, b, c = tri[cand, 0], tri[cand, 1], tri[cand, 2]
        e1, e2 = b - a, c - a
        pv = np.cross(d, e2)
        det = np.sum(e1 * pv, axis=1)
        ok = np.abs(det) > 1e-14
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        tv = origin - a
        u = np.sum(tv * pv, axis=1) * inv
        qv = np.cross(tv, e1)
        v = (qv @ d) * inv
        t = np.sum(e2 * qv, axis=1) * inv
        hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        if hit.any():
            k = np.argmin(np.where(hit, t, np.inf))
            t_best[i], f_best[i] = t[k], cand[k]
            bary[i] = (1 - u[k] - v[k], u[k], v[k])
    return t_best, f_best, bary


def _offsets(mesh, face, view, size, rows, cols, origin, pos, hit):
    """``split_offset`` of GL positions against their texel centres' hits on faces ``face``."""
    n = face_normals(mesh, face)
    right = plane_hits(origin, texel_rays(view.view_proj, size, rows, cols + 1, origin), hit, n)
    up = plane_hits(origin, texel_rays(view.view_proj, size, rows - 1, cols, origin), hit, n)
    return split_offset(pos, hit, n, right, up)


@pytest.mark.parametrize("name", ["sphere_homogeneous", "skin_torus"])
def test_injection_rsm_matches_mesh(gl_renderer, name):
    scene = load_scene(name)
    mesh = scene.mesh
    size_scale = float(np.ptp(mesh.vertices, axis=0).max())
    params = SSLPVParams(N=16, inject_size=SIZE, rsm_size=256)
    texels = gl_renderer.rsm_texels(scene, params)
    views, _, _, _ = light_views(scene)
    rng = np.random.default_rng(11)
    edge = float(np.linalg.norm(mesh.vertices[mesh.faces[:, 0]] - mesh.vertices[mesh.faces[:, 1]], axis=1).max())
    for light, view, tex in zip(scene.lights, views, texels):
        origin = np.asarray(light.position, dtype=np.float64)
        valid = tex[:, 9] > 0.5
        assert 0.05 < valid.mean() < 0.95, f"{name}: {valid.mean():.3f} of the texels are valid"
        picks = np.concatenate([rng.choice(np.flatnonzero(valid), SAMPLES, replace=False),
                                rng.choice(np.flatnonzero(~valid), SAMPLES // 4, replace=False)])
        rows, cols = picks // SIZE, picks % SIZE
        dirs = texel_rays(view.view_proj, SIZE, rows, cols, origin)
        on = valid[picks]
        pos = tex[picks, 0:3].astype(np.float64)
        nrm = tex[picks, 3:6].astype(np.float64)
        # valid texels: the hit near the texel's own position; invalid ones: no hit anywhere
        t, face, _ = intersect(mesh, origin, dirs[on], hint=pos[on], radius=3 * edge)
        assert np.all(np.isfinite(t)), f"{name}: {np.sum(~np.isfinite(t))} valid texels whose ray misses the mesh"
        hit = origin + t[:, None] * dirs[on]
        off_plane, texels = _offsets(mesh, face, view, SIZE, rows[on], cols[on], origin, pos[on], hit)
        err_p = off_plane.max() / size_scale
        normal = interpolated_normals(mesh, face, pos[on])
        err_n = np.linalg.norm(nrm[on] - normal, axis=1).max()
        t_off, _, _ = intersect(mesh, origin, dirs[~on])
        # a texel whose centre grazes the silhouette may go either way: allow misses within a texel
        grazing = np.isfinite(t_off)
        bound = subpixel_bound(gl_renderer.ctx)
        print(f"{name}: position {err_p:.2e} of the mesh size off the plane, {texels.max():.2e} texels from the "
              f"hit in it (bound {bound:.2e}), normal error {err_n:.2e}, "
              f"{grazing.sum()} of {(~on).sum()} invalid texels graze the mesh")
        assert err_p <= 2e-5, f"{name}: RSM position off the mesh by {err_p:.2e} of its size"
        assert texels.max() <= bound, (f"{name}: RSM position {texels.max():.2e} texels from its centre's hit, more "
                                       f"than sub-pixel precision explains ({bound:.2e})")
        assert err_n <= 1e-4, f"{name}: RSM normal differs from the mesh's interpolated normal by {err_n:.2e}"
        assert grazing.sum() <= 2, f"{name}: {grazing.sum()} invalid texels whose ray hits the mesh"


def test_shadow_map_positions_match_mesh(gl_renderer):
    """The shadow-map atlas (what shading tests visibility against) holds the same surface."""
    scene = load_scene("skin_torus")
    size = 256
    params = SSLPVParams(N=16, inject_size=SIZE, rsm_size=size)
    views, _, _, _ = light_views(scene)
    with gl_renderer.ctx:
        _, shadow = gl_renderer._render_rsm(scene, params, views)
        atlas = np.frombuffer(shadow.read(), dtype=np.float32).reshape(shadow.height, shadow.width, 4)[::-1]
    mesh = scene.mesh
    rng = np.random.default_rng(5)
    edge = float(np.linalg.norm(mesh.vertices[mesh.faces[:, 0]] - mesh.vertices[mesh.faces[:, 1]], axis=1).max())
    for i, (light, view) in enumerate(zip(scene.lights, views)):
        tile = atlas[:, i * size:(i + 1) * size].reshape(-1, 4)
        valid = np.flatnonzero(tile[:, 3] > 0.5)
        picks = rng.choice(valid, SAMPLES, replace=False)
        origin = np.asarray(light.position, dtype=np.float64)
        dirs = texel_rays(view.view_proj, size, picks // size, picks % size, origin)
        pos = tile[picks, :3].astype(np.float64)
        t, face, _ = intersect(mesh, origin, dirs, hint=pos, radius=3 * edge)
        assert np.all(np.isfinite(t))
        off_plane, texels = _offsets(mesh, face, view, size, picks // size, picks % size, origin, pos,
                                     origin + t[:, None] * dirs)
        err = off_plane.max() / float(np.ptp(mesh.vertices))
        assert err <= 2e-5, f"light {i}: shadow-map position off the mesh by {err:.2e} of its size"
        assert texels.max() <= subpixel_bound(gl_renderer.ctx), (
            f"light {i}: shadow-map position {texels.max():.2e} texels from its centre's hit")
