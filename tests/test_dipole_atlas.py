"""The atlas gather (Carr, Hall & Hart 2003; ``dipole_gl.atlas``, ``dipole_gl.links``, ``gather_atlas.comp``).

* the multiresolution meshed atlas: a binary tree of ``2T - 1`` clusters, children partitioning their
  parent, rectangles halved (square / 2:1) down to one per triangle and tiling the atlas, every MIP
  block of a square cluster exactly that cluster's texels; the topology measure (components, ``V - E + F``,
  boundary loops) on known face sets; disc clusters wherever the genus allows; per-triangle texels inside
  their triangle, areas summing to the triangle's;
* the links: the Barnes-Hut throughput against the exact sum of Eq. (10); the vectorised priority queue
  against a sequential ``heapq`` one; an adaptive texel's links tile the surface;
* GL against the twin pass by pass (radiosity map, every MIP level, the scattered irradiance map, the
  image; ``max |GL - twin| <= 1e-4 max |twin|``), also in chunks; convergence toward the dense gather as
  links and atlas size grow; the render's self-check; S1 under ``terms = both``; one-line refusals.
"""

import heapq

import numpy as np
import pytest

from harness.errors import InputError, ResultRefused
from harness.regression.accuracy import small_scene
from harness.scene import load_scene
from dipole_gl import atlas as atlas_mod
from dipole_gl import budget, check, links, twin, twin_atlas
from dipole_gl.medium import scene_material
from dipole_gl.params import DipoleParams
from tests.test_dipole_gl import close


def _atlas(name="layered_dielectric", size=32):
    scene = load_scene(name)
    return scene, atlas_mod.build(scene.mesh, size)


def _coeffs(scene, at):
    mat = scene_material(scene, "dipole")
    P = at.texels
    return twin.exit_coefficients(mat, at.position.reshape(P, 3), at.normal.reshape(P, 3), scene.boundary.eta)


# ---------------------------------------------------------------------------- the atlas (no GL)

@pytest.mark.parametrize("name,size", [("thin_ring", 128), ("layered_dielectric", 16)])
def test_clusters_are_a_quadtree_of_halved_rectangles(name, size):
    scene = load_scene(name)
    T = len(scene.mesh.faces)
    children, leaf, members = atlas_mod.cluster_tree(scene.mesh, size)
    rects = atlas_mod.pack(size, children, members)
    assert len(children) == 2 * T - 1 and np.sum(leaf >= 0) == T
    owner = np.full((size, size), -1)
    connected = 0
    nb = atlas_mod.face_adjacency(scene.mesh)
    for j, (a, b) in enumerate(children):
        x0, y0, w, h = rects[j]
        assert w == h or h == 2 * w, f"node {j}: a {w} x {h} rectangle"
        assert len(members[j]) <= w * h
        connected += len(atlas_mod._components(members[j], nb)) == 1
        if a < 0:
            assert np.all(owner[y0:y0 + h, x0:x0 + w] == -1), "leaf rectangles overlap"
            owner[y0:y0 + h, x0:x0 + w] = leaf[j]
            continue
        assert sorted(members[a] + members[b]) == sorted(members[j])
        assert rects[a][2] * rects[a][3] * 2 == w * h == rects[b][2] * rects[b][3] * 2
        if w == h and (w & (w - 1)) == 0:           # a square cluster is one MIP texel's block
            assert x0 % w == 0 and y0 % h == 0
    assert np.all(owner >= 0), "the leaves do not tile the atlas"
    at = atlas_mod.build(scene.mesh, size)
    assert np.array_equal(at.face, owner)
    print(f"{name}: {T} triangles, {connected / len(children):.3f} of the clusters connected "
          f"({at.disconnected} not)")
    assert connected / len(children) > 0.95


def _grid(m, n, wrap_u=False, wrap_v=False):
    """An ``m x n`` grid of quads, two triangles each, as welded corners; wrapped in u and/or v (an annulus, a torus)."""
    M, N = m + (not wrap_u), n + (not wrap_v)
    vid = lambda i, j: (i % M) * N + (j % N)          # noqa: E731
    tri = []
    for i in range(m):
        for j in range(n):
            a, b, c, d = vid(i, j), vid(i + 1, j), vid(i + 1, j + 1), vid(i, j + 1)
            tri += [[a, b, c], [a, c, d]]
    return np.array(tri)


