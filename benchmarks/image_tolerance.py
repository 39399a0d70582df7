"""What must the floating-point tolerance of "unchanged" cover? (``harness.regression.verdict``)

No second OpenGL implementation is available here, so the differences one can bring
are emulated on llvmpipe for every case of ``baselines/accuracy_matrix.toml`` (64x64):

* ``repeat``: the same render twice (is llvmpipe deterministic?);
* ``vertex ULP``: every mesh vertex coordinate moved by one float32 ULP, up or down at
  random: another driver's rounding of the vertex transform, the rasteriser's edge
  functions and the interpolated positions that pick a cell (``texelFetch``) and light
  the RSM texels;
* ``camera 1e-6``: the camera origin scaled by 1 + 1e-6 (about 8 ULP), a larger such
  perturbation;
* ``fp16``: 16-bit grids (the paper's storage), the smallest *deliberate* change, which
  must be far beyond the tolerance.

For each it prints the largest per-pixel ``|a - b| / max(|b|, 1e-3 max|b|)``, the pixels
covered in one image only, and how many pixels ``verdict.image_change`` calls changed
(with the committed tolerance); the last lines are the summary the tolerance is chosen from.
A driver-like pair (vertex ULP, camera) that is called changed is then judged by step 2
against the committed reference (relMSE, si-relMSE, energy ratio; Bonferroni over the
accuracy matrix): it must come out *changed-within-noise*, never a regression or an
improvement.

    .venv/bin/python benchmarks/image_tolerance.py [--scenes A,B]
"""

import argparse

import dataclasses

import numpy as np

from harness.regression.accuracy import case_reference, cases, family_size, small_scene
from harness.regression.verdict import IMAGE_ATOL, IMAGE_RTOL, image_change, judge_images, overall
from sslpv_gl.renderer import SSLPVRenderer
from sslpv_gl.calibrated import parse_mapping


def vertex_ulp(scene, rng):
    v = scene.mesh.vertices.astype(np.float32)
    up = rng.uniform(size=v.shape) < 0.5
    moved = np.where(up, np.nextafter(v, np.float32(np.inf)), np.nextafter(v, np.float32(-np.inf)))
    mesh = dataclasses.replace(scene.mesh, vertices=moved.astype(np.float64))
    return dataclasses.replace(scene, mesh=mesh, content_hash=scene.content_hash + "-ulp")


def camera_shift(scene, rel=1e-6):
    o = tuple(float(x) * (1 + rel) for x in scene.camera.origin)
    return dataclasses.replace(scene, camera=dataclasses.replace(scene.camera, origin=o),
                               content_hash=scene.content_hash + "-cam")


def difference(a, b):
    both = a.mask & b.mask
    x, y = a.subsurface[both].astype(np.float64), b.subsurface[both].astype(np.float64)
    peak = np.abs(y).max()
    rel = np.abs(x - y) / np.maximum(np.abs(y), 1e-3 * peak)
    ic = image_change(a.subsurface, b.subsurface, a.mask, b.mask)
    return float(rel.max()), int((a.mask != b.mask).sum()), ic.beyond, ic.changed


def main():
    ap = argparse.ArgumentParser(description="what the floating-point tolerance of 'unchanged' must cover")
    ap.add_argument("--scenes", help="comma-separated subset of the accuracy matrix's scenes (default: all)")
    args = ap.parse_args()
    renderer = SSLPVRenderer()
    rng = np.random.default_rng(0)
    kinds = ("repeat", "vertex ULP", "camera 1e-6", "fp16")
    worst = {k: 0.0 for k in kinds}
    least = {k: np.inf for k in kinds}
    flips = {k: 0 for k in kinds}
    changed = {k: 0 for k in kinds}
    counted = {k: 0 for k in kinds}
    step2 = {}
    all_cases = [c for c in cases() if not args.scenes or c[0] in args.scenes.split(",")]
    print(f"{'scene':<20} {'config':<22} " + " ".join(f"{k + ' max rel (flips, changed px)':>38}" for k in kinds))
    for name, params, tol in all_cases:
        s = small_scene(name)
        base = renderer.render(s, params)
        others = {"repeat": renderer.render(s, params), "vertex ULP": renderer.render(vertex_ulp(s, rng), params),
                  "camera 1e-6": renderer.render(camera_shift(s), params)}
        if parse_mapping(params.mapping) is None:        # a calibrated mapping was fitted at fp32 and refuses fp16
            others["fp16"] = renderer.render(s, params.replace(precision="fp16"))
        cells = []
        for k in kinds:
            if k not in others:
                cells.append(f"{'-':>24} (calibrated: fp32 only)")
                continue
            counted[k] += 1
            rel, fl, beyond, ch = difference(others[k], base)
            worst[k], least[k] = max(worst[k], rel), min(least[k], rel)
            flips[k] += fl
            changed[k] += ch
            cells.append(f"{rel:>24.2e} ({fl}, {beyond:>4})")
            if ch and k in ("vertex ULP", "camera 1e-6"):
                ref = case_reference(s)
                v = overall(judge_images(name, str(params.N), "subsurface", others[k].subsurface, base.subsurface,
                                         ref["subsurface"], ref["se"], ref["mask"], tol, family_size(), k=ref["K"],
                                         metrics=("relmse", "si_relmse", "energy_ratio")), True)
                step2[v] = step2.get(v, 0) + 1
        print(f"{name:<20} {params.N}/{params.steps}/{params.mapping:<16} " + " ".join(f"{c:>38}" for c in cells),
              flush=True)

    print(f"tolerance: |new - old| <= {IMAGE_RTOL:g} |old| + {IMAGE_ATOL:g} max|old|")
    for k in kinds:
        print(f"{k}: largest per-pixel relative difference {worst[k]:.2e} (smallest case {least[k]:.2e}); "
              f"{flips[k]} coverage flips; called changed in {changed[k]} of {counted[k]} cases")
    print(f"driver-like pairs called changed, judged by step 2: {step2 or 'none'}")


if __name__ == "__main__":
    from page import run

    raise SystemExit(run(main, "image_tolerance", 'What the floating-point tolerance of "unchanged" must cover'))
