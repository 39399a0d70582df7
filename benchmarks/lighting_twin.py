"""What no calibration that depends on the material can do for a back-lit object: the lighting twin.

A calibrated mapping (scalar or a form of the material, ``sslpv_gl.material_form``) gives the same
``sigma_scale`` and ``radiance_scale`` to a scene and to its *lighting twin*, the same scene with its
lights mirrored to the other side of the object (``harness.study.twin``): the cells' numbers do not
depend on the lights. The ratio of the two scenes' energy ratios is then fixed by SSLPV within the
interval of Eq. (W3) there, whatever the radiance scale. This benchmark measures that interval per
renderer setting and budget, over a scan of ``sigma_scale``:

* **the truth** of both scenes, per channel over the committed reference's mask: from the path-length
  tracer (``harness.reference.path_length``, which reproduces the committed Mitsuba references' energy)
  where it models the scene, beside the scene's own reference; otherwise (``--truth mitsuba``, any
  homogeneous scene: a non-convex or scanned mesh, a dielectric boundary) the scene's reference and a
  Mitsuba reference of the twin rendered at the same size and noise target (``render_reference``).
  ``--mitsuba-check`` renders the twin's reference beside the tracer's truth too, as a second route;
* **SSLPV** at grid ``N`` for every mapping and ``outside`` treatment the renderer has (``transport``
  with the two it allows), the paper's skip of 2, the collision mapping with ``skip = 0`` and with
  delta-Eddington scaling, and the collision mapping with the extensions of the committed calibrations
  ``collision_interior_shade`` and ``collision_interior_shade_trilinear`` (``interior``, an injection 1 mfp'
  deep, the grid read 1 cell deep, by cell and trilinear) and ``collision_interior_depth05_shade_trilinear`` (the
  same, trilinear, injected 0.5 mfp' deep), at ``sigma_scale`` from 1e-4 to 1e3 (a third of a decade apart);
* per budget and setting: the attainable interval of ``rho_A / rho_B`` (W3), whether it meets the
  band ``[0.64, 1.5625]`` that both scenes in ``[0.8, 1.25]`` need, and the least energy ratio the
  front-lit twin must have when the back-lit scene is in range (W4);
* the best committed calibration (``baselines/calibrated/best``), the collision family's loss form, and the
  loss forms of those extensions (and the half-depth setting's radiance form) rendered on both scenes.

Usage: ``python benchmarks/lighting_twin.py [--scene backlit_sphere] [--grid 32] [--photons 65536]
[--truth auto|tracer|mitsuba] [--mitsuba-check] [--write]`` (about 20 minutes on 2 cores, and the twin's
reference with Mitsuba). ``--write`` writes ``docs/benchmarks/lighting_twin.md``, or
``lighting_twin_<scene>.md`` for a scene other than ``backlit_sphere``.

Limits: those of ``harness.study.twin`` (a grid of ``sigma_scale``; homogeneous media); the tracer's
truth needs an index-matched sphere; a Mitsuba truth's standard error takes the pixels' errors as
independent.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from page import Page  # noqa: E402

from harness.errors import InputError  # noqa: E402

BUDGETS = (8, 16, 32, 64, "steady")
SIGMA_SCALES = tuple(float(x) for x in np.logspace(-4.0, 3.0, 22))
BEST = Path(__file__).resolve().parents[1] / "baselines" / "calibrated" / "best" / "calibrated.toml"
#: committed calibrations rendered beside the best (less the one the best is): the paper's setting's loss form and
#: those of the extensions that :func:`settings` scans last
EXTENDED = tuple(BEST.parents[1] / name / "calibrated.toml" for name in (
    "collision_loss_form", "collision_interior_shade_loss_form", "collision_interior_shade_trilinear_loss_form",
    "collision_interior_depth05_shade_trilinear_loss_form", "collision_interior_depth05_shade_trilinear_radiance_form"))


def settings():
    """``(label, SSLPVParams keyword dict)`` of every setting scanned."""
    from sslpv_gl.boundary import OUTSIDE_MODES
    from sslpv_gl.material import TRANSPORT_OUTSIDE

    out = []
    for mapping in ("literal", "collision", "diffusion", "transport"):
        for outside in (TRANSPORT_OUTSIDE if mapping == "transport" else OUTSIDE_MODES):
            out.append((f"{mapping}, {outside}", {"mapping": mapping, "outside": outside}))
    out.append(("collision, vacuum, skip 0", {"mapping": "collision", "outside": "vacuum", "skip": 0}))
    out.append(("collision, vacuum, delta-Eddington", {"mapping": "collision", "outside": "vacuum",
                                                        "phase_scaling": "delta-eddington"}))
    # the committed calibrations with an injection and a read at depth
    for depth, lookup in ((1, "cell"), (1, "trilinear"), (0.5, "trilinear")):
        out.append((f"collision, interior, depth {depth:g} mfp', read 1 cell deep, {lookup} lookup",
                    {"mapping": "collision", "outside": "interior", "inject_depth": float(depth),
                     "shade_depth": 1.0, "lookup": lookup}))
    return out


def truth(sphere, mask, photons):
    """Per channel: the tracer's masked energy and its standard error."""
    from harness.reference import path_length as pl

    runs = [pl.trace(sphere, c, [0.0], photons=photons, batches=16, seed=0, mask=mask) for c in range(3)]
    return np.array([r.energy for r in runs]), np.array([r.energy_se for r in runs])