def _octahedron():
    return np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])


@pytest.mark.parametrize("case,faces,want", [
    ("one triangle", lambda: (_grid(1, 1), [0]), (1, 1, 1)),
    ("a strip", lambda: (_grid(1, 6), range(12)), (1, 1, 1)),
    ("two apart", lambda: (_grid(1, 6), [0, 11]), (2, 2, 2)),
    ("an annulus", lambda: (_grid(3, 8, wrap_v=True), range(48)), (1, 0, 2)),
    ("a torus", lambda: (_grid(6, 8, wrap_u=True, wrap_v=True), range(96)), (1, 0, 0)),
    ("a torus minus a face", lambda: (_grid(6, 8, wrap_u=True, wrap_v=True), range(1, 96)), (1, -1, 1)),
    ("a closed octahedron", lambda: (_octahedron(), range(8)), (1, 2, 0)),
    ("an octahedron minus a face", lambda: (_octahedron(), range(1, 8)), (1, 1, 1)),
    ("a strip pinched at a vertex (one boundary, not a disc)", lambda: (_grid(1, 4, wrap_v=True), range(7)), (1, 0, 1)),
])
def test_topology_of_known_face_sets(case, faces, want):
    tri, f = faces()
    t = atlas_mod.topology(list(f), tri)
    assert (t.components, t.euler, t.boundary_loops) == want, case
    assert t.disc == (want[:2] == (1, 1))


def test_topology_of_suite_meshes():
    for name, chi in (("apple_sphere", 2), ("thin_ring", 0)):
        tri = atlas_mod.welded_faces(load_scene(name).mesh)
        T = len(tri)
        assert atlas_mod.topology(range(T), tri) == atlas_mod.Topology(1, chi, 0), name
        assert atlas_mod.topology(range(1, T), tri) == atlas_mod.Topology(1, chi - 1, 1), name


@pytest.mark.parametrize("name,size,not_disc", [("apple_sphere", 256, 1), ("thin_ring", 128, 3)])
def test_clusters_are_discs(name, size, not_disc):
    """Every connected cluster is a disc but the root and, on a torus, the depth-1 clusters: a closed surface of
    genus g splits into discs A, B only if ``chi(M) = chi(A) + chi(B) - chi(A n B) = 2`` (``A n B`` the one loop of
    ``A``'s boundary, ``chi = 0``), so no split of a torus (``chi = 0``) gives two discs. On the sphere at 256 texels
    per side every cluster is connected."""
    mesh = load_scene(name).mesh
    tri = atlas_mod.welded_faces(mesh)
    children, _, members = atlas_mod.cluster_tree(mesh, size)
    depth = np.zeros(len(children), int)
    for j, (a, b) in enumerate(children):
        if a >= 0:
            depth[a] = depth[b] = depth[j] + 1
    kinds = {j: atlas_mod.topology(m, tri) for j, m in enumerate(members) if len(m) > 1}
    bad = sorted((int(depth[j]), j, t) for j, t in kinds.items() if t.components == 1 and not t.disc)
    split = sum(t.components > 1 for t in kinds.values())
    print(f"{name} at {size}: {len(kinds)} clusters of 2 faces or more, {len(bad)} connected but not discs "
          f"(depths {[d for d, _, _ in bad]}), {split} disconnected")
    assert len(bad) == not_disc and all(d <= 1 for d, _, _ in bad), bad[:6]
    assert name != "apple_sphere" or split == 0
    assert atlas_mod.build(mesh, size).not_disc == not_disc


def test_mip_blocks_are_clusters():
    scene, at = _atlas("thin_ring", 128)
    children, _, members = atlas_mod.cluster_tree(scene.mesh, 128)
    rects = atlas_mod.pack(128, children, members)
    checked = 0
    for j in range(len(children)):
        x0, y0, w, h = rects[j]
        if w == h and w > 1:
            assert set(np.unique(at.face[y0:y0 + h, x0:x0 + w])) == set(members[j])
            checked += 1
    assert checked > 100


