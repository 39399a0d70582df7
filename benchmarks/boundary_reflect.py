"""The dielectric boundary in SSLPV's lattice: ``boundary_reflect = none`` (the paper) against ``rdr``.

For each dielectric scene (``skin_torus_dielectric``, ``jade_backlit_dielectric``: their committed 64 x 64
references; a dielectric copy of ``sphere_homogeneous``, eta 1.4, whose reference is rendered here with
mneevolpath and kept under ``cache/bench_rdr/``, NOT part of the suite) and its index-matched twin (the same
scene with ``kind = "index-matched"``: its reference rendered here, except ``sphere_homogeneous``'s own
committed one), renders SSLPV at N = ``--grid``, K = 32 and ``steady``, mappings ``collision`` and
``diffusion``, with ``boundary_reflect = none`` and ``rdr`` (:mod:`sslpv_gl.reflect`), and prints

* the subsurface energy ratio and relMSE against the scene's own reference over its comparison mask
  (:func:`harness.metrics.compute`), with the reference's noise floor;
* the dielectric / index-matched ratio of the subsurface image's sum over both references' masks, for
  the truth (the two references) and for SSLPV (dielectric render with each setting over the
  index-matched render, which ``rdr`` leaves unchanged as eta = 1 there), each option also with
  ``eta2`` (the radiance compression ``1 / eta^2`` leaving the medium, which the truth has).

    python benchmarks/boundary_reflect.py [--grid 32] [--refs-only] [--write]

Limits: the rendered references are at 64 x 64 with the suite's small targets; three objects, one light each.
"""

import argparse
import re
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CACHE = REPO / "cache" / "bench_rdr"
SCENES = ("skin_torus_dielectric", "jade_backlit_dielectric", "sphere_homogeneous")
MAPPINGS = ("collision", "diffusion")
SIZE = 64


def _variant(name, label, boundary):
    """Scene ``name`` with its ``[boundary]`` table replaced, as a folder under :data:`CACHE`."""
    from harness.scene import load_scene

    text = (REPO / "reference_scenes" / name / "scene.toml").read_text()
    text, n = re.subn(r"^\[boundary\]\n(?:(?:kind|eta|roughness) = .*\n)+", "[boundary]\n" + boundary + "\n", text,
                      flags=re.M)
    assert n == 1, f"{name}'s [boundary] table changed; update boundary_reflect.py"
    text = re.sub(r"^description = .*$", f'description = "{name}, {label} (benchmarks/boundary_reflect.py)"', text,
                  count=1, flags=re.M)
    d = CACHE / f"{name}_{label}"
    d.mkdir(parents=True, exist_ok=True)
    if not (d / "scene.toml").is_file() or (d / "scene.toml").read_text() != text:
        (d / "scene.toml").write_text(text)
    return load_scene(d).with_resolution(SIZE, SIZE)


def pairs():
    """``[(name, dielectric scene, committed or None, index-matched scene, committed or None)]``."""
    from harness.regression.accuracy import small_scene

    out = []
    for name in SCENES:
        if name == "sphere_homogeneous":
            out.append((name, _variant(name, "dielectric", 'kind = "dielectric"\neta = 1.4\nroughness = 0.0'), False,
                        small_scene(name), True))
        else:
            out.append((name, small_scene(name), True, _variant(name, "matched", 'kind = "index-matched"'), False))
    return out


def reference(scene, committed):
    """The scene's reference arrays and noise floors: committed, or rendered once into :data:`CACHE`."""
    from harness.reference.render import render_reference
    from harness.regression.accuracy import load_case_reference
    from harness.runs.references import load_reference
    from harness.runs.worker import reference_floors

    if committed:
        return load_case_reference(scene)
    out = CACHE / f"ref_{Path(scene.path).name}_{SIZE}"
    if not (out / "reference.json").is_file():
        t0 = time.perf_counter()
        target = 0.04 if scene.boundary.kind == "dielectric" else 0.03     # the suite's small targets
        render_reference(scene, out, target_rel_se=target)
        print(f"({Path(scene.path).name}: reference rendered in {time.perf_counter() - t0:.0f} s)", file=sys.stderr)
    ref = load_reference(out, (SIZE, SIZE))
    return ref, reference_floors(ref)


