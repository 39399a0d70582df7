"""The floor of a calibrated family: each scene at its own best scales, per colour channel (Eqs. L1, L2).

A calibration of a family (a mapping with its renderer settings) gives each cell and colour channel a
``sigma_scale`` ``s`` and a ``radiance_scale`` ``r``. SSLPV propagates each colour channel alone and relMSE
(Eq. C1 of :mod:`harness.calibration.fit`) is the mean of the channels' (every channel has the same pixels;
``tests/test_calibrated_form_channels.py`` checks the first on the renderer), so on scene ``i``::

    relMSE_i = (1/3) sum_c  A_ic(u_c) r_c^2 - 2 B_ic(u_c) r_c + C_ic,    u_c = ln s_c

and no choice of ``(s_c, r_c)`` does better than::

    F_i = (1/3) sum_c  min_u ( C_ic - B_ic(u)^2 / A_ic(u) )                                     (L1)

(the inner minimum over ``r`` is at ``r = B / A``, clamped to the file format's range
:data:`~harness.calibration.fit.V_BOUNDS`). With one pair for all three channels the floor is::

    S_i = min_u min_r (1/3) sum_c relMSE_ic(u, r)                                               (L2)

the calibration's own oracle (``oracle`` of its ``calibration.json``, there by Brent on the spline and a
render at the optimum); :func:`scene_floor` recomputes it on a fine grid as a second route.

``sslpv-harness calibrate`` writes the floor beside every calibration it fits (:func:`floor_info`, from its own
scan); ``sslpv-harness calibrate-floor`` writes it for an existing calibration (:func:`run_floor`). Both take the
scan's samples alone (:func:`scan_samples`), so they write the same file.

**What it bounds.** A scalar calibration gives a scene one ``(s, r)``: its relMSE there is at least ``S_i``.
A form (F1 of :mod:`sslpv_gl.material_form`) gives each cell and channel the scales of that cell's terms; on a
scene whose terms take one value per channel over every cell of the grid (``uniform``: a homogeneous medium
filling its box) that is one ``(s_c, r_c)`` per channel, so its relMSE is at least ``F_i`` for scales within the
scan, and for any scales where no channel's least lies at an end of the scan that the loss had not levelled off
at (:func:`bounds`). The median over the
scenes of any calibration is then at least the median of the floors (the median is monotone in each value),
held out or in sample. Where the terms vary over the cells (a medium that varies, or one the resampling leaves
uneven) a form can do better than ``F_i``, and the floor is only the scalar calibrations' bound (within the scan).
The least median any calibration of the family reaches (:func:`median_bound`) takes every scene whose floor does
not bound it as 0.

Limits:

* the minimum is taken over the calibration's scan of ``s`` (its images, interpolated by the calibration's own
  cubic spline of the image, on :data:`U_POINTS` values of ``ln s``); a channel whose minimum lies at an end of
  the scan is marked ``at_bound``: beyond the scan it may lie lower;
* between samples the image is the spline's, not a render (at the scan's samples it is the render itself);
  ``tests/test_calibration_floor.py`` checks every committed floor against its calibration's oracle, which was
  rendered: never above it, and equal where both found the same optimum (the oracle's fit searches the bracket of
  its best sample, the floor the whole scan, so the floor may lie in another basin of the loss);
* the floor is the family's: another mapping or extension has its own (calibrate it and take its floor).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from harness.calibration.fit import V_BOUNDS
from harness.calibration.form_loss import scan_grid, scene_table_channels
from harness.calibration.scan import budget_label
from harness.errors import InputError

__all__ = ["U_POINTS", "FILE", "channel_floor", "scene_floor", "terms_uniform", "run_floor", "read_floor", "floor_for",
           "bounds", "median_bound", "scan_samples", "floor_info"]

#: Values of ``ln s`` on which the floor is searched (four times the loss form's table).
U_POINTS = 769
#: The floor's file, beside the calibration's ``calibration.json``.
FILE = "floor.json"


def _best_r(A, B):
    """``r = B / A`` clamped to the file format's range (``r`` where ``A`` or ``B`` is not positive: the bound's
    end that the quadratic prefers)."""
    lo, hi = math.exp(V_BOUNDS[0]), math.exp(V_BOUNDS[1])
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(A > 0, B / np.where(A > 0, A, 1.0), hi)
    return np.clip(np.where(B > 0, r, lo), lo, hi)


def channel_floor(table, u_grid, step=None):
    """Eq. (L1) of one channel: ``table`` (P, 3) of (A, B, C) on ``u_grid`` -> ``{"relmse", "s", "r", "at_bound",
    "settled"}``, the least relMSE over the grid with ``r`` at its best for each ``u``. ``at_bound``: the least lies
    at an end of the grid; ``settled``: there, the value ``step`` grid points inwards (default: a twelfth of the
    grid) is within 0.1 % of it, so the loss has levelled off and a wider scan would not lower it much."""
    T = np.asarray(table, dtype=np.float64)
    A, B, C = T[:, 0], T[:, 1], T[:, 2]
    r = _best_r(A, B)
    q = np.maximum(A * r * r - 2.0 * B * r + C, 0.0)
    j = int(np.argmin(q))
    at_bound = j == 0 or j == len(u_grid) - 1
    step = step or max(len(u_grid) // 12, 1)
    inner = q[min(step, len(q) - 1)] if j == 0 else q[max(len(q) - 1 - step, 0)]
    return {"relmse": float(q[j]), "s": float(math.exp(u_grid[j])), "r": float(r[j]), "at_bound": bool(at_bound),
            "settled": bool(not at_bound or inner <= 1.001 * q[j])}


def scene_floor(samples, u_grid, ref="full"):
    """Eqs. (L1) and (L2) of one scene's :class:`~harness.calibration.fit.SceneSamples` -> ``{"relmse": F_i,
    "energy_ratio", "channels": [channel_floor...], "scalar": {"relmse": S_i, "s", "r", "energy_ratio",
    "at_bound"}}``. Energy ratios are the masked subsurface sum at the floor's scales over the reference's."""
    tabs = scene_table_channels(samples, u_grid, ref)                 # (3, P, 3)
    chans = [channel_floor(t, u_grid) for t in tabs]
    R = samples.refs[ref]
    total = float(np.sum(R))
    lo, hi = samples.u_range

    def image(s):
        return samples.image_at(float(min(max(math.log(s), lo), hi)))

    energy = sum(c["r"] * float(np.sum(image(c["s"])[k::3])) for k, c in enumerate(chans)) / total
    scalar = channel_floor(tabs.mean(axis=0), u_grid)
    scalar["energy_ratio"] = scalar["r"] * float(np.sum(image(scalar["s"]))) / total
    return {"relmse": float(np.mean([c["relmse"] for c in chans])), "energy_ratio": float(energy),
            "channels": chans, "scalar": scalar}


def terms_uniform(scene, N, settings, rtol=1e-6):
    """True when the terms of (F1) other than the extent take one value per colour channel over every cell of the
    LPV grid at ``N`` (the medium as the renderer resamples it): then a form is one ``(s_c, r_c)`` per channel."""
    from harness.calibration.form import grid_medium
    from sslpv_gl.material_form import cell_numbers

    st, a, g, dx = grid_medium(scene, N, settings)
    numbers = cell_numbers(st, a, g, dx, float(scene.boundary.eta))
    for name, x in numbers.items():
        if name == "ln_extent_per_step":
            continue
        x = np.asarray(x, dtype=np.float64).reshape(-1, np.shape(x)[-1])
        if np.any(np.ptp(x, axis=0) > rtol * np.maximum(np.abs(x).max(axis=0), 1.0)):
            return False
    return True


def read_floor(folder):
    """The floor written beside the calibration in ``folder`` (its :data:`FILE`), or None."""
    path = Path(folder) / FILE
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def floor_files(report):
    """The floor files a calibration's floor may come from, in the order :func:`floor_for` looks: its own
    :data:`FILE` beside ``report`` (its ``calibration.json``), then its sources' (a form's ``sources``)."""
    from harness import paths

    report = Path(report)
    try:
        sources = json.loads(report.read_text()).get("sources") or []
    except (OSError, ValueError):
        sources = []
    return [folder / FILE for folder in
            [report.parent, *(Path(s) if Path(s).is_absolute() else paths.REPO / s for s in sources)]]


def floor_for(report, key):
    """The floor of the calibration whose ``calibration.json`` is ``report`` at budget ``key`` (``"N=32 steps=32"``):
    its own :data:`FILE`, else that of the first of its sources (a form's ``sources``) that has the budget ->
    ``(budget entry, path of the floor file)``, or ``(None, None)``."""
    for folder in (f.parent for f in floor_files(report)):
        floor = read_floor(folder)
        if floor and key in (floor.get("budgets") or {}):
            return floor["budgets"][key], folder / FILE
    return None, None


def bounds(row):
    """True when a scene's floor bounds every calibration of the family: its terms are uniform on the grid and no
    channel's least lies at an end of the scan where the loss had not levelled off (beyond the scan, where a form may
    extrapolate, it may lie lower)."""
    return bool(row.get("uniform")) and all(c.get("settled", True) for c in row.get("channels", []))


def median_bound(entry, scenes=None):
    """The least median relMSE any calibration of the family can reach over ``scenes`` (default: the entry's):
    each scene whose floor bounds it (:func:`bounds`) at its floor (L1), each other scene, and each scene the entry
    has no row for (too few usable samples), at 0 -> float, or None when the entry has none of ``scenes``."""
    rows = entry.get("scenes") or {}
    names = list(scenes if scenes is not None else rows)
    if not any(n in rows for n in names):
        return None
    return statistics.median(rows[n]["relmse"] if n in rows and bounds(rows[n]) else 0.0 for n in names)


def scan_samples(samples, scan):
    """``samples`` (:class:`~harness.calibration.fit.SceneSamples`) restricted to the ``sigma_scale`` values of
    ``scan``: a calibration also renders at its fitted optima, and the floor is defined on the scan alone, so that
    ``calibrate`` and ``calibrate-floor`` give the same file."""
    from harness.calibration.fit import SceneSamples

    want = [math.log(float(x)) for x in scan]
    out = SceneSamples(samples.scene, samples.refs)
    for u, img in zip(samples.u, samples.images):
        if any(abs(u - w) < 1e-12 for w in want):
            out.add(math.exp(u), img)
    return out


def floor_info(scanner, cal, settings, scenes, command, wall_s=None):
    """The floor file's contents (every budget and scene of ``cal``, a calibration's report or what will be written
    as one, with its ``oracle``) from ``scanner``, which holds the calibration's scan."""
    names = list(cal["scenes"])
    u_grid = scan_grid(cal["sigma_scan"], U_POINTS)
    budgets, uniform = {}, {}
    for N, k in [(int(N), k) for N, k in cal["budgets"]]:
        label = budget_label(N, k)
        rows = {}
        for n in names:
            smp = scan_samples(scanner.samples[((N, k), n)], cal["sigma_scan"])
            if len(smp.u) < 3:
                continue
            if (n, N) not in uniform:                          # the same at every budget of a grid
                uniform[(n, N)] = terms_uniform(scenes[n], N, settings)
            rows[n] = scene_floor(smp, u_grid) | {"uniform": uniform[(n, N)],
                                                  "oracle": cal["results"][label]["oracle"][n]["relmse"]}
        budgets[label] = {"N": N, "steps": k, "scenes": rows,
                          "median": statistics.median(r["relmse"] for r in rows.values()) if rows else None,
                          "median_scalar": (statistics.median(r["scalar"]["relmse"] for r in rows.values())
                                            if rows else None)}
    return {"format": "sslpv-calibration-floor", "family": cal["family"], "mapping": cal["mapping"],
            "settings": settings, "scenes": names, "u_points": U_POINTS, "budgets": budgets,
            "renders": scanner.renders, "served_from_cache": scanner.served,
            "render_failures": [list(map(str, f)) for f in scanner.failures],
            "gl_renderer": getattr(scanner.renderer, "gl_renderer", "unknown"),
            "time": {"wall_s": wall_s}, "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "command": command}


def run_floor(source, out=None, renderer=None, cache=True, progress=print, argv=None,
              command="python -m harness.calibration.floor"):
    """The floor of every scene and budget of the ``sslpv-harness calibrate`` folder ``source``, written to ``out``
    (default: :data:`FILE` beside its ``calibration.json``) -> the report dict. The scan's images come from the
    result cache where an earlier run stored them (``cache``, :func:`harness.runs.cache.open_cache`'s argument).
    ``sslpv-harness calibrate`` writes the same file beside a new calibration (:func:`floor_info`)."""
    from harness.calibration.form_files import read_sources
    from harness.calibration.scan import calibration_scanner
    from harness.io.atomic import atomic_write

    t0 = time.perf_counter()
    source = Path(source)
    cal, settings = read_sources([str(source)])
    if "sigma_scan" not in cal:
        raise InputError(source / "calibration.json", "sigma_scan", "not a scalar calibration's report (a form has "
                         "no scan of its own)", "give the sslpv-harness calibrate folder it was fitted from")
    out = Path(out) if out is not None else source / FILE
    scanner, scenes, results_cache = calibration_scanner(cal, settings, source / "calibration.json", renderer, cache,
                                                         "calibration floor")
    for n in cal["scenes"]:
        for s in cal["sigma_scan"]:
            scanner.render(n, s)
        progress(f"scanned {n} at every sigma_scale of the calibration's scan")
    info = floor_info(scanner, cal, settings, scenes,
                      command + " " + " ".join(argv if argv is not None else ["--from", str(source)]),
                      wall_s=time.perf_counter() - t0) | {"source": str(source), "out": str(out)}
    if results_cache is not None:
        results_cache.prune()
    with atomic_write(out) as tmp:
        tmp.write_text(json.dumps(info, indent=1) + "\n")
    return info


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    ap = argparse.ArgumentParser(prog="python -m harness.calibration.floor", description=__doc__.splitlines()[0])
    ap.add_argument("--from", dest="source", required=True, help="an sslpv-harness calibrate --out folder")
    ap.add_argument("--out", default=None, help=f"the file to write (default: {FILE} in the --from folder)")
    ap.add_argument("--no-cache", action="store_true", help="render the scan afresh instead of serving it from the "
                    "result cache (cache/results/)")
    args = ap.parse_args(argv)
    try:
        info = run_floor(args.source, args.out, cache=not args.no_cache, argv=argv,
                         progress=lambda m: print(m, file=sys.stderr, flush=True))
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for label, b in info["budgets"].items():
        print(f"{label}: median floor {b['median']:.4g} per channel, {b['median_scalar']:.4g} per scene")
    return 0


if __name__ == "__main__":
    sys.exit(main())