def mitsuba_energy(folder, mask):
    """Per channel: a reference folder's masked subsurface energy and its standard error (pixels independent)."""
    from harness.io.images import read_exr

    img = read_exr(Path(folder) / "subsurface.exr")
    m = np.asarray(mask, bool)
    return img["rgb"][m].astype(np.float64).sum(axis=0), np.sqrt((img["se"][m].astype(np.float64) ** 2).sum(axis=0))


def mitsuba_twin(front, folder_a, mask, out):
    """Render the twin's reference into ``out`` at the noise target of the scene's own; its energy and SE."""
    import json

    from harness.io.images import read_exr
    from harness.reference.render import render_reference

    target = float(json.loads((Path(folder_a) / "reference.json").read_text())["target_rel_se"])
    meta = render_reference(front, out, target_rel_se=target)
    if meta.get("exact") is False:
        raise SystemExit(f"error: {out}: exact: the twin's reference is not exact ({meta.get('exact_note', '')}); "
                         "use a scene whose reference can be exact")
    mask_b = read_exr(Path(out) / "mask.exr")["rgb"][..., 0] >= 0.999
    if not np.array_equal(mask_b, mask):
        raise SystemExit(f"error: {out}: mask: the twin's mask differs from the scene's; the lights must not "
                         "change which pixels see the object")
    return mitsuba_energy(out, mask), float(meta.get("render_seconds", float("nan")))


def label(b):
    return "steady" if b == "steady" else f"K = {b}"


