"""The hierarchical gather (Jensen & Buhler 2002; ``dipole_gl.octree``, ``gather_tree.comp``, ``dipole_gl.twin_tree``).

* the octree against a recursive subdivision written here (the node set), its cells against the
  samples' positions, its aggregates against direct sums over the samples inside each cell;
* the twin's descent (all nodes at once, a difference array) against a sequential stackless walk;
* at ``epsilon = 0`` the twin equals the dense gather's twin (float64, the same samples in another
  order: within 1e-10), and the GL image the dense GL image (float32: within 1e-5 of the largest value);
* GL against the twin at every covered pixel (``max |GL - twin| <= 1e-4 max |twin|``, as
  ``tests/test_dipole_gl.py``), node visits per pixel equal, also past llvmpipe's 65,535 loop
  iterations per invocation (``apple_sphere`` at ``epsilon = 0``);
* as ``epsilon`` falls, the image approaches the dense one; the render's self-check; bad ``epsilon``.
"""

import numpy as np
import pytest

from harness.errors import InputError, ResultRefused
from harness.regression.accuracy import small_scene
from harness.scene import load_scene
from dipole_gl import budget, check, octree, twin, twin_tree
from dipole_gl.medium import scene_material
from dipole_gl.params import DEFAULT_EPSILON, DipoleParams
from dipole_gl.sampling import NEAR_RADIUS, surface_samples
from tests.test_dipole_gl import close

TOP = octree.MORTON_BITS


# ---------------------------------------------------------------------------- the octree (no GL)

def _points(n=400, seed=0):
    rng = np.random.default_rng(seed)
    p = rng.random((n, 3)) * [2.0, 1.0, 0.5]
    p[7] = p[3]                                            # two samples in one finest cell
    p[20:40] = p[20] + rng.random((20, 3)) * 1e-4          # a tight cluster: a deep chain of one-child cells
    n_ = rng.normal(size=(n, 3))
    return p, n_ / np.linalg.norm(n_, axis=1, keepdims=True), rng.random(n) + 0.1


def _reference_nodes(q, idx, depth=0):
    """{(samples, depth)}: the cell at ``depth`` holding ``idx`` descends while one child holds them all."""
    if len(idx) == 1:
        return {(frozenset(idx.tolist()), TOP)}
    while depth < TOP:
        keys = q[idx] >> (TOP - depth - 1)
        if len(np.unique(keys, axis=0)) > 1:
            break
        depth += 1
    out = {(frozenset(idx.tolist()), depth)}
    if depth == TOP:                                       # one finest cell: its samples are leaves
        return out | {(frozenset([i]), TOP) for i in idx.tolist()}
    keys = q[idx] >> (TOP - depth - 1)
    for key in np.unique(keys, axis=0):
        out |= _reference_nodes(q, idx[np.all(keys == key, axis=1)], depth + 1)
    return out


def test_octree_matches_a_recursive_subdivision():
    p, n, a = _points()
    tree = octree.build(p, n, a)
    _, q, _, _ = octree.morton_codes(p)
    mine = {(frozenset(tree.order[f:e].tolist()), int(d)) for f, e, d in zip(tree.first, tree.end, tree.depth)}
    ref = _reference_nodes(q, np.arange(len(p)))
    assert mine == ref and tree.nodes == len(ref)
    again = octree.build(p, n, a)
    assert all(np.array_equal(getattr(tree, k), getattr(again, k)) for k in ("order", "first", "skip", "cell"))


def test_octree_order_skip_and_cells():
    p, n, a = _points(seed=1)
    tree = octree.build(p, n, a)
    assert np.array_equal(np.sort(tree.order), np.arange(len(p)))
    for j in range(tree.nodes):
        f, e, s = tree.first[j], tree.end[j], tree.skip[j]
        x = tree.positions[f:e]
        assert np.all(np.abs(x - tree.cell[j, :3]) <= tree.cell[j, 3] * (1 + 1e-9)), f"node {j}: a sample outside its cell"
        if e - f == 1:
            assert tree.internal[j] < 0 and s == j + 1
            continue
        # its children: from j + 1 along the skips, they tile [f, e) in order, at least two
        kids, c = [], j + 1
        while c < s:
            kids.append(c)
            c = tree.skip[c]
        assert c == s and len(kids) >= 2, f"node {j}"
        assert tree.first[kids[0]] == f and tree.end[kids[-1]] == e
        assert np.array_equal(tree.end[kids[:-1]], tree.first[kids[1:]])
        assert np.all((tree.depth[kids] > tree.depth[j]) | ((tree.depth[j] == TOP) & (tree.internal[kids] < 0)))
    assert np.array_equal(np.sort(tree.internal[tree.internal >= 0]), np.arange(tree.internal_count))