@pytest.mark.parametrize("name,size", [("thin_ring", 128), ("layered_dielectric", 32)])
def test_texels_lie_on_their_triangle(name, size):
    scene, at = _atlas(name, size)
    V, F = scene.mesh.vertices, scene.mesh.faces
    tri = V[F[at.face]]                                           # (n, n, 3, 3)
    e1, e2, d = tri[..., 1, :] - tri[..., 0, :], tri[..., 2, :] - tri[..., 0, :], at.position - tri[..., 0, :]
    g = np.stack([np.einsum("...i,...i", e1, e1), np.einsum("...i,...i", e1, e2), np.einsum("...i,...i", e2, e2)], -1)
    r1, r2 = np.einsum("...i,...i", d, e1), np.einsum("...i,...i", d, e2)
    det = g[..., 0] * g[..., 2] - g[..., 1] ** 2
    s = (g[..., 2] * r1 - g[..., 1] * r2) / det
    t = (g[..., 0] * r2 - g[..., 1] * r1) / det
    assert np.all(s > -1e-9) and np.all(t > -1e-9) and np.all(s + t < 1 + 1e-9), "a texel off its triangle"
    gutter = at.area == 0
    assert np.all(np.abs(s + t - 1)[gutter] < 1e-9), "a gutter texel off the long edge"
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    per_face = np.bincount(at.face.reshape(-1), at.area.reshape(-1), minlength=len(F))
    np.testing.assert_allclose(per_face, area, rtol=1e-12)
    assert np.all(per_face > 0), "a triangle without a patch"


# ---------------------------------------------------------------------------- links (no GL)

def test_estimate_is_the_exact_throughput():
    scene, at = _atlas("layered_dielectric", 32)
    m, blk = _coeffs(scene, at), None
    blk = links.blocks(at)
    rows = np.arange(0, at.texels, 7)
    exact = links.throughput(at, m, rows)
    est = links.Estimate(at, blk, m, rows)
    R = len(rows)
    worst = 0.0
    for lv in range(at.levels):
        vv, uu = np.nonzero(blk.area[lv] > 0)
        F = est.get(lv, np.repeat(np.arange(R), len(uu)), np.tile(vv, R), np.tile(uu, R)).reshape(R, len(uu), 3)
        ref = exact[lv][:, vv, uu]
        worst = max(worst, float(np.abs(F - ref).max() / ref.max()))
        if lv == 0:
            assert np.array_equal(F, ref)
    print(f"Barnes-Hut throughput against the exact sum: {worst:.2e} of the largest")
    assert worst < 5e-3
    np.testing.assert_allclose(exact[-1][:, 0, 0], exact[0].sum(axis=(1, 2)), rtol=1e-12)


def _heap_links(est, blk, top, r, L):
    """One receiver's queue, sequentially with heapq (the order of Sec. 4.2.1)."""
    def F(lv, u, v):
        return float(est.get(lv, [r], [v], [u]).mean())
    queue = [(-F(top, 0, 0), top, 0, 0)]
    while True:
        refinable = [q for q in queue if q[1] > 0]
        if not refinable:
            break
        best = min(refinable)
        lv, u, v = best[1] - 1, 2 * best[2], 2 * best[3]
        kids = [(lv, u + du, v + dv) for dv in (0, 1) for du in (0, 1) if blk.area[lv][v + dv, u + du] > 0]
        if len(queue) - 1 + len(kids) > L:
            break
        queue.remove(best)
        for k in kids:
            heapq.heappush(queue, (-F(*k), *k))
    return sorted((lv, u, v) for _, lv, u, v in queue)


@pytest.mark.parametrize("L", [4, 16, 40])
def test_adaptive_queue_is_the_sequential_one(L):
    scene, at = _atlas("backlit_slab", 32)
    m, blk = _coeffs(scene, at), links.blocks(at)
    lk = links.adaptive(at, blk, m, L)
    pick = np.random.default_rng(3).choice(at.texels, 12, replace=False)
    est = links.Estimate(at, blk, m, pick)
    for i, b in enumerate(pick):
        used = lk.node[b][lk.node[b] >= 0]
        mine = sorted(zip(*(x.tolist() for x in links.decode(used))))
        assert mine == _heap_links(est, blk, at.levels - 1, i, L), f"texel {b}"
        assert len(mine) == lk.count[b] <= L
    # the links of a texel tile the surface: their blocks are disjoint and cover every patch
    for b in pick:
        cover = np.zeros((at.size, at.size), int)
        for lv, u, v in zip(*links.decode(lk.node[b][lk.node[b] >= 0])):
            s = 1 << int(lv)
            cover[v * s:(v + 1) * s, u * s:(u + 1) * s] += 1
        assert np.all(cover[at.area > 0] == 1) and cover.max() == 1