def main(argv=None):
    from harness.calibration.run import _reference
    from harness.io.images import read_exr
    from harness.reference import path_length as pl
    from harness.study import twin
    from sslpv_gl.params import SSLPVParams
    from sslpv_gl.renderer import SSLPVRenderer

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="backlit_sphere", help="a homogeneous, index-matched sphere scene")
    ap.add_argument("--grid", type=int, default=32, help="the LPV grid N")
    ap.add_argument("--photons", type=int, default=1 << 16, help="photons per light and channel for the truth")
    ap.add_argument("--truth", choices=("auto", "tracer", "mitsuba"), default="auto",
                    help="the truth of both scenes: the path-length tracer (index-matched spheres), Mitsuba "
                         "(the scene's reference and one rendered for the twin), or auto (the tracer where it can)")
    ap.add_argument("--mitsuba-check", action="store_true",
                    help="with the tracer's truth, render the twin's Mitsuba reference too, as a second route")
    ap.add_argument("--write", action="store_true", help="write docs/benchmarks/lighting_twin.md")
    args = ap.parse_args(argv)
    try:
        scene, folder = _reference(args.scene, None)
        twin.check_homogeneous(scene)
        front = twin.lighting_twin(scene)
        spheres = None
        if args.truth != "mitsuba":
            try:
                spheres = pl.sphere_scene(scene), pl.sphere_scene(front)
            except InputError:
                if args.truth == "tracer":
                    raise
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    mask = read_exr(folder / "mask.exr")["rgb"][..., 0] >= 0.999
    ref, ref_se = mitsuba_energy(folder, mask)
    check = None
    with tempfile.TemporaryDirectory(prefix="lighting_twin_") as tmp:
        if spheres is None:
            (t_b, se_b), seconds = mitsuba_twin(front, folder, mask, Path(tmp) / "twin")
            t_a, se_a = ref, ref_se
        else:
            (t_a, se_a), (t_b, se_b) = (truth(s, mask, args.photons) for s in spheres)
            if args.mitsuba_check:
                check = mitsuba_twin(front, folder, mask, Path(tmp) / "twin")
    rel_se = np.sqrt((se_a / t_a) ** 2 + (se_b / t_b) ** 2)

    renderer = SSLPVRenderer()
    page = Page(_page_name(args), f"What no calibration that depends on the material can do for a back-lit object: "
                f"{args.scene} and its lighting twin")
    page.gl_renderer = renderer.gl_renderer
    lights = "; ".join(f"({', '.join(f'{x:.3g}' for x in lt.position)})" for lt in scene.lights)
    lights_b = "; ".join(f"({', '.join(f'{x:.3g}' for x in lt.position)})" for lt in front.lights)
    page.para(f"Scene A: `{args.scene}` (lights at {lights}). Scene B, its lighting twin: the same mesh, medium, "
              f"camera and grid with the lights mirrored through the plane through the object's centre (the mean of "
              f"its vertices) normal to the view axis ({lights_b}). A calibration, scalar or a form of the material, gives both the same "
              f"`sigma_scale` and `radiance_scale`, so the ratio of their energy ratios, rho_A / rho_B, is a weighted "
              f"mean of the per-channel twin factors q_c(s) (Eqs. W1-W3 of `harness.study.twin`). Grid N = {args.grid}; "
              f"`sigma_scale` s at {len(SIGMA_SCALES)} points from {SIGMA_SCALES[0]:g} to {SIGMA_SCALES[-1]:g}.")
    page.heading("The truth of both scenes")
    if spheres is None:
        page.table(["channel", "A: Mitsuba reference", "B: Mitsuba reference", "T_A / T_B"],
                   [[c, f"{t_a[i]:.4g} ± {se_a[i]:.2g}", f"{t_b[i]:.4g} ± {se_b[i]:.2g}",
                     f"{t_a[i] / t_b[i]:.4f} ± {t_a[i] / t_b[i] * rel_se[i]:.4f}"] for i, c in enumerate("RGB")],
                   note=f"Masked subsurface energy per channel; B's reference rendered here in {seconds:.0f} s. The twin "
                        f"factors below carry the truth's relative standard error, {rel_se.max():.2%} at most.")
    else:
        head = ["channel", "A: tracer", "A: Mitsuba reference", "A tracer / Mitsuba", "B: tracer"]
        rows = [[c, f"{t_a[i]:.4g} ± {se_a[i]:.2g}", f"{ref[i]:.4g} ± {ref_se[i]:.2g}", f"{t_a[i] / ref[i]:.4f}",
                 f"{t_b[i]:.4g} ± {se_b[i]:.2g}"] for i, c in enumerate("RGB")]
        if check is not None:
            (m_b, m_se), _ = check
            head += ["B: Mitsuba reference", "B tracer / Mitsuba"]
            for i, row in enumerate(rows):
                row += [f"{m_b[i]:.4g} ± {m_se[i]:.2g}", f"{t_b[i] / m_b[i]:.4f} ± "
                        f"{t_b[i] / m_b[i] * np.hypot(se_b[i] / t_b[i], m_se[i] / m_b[i]):.4f}"]
        head.append("T_A / T_B")
        for i, row in enumerate(rows):
            row.append(f"{t_a[i] / t_b[i]:.4f} ± {t_a[i] / t_b[i] * rel_se[i]:.4f}")
        page.table(head, rows,
                   note=f"Masked subsurface energy per channel; the tracer with {args.photons} photons per light and "
                        "channel. The twin factors below carry the truth's relative standard error (the tracer's), "
                        f"{rel_se.max():.2%} at most."
                        + (f" B's Mitsuba reference was rendered here in {check[1]:.0f} s." if check else ""))

    results = {b: [] for b in BUDGETS}
    curves = {}
    for name, kw in settings():
        params = SSLPVParams(N=args.grid, **kw)
        energies = twin.scan(renderer, scene, front, params, SIGMA_SCALES, BUDGETS, mask)
        for b in BUDGETS:
            e_a, e_b = energies[b]
            q = twin.twin_factors(e_a, t_a, e_b, t_b)
            low, high, i_lo, i_hi = twin.attainable(q)
            results[b].append((name, q, low, high, i_lo, i_hi, int((~np.isfinite(q).all(axis=1)).sum())))
            curves[name, b] = q
        print(f"{name}: done", file=sys.stderr)

    page.heading("The attainable ratio per setting and budget")
    page.para("\"low\", \"high\": the least and largest twin factor over every s scanned and channel (W3), with the s "
              "where each is reached. Both scenes in [0.8, 1.25] need rho_A / rho_B in [0.64, 1.5625]; \"B at least\": "
              "the twin's least energy ratio when A is in range (W4). \"high / next\": where \"high\" lies at an "
              "end of the scan, its ratio to the same channel's factor at the next s inwards (1.000: the factor has "
              "settled there, so a wider scan would not raise it). \"unusable\": points of the scan with a dark or "
              "failed render.")
    summary = []
    for b in BUDGETS:
        rows, best = [], None
        for name, q, low, high, i_lo, i_hi, bad in results[b]:
            if low is None:
                rows.append([name, "-", "-", "no usable point", "-", str(bad)])
                continue
            v = twin.verdict(low, high)
            edge = "–"
            if i_hi in (0, len(SIGMA_SCALES) - 1):
                c = int(np.argmax(q[i_hi]))
                nxt = q[1 if i_hi == 0 else i_hi - 1, c]
                edge = f"{high / nxt:.3f}" if np.isfinite(nxt) and nxt > 0 else "no neighbour"
            rows.append([name, f"{low:.3g} (s = {SIGMA_SCALES[i_lo]:.3g})", f"{high:.3g} (s = {SIGMA_SCALES[i_hi]:.3g})",
                         edge, "yes" if v["possible"] else "no", f"{v['twin_at_least']:.3g}", str(bad)])
            if best is None or high > best[1]:
                best = (name, high, v)
        page.heading(f"At {label(b)}")
        page.table(["setting", "low", "high", "high / next", "both in range possible", "B at least", "unusable"], rows)
        n_possible = sum(1 for r in rows if r[4] == "yes")
        summary.append([label(b), f"{n_possible} of {len(rows)}", best[0], f"{best[1]:.3g}",
                        f"{best[2]['twin_at_least']:.3g}"])
    page.heading("Summary")
    page.table(["budget", "settings where both can be in range", "setting with the largest ratio",
                "largest rho_A / rho_B", "B at least, with that setting"], summary,
               note="Where no setting can put both in range, a calibration that puts A in [0.8, 1.25] renders the "
                    "same object lit from the front at least \"B at least\" times its truth.")
    top = max(results[32], key=lambda r: -np.inf if r[3] is None else r[3])[0]
    for name in dict.fromkeys(("collision, vacuum", top)):
        page.heading(f"The twin factor of {name} against s")
        page.table(["s"] + [label(b) + " (R / G / B)" for b in BUDGETS],
                   [[f"{s:.3g}"] + [" / ".join(f"{x:.3g}" for x in curves[name, b][i]) for b in BUDGETS]
                    for i, s in enumerate(SIGMA_SCALES)],
                   note="collision, vacuum: the paper's setting." if name == "collision, vacuum" else
                   "The setting with the largest ratio at K = 32.")

    import json

    winner = BEST.parents[3] / json.loads((BEST.parent / "selection.json").read_text())["winner"]
    rows = []
    for path in (BEST, *(p for p in EXTENDED if p.parent.resolve() != winner.resolve())):   # the best's own fit once
        for b in BUDGETS:
            p = SSLPVParams.given(N=args.grid, steps=b, mapping=f"calibrated:{path}")
            e = [twin.channel_energies(renderer.render(sc, p).subsurface, mask) for sc in (scene, front)]
            rho_a = float(np.mean(e[0] / t_a))
            rho_b = float(np.mean(e[1] / t_b))
            rows.append([f"`{path.parent.relative_to(BEST.parents[3])}`", label(b), f"{rho_a:.3g}", f"{rho_b:.3g}",
                         f"{rho_a / rho_b:.3g}"])
    page.heading("Committed calibrations on both scenes")
    page.table(["calibration", "budget", "A: energy ratio", "B: energy ratio", "rho_A / rho_B"], rows,
               note=f"`--mapping calibrated:PATH/calibrated.toml` at N = {args.grid}, with the file's renderer settings: "
                    "the best (`baselines/calibrated/best`), then the collision family's loss form and those with the "
                    "extensions scanned above. "
                    "Energy ratio against the truth above (the mean of the per-channel ratios).")
    page.finish(args.write)
    if args.write:                                 # after the page: its header checks the tree is clean
        write_verdicts(args, scene, results)        # harness.study.twin.VERDICTS, which the study reads


