"""The audit of every shader loop against llvmpipe's 65,535 iterations per invocation (``dipole_gl.budget``).

Reads every ``for``/``while`` loop of ``dipole_gl/shaders/`` and ``sslpv_gl/shaders/`` (a loop that
the table below does not know stops the script), and computes, from the suite's scenes at their
committed small size (``harness.regression.accuracy.small_scene``), what bounds each loop and the
largest number of loop iterations one invocation runs on the suite: as one dispatch (the whole
loop in one invocation) and as chunked now (the largest dispatch). The rivals' settings are the
nightly's (``harness/regression/nightly_matrix.toml``: dense at the default spacing, vertex at
density 0.5 and range 2) under the sizing rule ``fit = coarsen`` (``dipole_gl.sizing``); the
vertex gather's longest row comes from the real precomputation (remeshing, neighbourhoods). The
hierarchical gather's descent is bounded by its octree's node count (``dipole_gl.octree``, at the
default spacing under the same rule without a pixel-pair budget): at ``epsilon = 0`` a pixel visits
every lit node. The atlas gather's pass 2 loops over a texel's links, as many as its setting gives
(the same for every scene).

    .venv/bin/python benchmarks/shader_loops.py            # prints the markdown table
    .venv/bin/python benchmarks/shader_loops.py --write    # and writes docs/benchmarks/shader_loops.md
"""

import argparse
import re
import sys
from pathlib import Path

import numpy as np

from harness.errors import InputError
from harness.regression.accuracy import small_scene
from harness.scene import list_scenes
from dipole_gl import budget, octree, single, sizing
from dipole_gl.medium import scene_material
from dipole_gl.params import DipoleParams
from dipole_gl.sampling import N_PHI, radial_nodes, sample_count, surface_samples
from dipole_gl.vertex import precompute

REPO = Path(__file__).resolve().parents[1]
N_RAD = len(radial_nodes()[0])
C = budget.DIRPOLE_CALL_ITERATIONS
NIGHTLY_VERTEX = {"density": 0.5, "range": 2.0}
#: The atlas gather's links per texel at the recommended budget (bench_atlas.py suite --budget 128:links=64).
ATLAS_LINKS = 64


def scene_figures(name, vertex=True):
    """L, the dense samples at the nightly's spacing under the sizing rule, the vertex gather's longest row."""
    scene = small_scene(name)
    mat = scene_material(scene)
    pixels = scene.camera.width * scene.camera.height
    spacing = sizing.dense_spacing(scene.mesh, mat.mfp, DipoleParams().spacing, pixels)
    out = {"scene": name, "L": len(scene.lights), "samples": sample_count(scene.mesh, spacing * mat.mfp),
           "spacing": spacing, "row": None}
    tree_spacing = sizing.dense_spacing(scene.mesh, mat.mfp, DipoleParams().spacing, 1)
    out["nodes"] = octree.build(*surface_samples(scene.mesh, tree_spacing * mat.mfp)).nodes
    if vertex:
        density = sizing.vertex_density(scene.mesh, mat.mfp, mat.diffusion_length, NIGHTLY_VERTEX["density"],
                                        NIGHTLY_VERTEX["range"])
        for _ in range(sizing.RETRIES + 1):                  # as the renderer's retries
            try:
                pre = precompute(scene, mat, "dirpole", density, NIGHTLY_VERTEX["range"], float(scene.boundary.eta))
                break
            except InputError:
                density = sizing.check_density(round(density * sizing.RETRY_FACTOR, 6))
        out.update(row=int(np.diff(pre.offsets).max()), density=density, vertices=len(pre.positions))
    print(f"  {name}: {out}", file=sys.stderr)
    return out


def _largest(figs, f):
    """(value, scene) of the largest ``f(fig)`` on the suite."""
    best = max(figs, key=f)
    return f(best), best["scene"]


def _dense_far(kernel):
    def f(fig):
        return fig["samples"] * budget.far_iterations_per_sample(kernel, fig["L"]) + \
            budget.near_iterations(kernel, fig["L"], N_RAD, N_PHI)
    return f