def _mean(img, mask):
    return float(img[mask].sum())


def _scores(compute, img, ref):
    e = compute("energy_ratio", img, ref["subsurface"], ref["mask"]).value
    r = compute("relmse", img, ref["subsurface"], ref["mask"]).value
    return f"{e:.3f} / {r:.3g}"


def main(argv=None):
    from harness.metrics import compute
    from sslpv_gl.params import SSLPVParams
    from sslpv_gl.reflect import reflectance
    from sslpv_gl.renderer import SSLPVRenderer

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid", type=int, default=32)
    ap.add_argument("--outside", default="vacuum", help="SSLPV's outside mode (sslpv_gl.boundary)")
    ap.add_argument("--refs-only", action="store_true", help="render the missing references and stop")
    args = ap.parse_args(argv)
    cases = []
    for name, diel, d_committed, matched, m_committed in pairs():
        cases.append((name, diel, reference(diel, d_committed), matched, reference(matched, m_committed)))
    if args.refs_only:
        return 0
    renderer = SSLPVRenderer()
    print(f"GL renderer: {renderer.gl_renderer}; N = {args.grid}, outside = {args.outside}, eta2 off, skip 0 for "
          "diffusion (2 otherwise).\n")
    print("Dielectric / index-matched ratio of the subsurface image's sum over both references' comparison masks "
          "(truth: the two references; SSLPV: its dielectric render with each setting over its index-matched "
          "render, where rdr is a no-op and eta2 has no effect). eta2 divides the dielectric render's radiance by "
          "eta^2 (the radiance compression leaving the medium, which the truth has). Then energy ratio / relMSE "
          "of each render against its own reference.\n")
    print("| scene (eta, R_dr) | noise floor d / m | mapping | K | truth d/m | SSLPV d/m none | rdr | none + eta2 "
          "| rdr + eta2 | E / relMSE: dielectric none | rdr | rdr + eta2 | index-matched |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name, diel, (ref_d, fl_d), matched, (ref_m, fl_m) in cases:
        mask = ref_d["mask"] & ref_m["mask"]
        truth = _mean(ref_d["subsurface"], mask) / _mean(ref_m["subsurface"], mask)
        eta = float(diel.boundary.eta)
        label = f"{name}{' (dielectric copy)' if name == 'sphere_homogeneous' else ''} ({eta:g}, " \
                f"{reflectance('rdr', eta):.3f})"
        floors = f"{fl_d['subsurface']['relmse']:.2g} / {fl_m['subsurface']['relmse']:.2g}"
        for mapping in MAPPINGS:
            for k in (32, "steady"):
                p = SSLPVParams(N=args.grid, steps=k, mapping=mapping, outside=args.outside,
                                **({"skip": 0} if mapping == "diffusion" else {}))
                settings = (p, p.replace(boundary_reflect="rdr"), p.replace(eta2=True),
                            p.replace(boundary_reflect="rdr", eta2=True))
                sums, cells = [], []
                base = renderer.render(matched, p).subsurface
                for params in settings:
                    img = renderer.render(diel, params).subsurface
                    sums.append(_mean(img, mask) / _mean(base, mask))
                    if params.eta2 is False or params.boundary_reflect == "rdr":
                        cells.append(_scores(compute, img, ref_d))
                cells.append(_scores(compute, base, ref_m))
                print(f"| {label} | {floors} | {mapping} | {k} | {truth:.3f} | "
                      + " | ".join(f"{v:.3f}" for v in sums) + " | " + " | ".join(cells) + " |", flush=True)
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    from page import named_by, run

    raise SystemExit(run(main, named_by("boundary_reflect", "--outside"), "The dielectric boundary in SSLPV's lattice: R_dr against the truth",
                         markdown=True))