def test_level_zero_links_are_the_midpoint_rule():
    scene, at = _atlas("backlit_slab", 16)
    m, blk = _coeffs(scene, at), links.blocks(at)
    lk = links.non_adaptive(at, blk, m, 0)
    rng = np.random.default_rng(1)
    flux = rng.random((1, at.texels, 3)) * at.area.reshape(1, -1, 1)
    got = twin_atlas.gather(lk, twin_atlas.radiosity_map(at, flux))
    x, a = at.position.reshape(-1, 3), at.area.reshape(-1)
    for b in rng.choice(at.texels, 6, replace=False):
        mb = {k: (v[b] if isinstance(v, np.ndarray) and v.ndim == 2 else v) for k, v in m.items()}
        rd = links.kernels.rd_dipole(np.linalg.norm(x - x[b], axis=1)[:, None], mb)
        e = flux[0] / np.where(a > 0, a, 1.0)[:, None]
        ref = (rd * a[:, None] * e).sum(axis=0) - rd[b] * a[b] * e[b] + links.rd_disc(np.sqrt(a[b] / np.pi), mb) * e[b]
        np.testing.assert_allclose(got[b], ref, rtol=1e-10)


@pytest.mark.parametrize("level", [None, 1, 3])
def test_uniform_irradiance_gathers_the_total_throughput(level):
    """With ``E = 1`` everywhere, ``B_b`` is ``b``'s whole throughput ``sum_t a_t R_d`` (the links' ``G``
    undo the MIP-map's mean over ``4^l`` texels and the cluster's area)."""
    scene, at = _atlas("layered_dielectric", 32)
    m, blk = _coeffs(scene, at), links.blocks(at)
    lk = links.adaptive(at, blk, m, 16) if level is None else links.non_adaptive(at, blk, m, level)
    b = twin_atlas.gather(lk, twin_atlas.radiosity_map(at, np.repeat(at.area.reshape(1, -1, 1), 3, axis=2)))
    rows = np.arange(0, at.texels, 11)
    total = links.throughput(at, m, rows)[-1][:, 0, 0]
    err = float(np.abs(b[rows] - total).max() / total.max())
    print(f"links {'adaptive' if level is None else f'level {level}'}: B against the total throughput {err:.1e}")
    assert err < 5e-3


# ---------------------------------------------------------------------------- GL

def _pass_by_pass(res, scene):
    d = res.debug
    at, lk = d["atlas"], d["links"]
    P = at.texels
    flux, _ = twin.irradiance(at.position.reshape(P, 3), at.normal.reshape(P, 3), at.area.reshape(P), scene.lights,
                              scene.boundary.eta, d["flux"][..., 3])
    mips = twin_atlas.radiosity_map(at, flux)
    for lv, (gl, ref) in enumerate(zip(d["radiosity"], mips)):
        close(gl, ref, f"{scene.name} pass 1, MIP level {lv}")
    scatter = twin_atlas.gather(lk, mips).reshape(at.size, at.size, 3)
    close(d["scatter"], scatter, f"{scene.name} pass 2")
    f, m = d["fragments"], res.mask
    # the half-texel gutter: every fragment's bilinear lookup weighs texels of one triangle only
    x = f["uv"][m] * at.size - 0.5
    x0, fr = np.floor(x).astype(int), x - np.floor(x)
    owners, weights = [], []
    for dx in (0, 1):
        for dy in (0, 1):
            owners.append(at.face[np.clip(x0[:, 1] + dy, 0, at.size - 1), np.clip(x0[:, 0] + dx, 0, at.size - 1)])
            weights.append((fr[:, 0] if dx else 1 - fr[:, 0]) * (fr[:, 1] if dy else 1 - fr[:, 1]))
    owners, weights = np.stack(owners, 1), np.stack(weights, 1)
    main = owners[np.arange(len(x)), np.argmax(weights, axis=1)][:, None]
    stray = np.sum(np.where(owners != main, weights, 0.0), axis=1)
    assert stray.max() < 1e-3, f"{np.sum(stray >= 1e-3)} fragments weigh another triangle's texels (up to " \
                               f"{stray.max():.3f})"
    ref = twin_atlas.shade(scatter, f["uv"][m], f["position"][m], f["normal"][m], scene.camera.origin,
                           scene.boundary.eta)
    close(res.subsurface[m], ref, f"{scene.name} pass 3")


