"""Forward-peaked media: SSLPV with and without delta-Eddington scaling against the truth.

For ``mixed_phase`` (g = 0.8 and -0.3 halves; its committed 64 x 64 reference) and a forward sphere
(``mixed_phase``'s sphere, light and medium with g = 0.9 everywhere; its reference rendered here
at ``--size`` and kept under ``cache/bench_forward/``), renders SSLPV at N = ``--grid`` for each
mapping, K = 32 and ``steady``, with ``phase_scaling = none`` (the paper) and ``delta-eddington``
(:func:`sslpv_gl.material.delta_eddington`), and prints the subsurface energy ratio and relMSE
against the reference over its comparison mask, with the reference's noise floor. The
``diffusion`` mapping depends only on the quantities the scaling keeps: its two rows must agree.

    python benchmarks/forward_scattering.py [--grid 32] [--size 32] [--outside vacuum] [--write]

Limits: two media, one light each; the forward sphere's reference is rendered at a small size
(its noise floor is printed beside it).
"""

import argparse
import re
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CACHE = REPO / "cache" / "bench_forward"
MAPPINGS = ("literal", "collision", "diffusion")


def forward_scene(size):
    """``mixed_phase`` with g = 0.9 everywhere, as a scene folder under :data:`CACHE`."""
    from harness.scene import load_scene

    text = (REPO / "reference_scenes" / "mixed_phase" / "scene.toml").read_text()
    text, n = re.subn(r"^g = \{kind = \"split\".*$", 'g = {kind = "constant", value = [0.9, 0.9, 0.9]}', text,
                      flags=re.M)
    assert n == 1, "mixed_phase's g line changed; update forward_scene"
    text = re.sub(r"^description = .*$", 'description = "mixed_phase with g = 0.9 everywhere (forward_scattering.py)"',
                  text, flags=re.M)
    d = CACHE / "forward_sphere"
    d.mkdir(parents=True, exist_ok=True)
    if not (d / "scene.toml").is_file() or (d / "scene.toml").read_text() != text:
        (d / "scene.toml").write_text(text)
    return load_scene(d).with_resolution(size, size)


def reference(scene, size):
    from harness.metrics.coverage import comparison_mask  # noqa: F401  (load_reference applies it)
    from harness.reference.render import render_reference
    from harness.runs.references import load_reference
    from harness.runs.worker import reference_floors

    out = CACHE / f"ref_{size}"
    if not (out / "reference.json").is_file():
        t0 = time.perf_counter()
        render_reference(scene, out, target_rel_se=0.03)
        print(f"(forward sphere reference rendered in {time.perf_counter() - t0:.0f} s)", file=sys.stderr)
    ref = load_reference(out, (size, size))
    return ref, reference_floors(ref)


def main(argv=None):
    from harness.metrics import compute
    from harness.regression.accuracy import load_case_reference, small_scene
    from sslpv_gl.params import SSLPVParams
    from sslpv_gl.renderer import SSLPVRenderer

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid", type=int, default=32)
    ap.add_argument("--size", type=int, default=32, help="the forward sphere's reference size")
    ap.add_argument("--outside", default="vacuum", help="SSLPV's outside mode (sslpv_gl.boundary)")
    args = ap.parse_args(argv)
    cases = [("mixed_phase", small_scene("mixed_phase"), *load_case_reference(small_scene("mixed_phase")))]
    fwd = forward_scene(args.size)
    cases.append(("forward sphere (g = 0.9)", fwd, *reference(fwd, args.size)))
    renderer = SSLPVRenderer()
    print(f"GL renderer: {renderer.gl_renderer}; N = {args.grid}, outside = {args.outside}; subsurface energy ratio / relMSE against the "
          "reference (its noise floor in relMSE beside the scene)\n")
    print("| scene | noise floor | mapping | K | none | delta-eddington |")
    print("|---|---|---|---|---|---|")
    for label, scene, ref, floors in cases:
        for mapping in MAPPINGS:
            for k in (32, "steady"):
                cells = []
                for scaling in ("none", "delta-eddington"):
                    p = SSLPVParams(N=args.grid, steps=k, mapping=mapping, phase_scaling=scaling, outside=args.outside,
                                    **({"skip": 0} if mapping == "diffusion" else {}))
                    res = renderer.render(scene, p)
                    e = compute("energy_ratio", res.subsurface, ref["subsurface"], ref["mask"]).value
                    r = compute("relmse", res.subsurface, ref["subsurface"], ref["mask"]).value
                    cells.append(f"{e:.3f} / {r:.4g}")
                print(f"| {label} | {floors['subsurface']['relmse']:.2g} | {mapping} | {k} | {cells[0]} | {cells[1]} |",
                      flush=True)
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    from page import named_by, run

    raise SystemExit(run(main, named_by("forward_scattering", "--outside"), "Forward-peaked media: delta-Eddington scaling against the truth",
                         markdown=True))