def write_verdicts(args, scene, results):
    """``baselines/lighting_twin/<scene>.json``: per budget and setting, the attainable interval (W3) and the
    verdict (W4), with the scene's content hash, the grid, the command and the commit that wrote them."""
    import json
    from datetime import datetime, timezone

    from page import command_line, commit_state

    from harness.io.atomic import atomic_write
    from harness.scene import load_scene
    from harness.study import twin
    from harness.study.target import ENERGY_RANGE

    commit, dirty = commit_state()
    budgets = {}
    for b in BUDGETS:
        rows = {}
        for name, _q, low, high, _i_lo, _i_hi, bad in results[b]:
            if low is None:
                rows[name] = {"usable": False}
                continue
            v = twin.verdict(low, high, ENERGY_RANGE)
            rows[name] = {"usable": True, "low": low, "high": high, "possible": v["possible"],
                          "twin_at_least": v["twin_at_least"], "unusable_points": bad}
        budgets[str(b)] = rows
    # the scene as its file declares it (the study's limits load it so), not at the reference's size
    data = {"format": "sslpv-lighting-twin", "scene": scene.name, "content_hash": load_scene(args.scene).content_hash,
            "grid": args.grid, "energy_range": list(ENERGY_RANGE), "band": list(twin.verdict(1.0, 1.0, ENERGY_RANGE)["band"]),
            "sigma_scales": list(SIGMA_SCALES), "budgets": budgets, "page": f"docs/benchmarks/{_page_name(args)}.md",
            "command": command_line(), "commit": commit + (" (with uncommitted changes)" if dirty else ""),
            "created": datetime.now(timezone.utc).isoformat(timespec="seconds")}
    with atomic_write(twin.VERDICTS / f"{scene.name}.json") as tmp:      # the file the study reads
        Path(tmp).write_text(json.dumps(data, indent=1) + "\n")


def _page_name(args):
    return "lighting_twin" if args.scene == "backlit_sphere" else "lighting_twin_" + Path(args.scene).name


if __name__ == "__main__":
    main()