def _dense_chunked(kernel):
    def f(fig):
        size = budget.dense_chunk(kernel, fig["L"], N_RAD, N_PHI)
        return min(size, fig["samples"]) * budget.far_iterations_per_sample(kernel, fig["L"]) + \
            budget.near_iterations(kernel, fig["L"], N_RAD, N_PHI)
    return f


def _per_item(field, chunk):
    """Iterations of a loop over ``fig[field]`` items (a neighbourhood row, the octree's nodes), each costing the
    far field's iterations per sample; chunked: at most ``chunk(kernel, L)`` items per dispatch."""
    def make(kernel, chunked):
        def f(fig):
            n = fig[field] if not chunked else min(fig[field], chunk(kernel, fig["L"]))
            return n * budget.far_iterations_per_sample(kernel, fig["L"])
        return f
    return make


_vertex = _per_item("row", budget.vertex_chunk)


CUBE_K = DipoleParams(gather="cubemap").samples


def _cubemap(kernel, chunked):
    """Iterations of one cubemap-gather invocation at the default k (``dipole_gl.cubemap.gather_chunk``)."""
    per = 1 + (C if kernel == "dirpole" else 0)

    def f(fig):
        from dipole_gl.cubemap import gather_chunk

        n = CUBE_K if not chunked else min(CUBE_K, gather_chunk(kernel, fig["L"]))
        return fig["L"] * (1 + n * per)
    return f


_tree = _per_item("nodes", budget.tree_chunk)