@pytest.mark.gl
@pytest.mark.parametrize("name,kw", [("layered_dielectric", {"atlas_size": 32, "links": 16}),
                                     ("backlit_slab", {"atlas_size": 16, "link_level": 1})])
def test_gl_matches_twin_pass_by_pass(dipole_renderer, name, kw):
    scene = load_scene(name).with_resolution(16, 16)
    res = dipole_renderer.render(scene, "dipole", DipoleParams(gather="atlas", terms="diffusion", **kw), debug=True)
    _pass_by_pass(res, scene)


@pytest.mark.gl
def test_gl_in_chunks(dipole_renderer, monkeypatch):
    """Pass 2 over the links in several dispatches (the chunk shrunk to 5 links) is still the twin's."""
    monkeypatch.setattr(budget, "atlas_chunk", lambda b=budget.ITERATION_BUDGET: 5)
    scene = load_scene("layered_dielectric").with_resolution(16, 16)
    res = dipole_renderer.render(scene, "dipole", DipoleParams(gather="atlas", atlas_size=16, links=16,
                                                               terms="diffusion"), debug=True)
    assert res.info["dispatches"] == 4
    _pass_by_pass(res, scene)


@pytest.mark.gl
def test_converges_to_the_dense_gather(dipole_renderer):
    """As links grow, and as the atlas grows at level 0, the error against the dense gather falls."""
    scene = load_scene("backlit_slab").with_resolution(16, 16)
    dense = dipole_renderer.render(scene, "dipole", DipoleParams(terms="diffusion")).subsurface

    def err(**kw):
        img = dipole_renderer.render(scene, "dipole", DipoleParams(gather="atlas", terms="diffusion", **kw)).subsurface
        return float(np.sum((img - dense) ** 2) / np.sum(dense ** 2))

    by_links = [err(atlas_size=32, links=L) for L in (4, 16, 64)]
    by_size = [err(atlas_size=n, link_level=0) for n in (8, 16, 32)]
    print(f"relMSE against dense: links 4/16/64 {by_links}; level 0 at 8/16/32 {by_size}")
    assert by_links[0] > by_links[1] > by_links[2] and by_size[0] > by_size[1] > by_size[2]
    assert by_size[2] < 2e-3


@pytest.mark.gl
def test_render_checks_itself(dipole_renderer, monkeypatch):
    scene = load_scene("layered_dielectric").with_resolution(16, 16)
    params = DipoleParams(gather="atlas", atlas_size=16, links=8, terms="diffusion")
    c = dipole_renderer.render(scene, "dipole", params).info["check"]
    assert c["points"] == check.CHECK_POINTS and c["max_rel_diff"] <= check.CHECK_RTOL and c["twin_evaluations"] > 0
    real = twin_atlas.gather
    monkeypatch.setattr(twin_atlas, "gather", lambda *a, **k: 1.01 * real(*a, **k))
    with pytest.raises(ResultRefused, match="layered_dielectric: dipole atlas gather: the GL result disagrees"):
        dipole_renderer.render(scene, "dipole", params)


@pytest.mark.gl
def test_both_adds_single(dipole_renderer):
    scene = load_scene("layered_dielectric").with_resolution(16, 16)
    kw = {"gather": "atlas", "atlas_size": 16, "links": 8}
    diff = dipole_renderer.render(scene, "dipole", DipoleParams(terms="diffusion", **kw)).subsurface
    both = dipole_renderer.render(scene, "dipole", DipoleParams(terms="both", **kw), debug=True)
    s1 = both.debug["single_pass"]["single"]
    assert np.abs(s1).max() > 0
    assert np.abs(both.subsurface - (diff + s1)).max() <= 1e-5 * np.abs(both.subsurface).max()


@pytest.mark.gl
def test_refusals_before_any_frame_work(dipole_renderer):
    scene = small_scene("apple_sphere")
    with pytest.raises(InputError, match=r"^--atlas-size: atlas_size: the mesh has 5,120 triangles, more than the "
                                         r"4,096 texels of a 64 x 64 atlas .*; raise --atlas-size to 128 or more$"):
        dipole_renderer.render(scene, "dipole", DipoleParams(gather="atlas", atlas_size=64))
    with pytest.raises(InputError, match=r"^--gather: gather: the atlas gather precomputes .*; use --method dipole"):
        dipole_renderer.render(scene, "dirpole", DipoleParams(gather="atlas"))