def test_aggregates_are_sums_over_the_cells_samples():
    p, n, a = _points(seed=2)
    tree = octree.build(p, n, a)
    rng = np.random.default_rng(3)
    flux = rng.random((2, len(p), 3)) * (rng.random((2, len(p), 1)) > 0.3)       # two lights, some samples unlit
    lights = [type("L", (), {"position": (3.0, 2.0, 1.0)}), type("L", (), {"position": (-2.0, 0.5, 4.0)})]
    to_light = octree.to_lights(tree, lights)
    agg = octree.aggregate(tree, flux[:, tree.order], to_light)
    _, q, _, _ = octree.morton_codes(p)
    for j in np.nonzero(tree.internal >= 0)[0]:
        k, d = tree.internal[j], tree.depth[j]
        cell_q = q[tree.order[tree.first[j]]] >> (TOP - d)
        inside = np.nonzero(np.all(q >> (TOP - d) == cell_q, axis=1))[0]            # the samples in the cell
        fl = flux[:, inside]
        w = fl.sum(axis=(0, 2))
        to = np.stack([np.asarray(lt.position) - p[inside] for lt in lights])
        to /= np.linalg.norm(to, axis=2, keepdims=True)
        mean_to = np.einsum("ls,lsc->lc", fl.sum(axis=2), to)
        mean_n = (w[:, None] * n[inside]).sum(axis=0)
        np.testing.assert_allclose(agg.area[k], a[inside].sum(), rtol=1e-12)
        np.testing.assert_allclose(agg.weight[k], w.sum(), rtol=1e-12)
        np.testing.assert_allclose(agg.flux[:, k], fl.sum(axis=1), rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(agg.total[k], fl.sum(axis=(0, 1)), rtol=1e-12, atol=1e-14)
        if w.sum() > 0:
            np.testing.assert_allclose(agg.centroid[k], (w[:, None] * p[inside]).sum(axis=0) / w.sum(), rtol=1e-10)
            np.testing.assert_allclose(agg.normal[k], mean_n / np.linalg.norm(mean_n), rtol=1e-9, atol=1e-12)
            for li in range(2):
                if fl[li].sum() > 0:
                    np.testing.assert_allclose(agg.to_light[li, k], mean_to[li] / np.linalg.norm(mean_to[li]),
                                               rtol=1e-9, atol=1e-12)


# ---------------------------------------------------------------------------- the twin (no GL)

def _walk(tree, agg, xo, epsilon, rho):
    """The shader's descent, sequentially (float64): (leaf samples, accepted nodes, visits)."""
    i, leaves, accepted, visits = 0, [], [], 0
    while i < tree.nodes:
        visits += 1
        k = tree.internal[i]
        if k < 0:
            leaves.append(tree.first[i])
            i = tree.skip[i]
            continue
        if agg.weight[k] <= 0:
            i = tree.skip[i]
            continue
        dq = np.maximum(np.abs(xo - tree.cell[i, :3]) - tree.cell[i, 3], 0.0)
        if dq @ dq < rho * rho or agg.area[k] > epsilon * np.sum((agg.centroid[k] - xo) ** 2):
            i += 1
            continue
        accepted.append(k)
        i = tree.skip[i]
    return np.array(leaves), np.array(accepted), visits


def _scene_tree(name, size=16, spacing=1.0):
    scene = load_scene(name).with_resolution(size, size)
    mat = scene_material(scene)
    tree = octree.build(*surface_samples(scene.mesh, spacing * mat.mfp))
    return scene, mat, tree


def _twin_irradiance(scene, tree, vis=None):
    vis = np.ones((len(scene.lights), len(tree.positions))) if vis is None else vis
    for li, light in enumerate(scene.lights):                           # unlit: the far side of each light
        vis[li] *= np.sum((np.asarray(light.position) - tree.positions) * tree.normals, axis=1) > 0
    return twin.irradiance(tree.positions, tree.normals, tree.areas, scene.lights, scene.boundary.eta, vis)


@pytest.mark.parametrize("epsilon", [0.0, 0.03, 0.3, 2.0])
def test_twin_descent_is_the_sequential_walk(epsilon):
    scene, mat, tree = _scene_tree("two_lights")
    flux, dirs = _twin_irradiance(scene, tree)
    agg = octree.aggregate(tree, flux, dirs)
    rho = NEAR_RADIUS * mat.mfp
    for s in np.random.default_rng(4).choice(len(tree.positions), 5, replace=False):
        xo = tree.positions[s] + 0.3 * mat.mfp * tree.normals[s]
        leaves, nodes, visits = twin_tree.visited_nodes(tree, agg, xo, epsilon, rho)
        ref = _walk(tree, agg, xo, epsilon, rho)
        assert np.array_equal(leaves, ref[0]) and np.array_equal(np.sort(nodes), np.sort(ref[1])) and visits == ref[2]
        if epsilon > 0:
            assert len(nodes) > 0, "a positive epsilon should accept some node"


@pytest.mark.parametrize("kernel", ["dipole", "dirpole"])
@pytest.mark.parametrize("name", ["two_lights", "layered_dielectric"])
def test_twin_at_epsilon_zero_is_the_dense_gather(kernel, name):
    scene, mat, tree = _scene_tree(name)
    flux, dirs = _twin_irradiance(scene, tree)
    agg = octree.aggregate(tree, flux, dirs)
    pick = np.random.default_rng(5).choice(len(tree.positions), 6, replace=False)
    xo, no = tree.positions[pick], tree.normals[pick]
    vis = np.ones((len(pick), len(scene.lights)))
    args = (scene.camera.origin,)
    hier, visits = twin_tree.tree_gather(kernel, tree, agg, xo, no, *args, flux, dirs, mat, scene.boundary.eta, mat.mfp,
                                         scene.lights, vis, 0.0)
    dense = twin.dense_gather(kernel, xo, no, *args, (tree.positions, tree.normals), flux, dirs, mat,
                              scene.boundary.eta, mat.mfp, scene.lights, vis)
    err = np.abs(hier - dense).max() / np.abs(dense).max()
    print(f"{name} {kernel}: epsilon = 0 against the dense twin: {err:.1e}, {visits.mean():.0f} visits per point")
    assert err < 1e-10


# ---------------------------------------------------------------------------- GL

@pytest.mark.gl
@pytest.mark.parametrize("kernel", ["dipole", "dirpole"])
@pytest.mark.parametrize("name,epsilon", [("two_lights", 0.0), ("two_lights", 0.1), ("layered_dielectric", 0.3)])
def test_gl_matches_twin(dipole_renderer, kernel, name, epsilon):
    """Irradiance, aggregates and descent at every covered pixel; the node visits per pixel equal."""
    scene = load_scene(name).with_resolution(16, 16)
    mat = scene_material(scene)
    res = dipole_renderer.render(scene, kernel, DipoleParams(gather="hierarchical", epsilon=epsilon, terms="diffusion"), debug=True)
    d = res.debug
    tree = d["tree"]
    flux, dirs = twin.irradiance(tree.positions, tree.normals, tree.areas, scene.lights, scene.boundary.eta,
                                 d["flux"][..., 3])
    close(d["flux"][..., :3], flux, f"{name} {kernel} irradiance")
    agg = octree.aggregate(tree, flux, dirs)
    m = res.mask
    ref, visits = twin_tree.tree_gather(kernel, tree, agg, d["position"][m], d["normal"][m], scene.camera.origin, flux,
                                        dirs, mat, scene.boundary.eta, d["spacing"], scene.lights, d["visibility"][m],
                                        epsilon)
    close(res.subsurface[m], ref, f"{name} {kernel} hierarchical gather, epsilon {epsilon}")
    gl_visits = d["state"][..., 1][m]
    print(f"visits per pixel: GL {gl_visits.mean():.1f}, twin {visits.mean():.1f}; dispatches {res.info['dispatches']}")
    assert np.array_equal(gl_visits, visits), f"{np.count_nonzero(gl_visits != visits)} pixels visit other nodes"


@pytest.mark.gl
@pytest.mark.parametrize("kernel", ["dipole", "dirpole"])
def test_gl_past_the_loop_limit(dipole_renderer, kernel):
    """``apple_sphere`` at ``epsilon = 0``: every lit node, over 65,535 loop iterations per invocation in all."""
    scene = small_scene("apple_sphere").with_resolution(12, 12)
    mat = scene_material(scene)
    spacing = {"dipole": 0.6, "dirpole": 1.0}[kernel]
    res = dipole_renderer.render(scene, kernel, DipoleParams(gather="hierarchical", epsilon=0.0, spacing=spacing,
                                                             terms="diffusion"), debug=True)
    d, tree = res.debug, res.debug["tree"]
    L = len(scene.lights)
    iterations = res.info["max_visits"] * budget.far_iterations_per_sample(kernel, L)
    print(f"{kernel}: {res.info['max_visits']:,} visits, {iterations:,} loop iterations unchunked, "
          f"{res.info['dispatches']} dispatches")
    assert iterations > budget.LLVMPIPE_LOOP_LIMIT and res.info["dispatches"] > 1
    flux, dirs = twin.irradiance(tree.positions, tree.normals, tree.areas, scene.lights, scene.boundary.eta,
                                 d["flux"][..., 3])
    agg = octree.aggregate(tree, flux, dirs)
    m = res.mask
    ref, _ = twin_tree.tree_gather(kernel, tree, agg, d["position"][m], d["normal"][m], scene.camera.origin, flux, dirs,
                                   mat, scene.boundary.eta, d["spacing"], scene.lights, d["visibility"][m], 0.0)
    close(res.subsurface[m], ref, f"apple_sphere {kernel} hierarchical gather, {len(tree.positions):,} samples")


@pytest.mark.gl
@pytest.mark.parametrize("kernel", ["dipole", "dirpole"])
def test_converges_to_the_dense_gather(dipole_renderer, kernel):
    """At epsilon = 0 the image is the dense gather's (float32 sums in another order); as epsilon falls,
    the relative mean squared error against it falls."""
    scene = load_scene("sphere_homogeneous").with_resolution(16, 16)
    dense = dipole_renderer.render(scene, kernel, DipoleParams(terms="diffusion")).subsurface
    err = {}
    for eps in (1.0, 0.3, 0.1, 0.0):
        img = dipole_renderer.render(scene, kernel, DipoleParams(gather="hierarchical", epsilon=eps, terms="diffusion")).subsurface
        err[eps] = float(np.sum((img - dense) ** 2) / np.sum(dense ** 2))
        if eps == 0.0:
            worst = float(np.abs(img - dense).max() / np.abs(dense).max())
    print(f"{kernel}: relMSE against dense {err}; at epsilon 0 max |diff| = {worst:.1e} of the largest value")
    assert worst < 1e-5
    assert err[1.0] > err[0.3] > err[0.1] > err[0.0]


@pytest.mark.gl
def test_render_checks_itself(dipole_renderer, monkeypatch):
    scene = load_scene("two_lights").with_resolution(16, 16)
    params = DipoleParams(gather="hierarchical", epsilon=0.1)
    c = dipole_renderer.render(scene, "dirpole", params).info["check"]
    assert c["points"] == check.CHECK_POINTS and c["max_rel_diff"] <= check.CHECK_RTOL and c["twin_evaluations"] > 0
    real = twin_tree.tree_gather
    monkeypatch.setattr(twin_tree, "tree_gather", lambda *a, **k: (1.01 * real(*a, **k)[0], real(*a, **k)[1]))
    with pytest.raises(ResultRefused, match="two_lights: dirpole hierarchical gather: the GL result disagrees"):
        dipole_renderer.render(scene, "dirpole", params)


@pytest.mark.gl
def test_an_octree_over_the_storage_limit_is_refused(dipole_renderer, monkeypatch):
    from dipole_gl import tree_gather

    monkeypatch.setattr(tree_gather, "storage_limit", lambda ctx: 500_000)
    scene = load_scene("two_lights").with_resolution(8, 8)
    with pytest.raises(InputError, match=r"^--spacing: spacing: the hierarchical gather's octree of 24,576 samples needs "
                                         r"a storage buffer of 827,200 bytes, over this GL's 500,000; raise"):
        dipole_renderer.render(scene, "dipole", DipoleParams(gather="hierarchical", spacing=0.5))
    assert dipole_renderer.render(scene, "dipole", DipoleParams(gather="hierarchical")).info["samples"] == 6144


# ---------------------------------------------------------------------------- parameters

@pytest.mark.parametrize("value", [-0.1, float("nan"), float("inf"), 13.0, True, "0.1"])
def test_bad_epsilon_is_one_line(value):
    with pytest.raises(InputError, match=r"^--epsilon: epsilon: must be a number in \[0, 12.5664\], got .*; change"):
        DipoleParams(gather="hierarchical", epsilon=value)


def test_epsilon_belongs_to_the_hierarchical_gather():
    assert DipoleParams(gather="hierarchical").as_dict() == {"gather": "hierarchical", "spacing": 1.0,
                                                             "epsilon": DEFAULT_EPSILON, "shadow_size": 1024,
                                                             "terms": "both"}
    with pytest.raises(InputError, match=r"^--epsilon: epsilon: belongs to gather=hierarchical, not gather=dense"):
        DipoleParams(epsilon=0.1)
    assert DipoleParams(gather="hierarchical", spacing=2.0).spacing == 2.0


def test_bad_epsilon_on_the_command_line(capsys, tmp_path):
    from harness.cli.main import main

    code = main(["render", "two_lights", "--method", "dipole", "--gather", "hierarchical", "--epsilon", "-1",
                 "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("error: --epsilon: epsilon: must be a number"), (code, err)