def loops(figs):
    """Each known loop: (file, text that identifies its line, what it is, bound, one dispatch, chunked, chunked?)."""
    L = lambda fig: fig["L"]                                                          # noqa: E731
    return [
        ("dipole_gl/shaders/gather_dense.comp", "for (int i = u_first; i < u_end; ++i)",
         "dense far field: surface samples (dipole)", "samples S",
         _largest(figs, _dense_far("dipole")), _largest(figs, _dense_chunked("dipole")), "yes"),
        ("dipole_gl/shaders/gather_dense.comp", "for (int l = 0; l < u_n_lights; ++l) {\n            vec4 f",
         "dense far field: samples x lights x kernel (dirpole)", f"S (1 + L (1 + {C}))",
         _largest(figs, _dense_far("dirpole")), _largest(figs, _dense_chunked("dirpole")), "yes"),
        ("dipole_gl/shaders/gather_dense.comp", "for (int k = 0; k < u_n_rad; ++k) {\n            float r",
         "dense near field (dirpole): lights x radial nodes", f"L x {N_RAD}", None, None, "no: part of the last dispatch"),
        ("dipole_gl/shaders/gather_dense.comp", "for (int j = 0; j < u_n_phi; ++j)",
         "dense near field (dirpole): x angles x kernel", f"L x {N_RAD} x {N_PHI} (1 + {C})",
         _largest(figs, lambda fig: budget.near_iterations("dirpole", L(fig), N_RAD, N_PHI)), None,
         "no: fixed per light, counted in the budget"),
        ("dipole_gl/shaders/gather_dense.comp", "for (int l = 0; l < u_n_lights; ++l) {\n        vec3 wi;\n        vec3 e",
         "dense near field (dirpole): lights", "L <= 8", _largest(figs, L), None, "no"),
        ("dipole_gl/shaders/gather_dense.comp", "for (int l = 0; l < u_n_lights; ++l) {\n        vec3 wi;\n        e +=",
         "dense near field (dipole): lights", "L <= 8", _largest(figs, L), None, "no"),
        ("dipole_gl/shaders/gather_dense.comp", "for (int k = 0; k < u_n_rad; ++k) {\n            float r = u_rho * u_rad_t[k];\n            acc",
         "dense near field (dipole): radial nodes", f"{N_RAD}", (N_RAD, "all"), None, "no"),
        ("dipole_gl/shaders/gather_vertex.comp", "for (int k = offsets[o] + u_k0; k < end; ++k)",
         "vertex gather: neighbours (dipole)", "longest neighbourhood row", _largest(figs, _vertex("dipole", False)),
         _largest(figs, _vertex("dipole", True)), "yes (a row can exceed the budget)"),
        ("dipole_gl/shaders/gather_vertex.comp", "for (int l = 0; l < u_n_lights; ++l)",
         "vertex gather: neighbours x lights x kernel (dirpole)", f"row (1 + L (1 + {C}))",
         _largest(figs, _vertex("dirpole", False)), _largest(figs, _vertex("dirpole", True)),
         "yes (a row can exceed the budget)"),
        ("dipole_gl/shaders/cubemap_gather.comp", "for (int l = 0; l < u_n_lights; ++l) {\n        vec3 wl",
         "cubemap gather: lights", "L <= 8", _largest(figs, L), None, "no"),
        ("dipole_gl/shaders/cubemap_gather.comp", "for (int j = u_first; j < u_end; ++j)",
         f"cubemap gather: lights x disc samples x kernel (dirpole, default k = {CUBE_K})", f"L (1 + k (1 + {C}))",
         _largest(figs, _cubemap("dirpole", False)), _largest(figs, _cubemap("dirpole", True)),
         "yes (k up to 65,536)"),
        ("dipole_gl/shaders/cubemap_combine.comp", "for (int f = 0; f < 6; ++f)",
         "cubemap combination: the six faces", "6", (6, "all"), None, "no"),
        ("dipole_gl/shaders/gather_tree.comp", "while (i < u_nodes && steps < u_steps)",
         "hierarchical descent: octree nodes (dipole)", "octree nodes", _largest(figs, _tree("dipole", False)),
         _largest(figs, _tree("dipole", True)), "yes (a cursor per pixel; dispatched until every pixel is done)"),
        ("dipole_gl/shaders/gather_tree.comp", "for (int l = 0; l < u_n_lights; ++l) {\n                    vec4 f",
         "hierarchical descent: nodes x lights x kernel (dirpole)", f"nodes (1 + L (1 + {C}))",
         _largest(figs, _tree("dirpole", False)), _largest(figs, _tree("dirpole", True)),
         "yes (a cursor per pixel; dispatched until every pixel is done)"),
        ("dipole_gl/shaders/gather_tree.comp", "for (int l = 0; l < u_n_lights; ++l) {\n            vec4 f = agg",
         "hierarchical descent: an accepted node's lights (dirpole)", "L <= 8", _largest(figs, L), None,
         "no: inside the node's cost above"),
        ("dipole_gl/shaders/gather_atlas.comp", "for (int k = u_first; k < u_end; ++k)",
         f"atlas gather (pass 2): links per texel (at {ATLAS_LINKS} links, the suite page's)",
         "links per texel (adaptive: --links; non-adaptive: the level's nodes)", (ATLAS_LINKS, "all"),
         (min(ATLAS_LINKS, budget.atlas_chunk()), "all"),
         "yes (a table within the storage limit can exceed the budget at level 0)"),
        ("dipole_gl/shaders/kernels.glsl", "for (int k = 0; k < 3; ++k)",
         "dirpole_sd: the three colours", "3", (3, "all"), None, f"no: counted as {C} per call"),
        ("dipole_gl/shaders/single.comp", "for (int k = 0; k < u_n_march; ++k)",
         "single scattering: march nodes x lights x atlas taps", f"{single.N_MARCH} (1 + L (1 + {single.ATLAS_TAPS}))",
         _largest(figs, lambda fig: single.iterations(L(fig))), None,
         f"no: fixed, {single.iterations(8):,} with 8 lights"),
        ("dipole_gl/shaders/single.comp", "for (int l = 0; l < u_n_lights; ++l)",
         "single scattering: lights", "L <= 8", _largest(figs, L), None, "no"),
        ("dipole_gl/shaders/single.comp", "for (int k = 0; k < 4; ++k)",
         "single scattering: bilinear atlas taps", "4 per light", _largest(figs, lambda fig: 4 * L(fig)), None, "no"),
        ("dipole_gl/shaders/irradiance.comp", "for (int l = 0; l < u_n_lights; ++l)",
         "irradiance: lights", "L <= 8", _largest(figs, L), None, "no"),
        ("dipole_gl/shaders/gbuffer.frag", "for (int i = 0; i < 8; ++i)",
         "G-buffer: visibility of 8 light slots", "8", (8, "all"), None, "no"),
        ("sslpv_gl/shaders/reflection.glsl", "for (int i = 0; i < u_n_lights; ++i)",
         "reflection: lights", "L <= 8", _largest(figs, L), None, "no"),
        ("sslpv_gl/shaders/shadow.glsl", "for (int dy = -1; dy <= 1; ++dy)",
         "shadow lookup: 3 x 3 filter rows", "3 per light", _largest(figs, lambda fig: 3 * L(fig)), None, "no"),
        ("sslpv_gl/shaders/shadow.glsl", "for (int dx = -1; dx <= 1; ++dx)",
         "shadow lookup: 3 x 3 filter taps", "9 per light", _largest(figs, lambda fig: 9 * L(fig)), None, "no"),
    ]