@pytest.mark.gl
def test_a_link_table_over_the_budget_is_refused(dipole_renderer, monkeypatch):
    from dipole_gl import atlas_gather

    monkeypatch.setattr(atlas_gather, "storage_limit", lambda ctx: 1_000_000)
    scene = load_scene("layered_dielectric").with_resolution(8, 8)
    with pytest.raises(InputError, match=r"^--link-level: link_level: level 0 links every texel of a 16 x 16 atlas "
                                         r"to up to 256 nodes: a table of 1,310,720 bytes, over the 1,000,000 that "
                                         r"fit; use --link-level 1 or more"):
        dipole_renderer.render(scene, "dipole", DipoleParams(gather="atlas", atlas_size=16, link_level=0))
    with pytest.raises(InputError, match=r"^--links: links: 256 links per texel of a 16 x 16 atlas need a table "
                                         r"of 1,310,720 bytes, over the 1,000,000 that fit; use --links 195 or less"):
        dipole_renderer.render(scene, "dipole", DipoleParams(gather="atlas", atlas_size=16, links=256))
    assert dipole_renderer.render(scene, "dipole", DipoleParams(gather="atlas", atlas_size=16, link_level=1,
                                                                terms="diffusion")).info["link_slots"] > 0


def test_non_manifold_mesh_is_refused():
    from dataclasses import replace

    scene = load_scene("backlit_slab")
    mesh = scene.mesh
    extra = np.array([[mesh.faces[0][0], mesh.faces[0][1], 0]])      # a third triangle on face 0's first edge
    far = np.vstack([mesh.vertices, mesh.vertices[:1] + 5.0])
    extra[0, 2] = len(mesh.vertices)
    bad = replace(mesh, vertices=far, faces=np.vstack([mesh.faces, extra]),
                  normals=np.vstack([mesh.normals, mesh.normals[:1]]))
    with pytest.raises(InputError, match=r"^mesh: faces: the mesh is non-manifold: edge .* is shared by 3 triangles"):
        atlas_mod.build(bad, 16)


@pytest.mark.parametrize("kw,msg", [
    ({"atlas_size": 100}, r"^--atlas-size: atlas_size: must be a power of two, got 100"),
    ({"atlas_size": 4}, r"^--atlas-size: atlas_size: must be an integer in \[8, 4096\]"),
    ({"links": 0}, r"^--links: links: must be an integer in \[1, 65536\], got 0"),
    ({"link_level": 8}, r"^--link-level: link_level: level 8 is above the atlas's top level 7"),
    ({"link_level": 2, "links": 4}, r"^--links: links: the non-adaptive scheme links every texel"),
    ({"link_level": 2, "adaptive": True}, r"^--adaptive: adaptive: the adaptive scheme takes no --link-level"),
    ({"adaptive": False}, r"^--adaptive: adaptive: the non-adaptive scheme needs a level; give --link-level")])
def test_bad_atlas_settings_are_one_line(kw, msg):
    with pytest.raises(InputError, match=msg):
        DipoleParams(gather="atlas", **kw)


def test_atlas_settings_belong_to_the_atlas_gather():
    assert DipoleParams(gather="atlas").as_dict() == {"gather": "atlas", "atlas_size": 128, "links": 16,
                                                      "adaptive": True, "shadow_size": 1024, "terms": "both"}
    assert DipoleParams(gather="atlas", link_level=3).as_dict()["adaptive"] is False
    with pytest.raises(InputError, match=r"^--links: links: belongs to gather=atlas, not gather=dense"):
        DipoleParams(links=4)


def test_bad_atlas_on_the_command_line(capsys, tmp_path):
    from harness.cli.main import main

    code = main(["render", "apple_sphere", "--method", "dipole", "--gather", "atlas", "--atlas-size", "64",
                 "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("error: --atlas-size: atlas_size: the mesh has 5,120 "
                                                             "triangles"), (code, err)


def test_scheme_flags_on_the_command_line():
    from harness.methods.params import params_from_cli

    p = params_from_cli("dipole", {"gather": "atlas", "adaptive": "false", "link_level": "2", "atlas_size": "32"})
    assert (p.adaptive, p.link_level, p.links) == (False, 2, None)
    assert params_from_cli("dipole", {"gather": "atlas", "adaptive": "true", "links": "8"}).links == 8