LOOP = re.compile(r"\b(for|while)\s*\(")


def shader_loops():
    """Every loop in the shaders: (file, offset of the keyword)."""
    found = []
    for folder in ("dipole_gl/shaders", "sslpv_gl/shaders"):
        for path in sorted((REPO / folder).iterdir()):
            text = path.read_text()
            found += [(f"{folder}/{path.name}", m.start(), text) for m in LOOP.finditer(text)]
    return found


def match(table):
    """Each loop of the shaders to its row (a loop without a row, or a row without its loop, stops the script)."""
    seen = []
    for path, at, text in shader_loops():
        rows = [i for i, row in enumerate(table) if row[0] == path and text.find(row[1]) == at]
        if len(rows) != 1:
            line = text[:at].count("\n") + 1
            sys.exit(f"{path}:{line}: a loop that the audit does not know ({text[at:at + 60]!r}); add it to loops()")
        seen += rows
    missing = [table[i][:2] for i in range(len(table)) if i not in seen]
    if missing:
        sys.exit(f"rows whose loop is gone: {missing}")


def fmt(pair):
    if pair is None:
        return "-"
    value, scene = pair
    return f"{value:,} ({scene})" if scene != "all" else f"{value:,}"


def table(figs):
    rows = loops(figs)
    match(rows)
    no_loop = sorted({p.name for f in ("dipole_gl/shaders", "sslpv_gl/shaders") for p in (REPO / f).iterdir()}
                     - {Path(r[0]).name for r in rows})
    out = [f"Budget: {budget.ITERATION_BUDGET:,} loop iterations per invocation (llvmpipe's limit "
           f"{budget.LLVMPIPE_LOOP_LIMIT:,}); L = lights, `dirpole_sd` counted as {C} iterations per call. "
           "Figures per invocation, the largest on the suite at the committed small size (nightly settings, "
           "`fit = coarsen`); a nested loop's figure includes the loops inside it, and the dense far field's "
           "includes the near field of the last dispatch.", "",
           "| loop | file | bounded by | unchunked (all in one dispatch) | chunked (largest dispatch) | chunked? |",
           "|---|---|---|---|---|---|"]
    for path, _, what, bound, whole, chunked, how in rows:
        out.append(f"| {what} | `{path}` | {bound} | {fmt(whole)} | {fmt(chunked)} | {how} |")
    out += ["", "Shaders without a loop: " + ", ".join(f"`{n}`" for n in no_loop) +
            " (SSLPV's RSM texels are injected one vertex invocation each, the propagation is one invocation "
            "per cell).", "", "Per scene (lights, dense samples at the rule's spacing, the vertex gather's "
            "longest row at the rule's density, the hierarchical gather's octree nodes):", "",
            "| scene | L | spacing (l') | samples | density | vertices | longest row | octree nodes |",
            "|---|---|---|---|---|---|---|---|"]
    for f in figs:
        out.append(f"| {f['scene']} | {f['L']} | {f['spacing']:g} | {f['samples']:,} | {f.get('density', '-')} | "
                   f"{f.get('vertices', '-'):,} | {f['row']:,} | {f['nodes']:,} |" if f["row"] is not None else
                   f"| {f['scene']} | {f['L']} | {f['spacing']:g} | {f['samples']:,} | - | - | - | {f['nodes']:,} |")
    return "\n".join(out)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", help="comma-separated scenes (default: the suite)")
    args = ap.parse_args(argv)
    names = args.scenes.split(",") if args.scenes else list_scenes()
    print(table([scene_figures(n) for n in names]))


if __name__ == "__main__":
    from page import run

    raise SystemExit(run(main, "shader_loops", "Every shader loop against llvmpipe's loop budget", markdown=True))
