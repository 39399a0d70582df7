r"""The lighting twin: what no calibration that depends on the material can do for a back-lit object.

A calibrated mapping sets SSLPV's ``sigma_scale`` ``s`` and ``radiance_scale`` ``r`` per LPV cell and
colour from the cell's dimensionless numbers and the object's extent against the step count
(:mod:`sslpv_gl.material_form`, Eq. F1); a scalar calibration (version 2) is the case of one
``(s, r)`` per budget. Neither sees the lights. Take a scene ``A`` and its **lighting twin** ``B``:
the same mesh, medium, grid, camera and renderer settings, with every point light mirrored to the
other side of the object (:func:`mirror_light`). Every cell has the same numbers in both, so every
calibration gives both scenes the same ``s_c(x)`` and ``r_c(x)``.

In a homogeneous medium those are one number per colour channel ``c``. SSLPV's channel ``c`` is its
own transport problem (``sigma_lpv`` is per colour) and is linear in ``r_c``: its masked energy is
``r_c e_c(s_c)``. The study's energy ratio against the truth ``T`` (``energy_ratio`` of
:mod:`harness.metrics`: the mean over channels of the masked sums' ratios) is

    rho_A = (1/3) sum_c r_c e_{A,c}(s_c) / T_{A,c}.                                        (W1)

With ``u_c = r_c e_{B,c}(s_c) / T_{B,c} >= 0`` (the twin's own per-channel ratio) and the **twin factor**

    q_c(s) = [e_{A,c}(s) / T_{A,c}] / [e_{B,c}(s) / T_{B,c}],                               (W2)

the ratio of the two scenes' energy ratios is a weighted mean of the ``q_c``,

    rho_A / rho_B = sum_c u_c q_c(s_c) / sum_c u_c  in  [min_c inf_s q_c, max_c sup_s q_c],     (W3)

whatever the ``r_c`` and whichever ``s_c`` each channel takes. Both scenes within the energy target
``[lo, hi]`` needs ``rho_A / rho_B`` in ``[lo / hi, hi / lo]``. Where the attainable interval (W3)
misses it, no calibration of those settings puts both scenes in range, and one that puts ``A`` in
range renders its twin at

    rho_B >= lo / max_c sup_s q_c      (or rho_B <= hi / min_c inf_s q_c).                     (W4)

:func:`attainable` and :func:`verdict` evaluate (W3) and (W4) from the per-channel energies of a
scan over ``s`` (:func:`scan`); ``benchmarks/lighting_twin.py`` writes the page, with the truth of
both scenes from the path-length tracer (:mod:`harness.reference.path_length`).

Limits:

* the supremum and infimum are over the scanned ``s`` (a grid), not over every real ``s``; the page
  shows ``q`` at every point of the grid, so a maximum at its edge is visible;
* a homogeneous medium only: a varying one gives each cell its own ``s``, which a scan of one
  number per channel does not cover (:func:`scan` refuses it);
* the settings other than ``s`` and ``r`` (mapping, outside treatment, skip, phase scaling) are
  those scanned, each on its own; a calibration file carries one set of them;
* the truth comes from whatever the caller gives; the benchmark's tracer models index-matched
  spheres only.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from harness.errors import InputError
from harness.reference.path_length import constant_channels

__all__ = ["mirror_light", "lighting_twin", "check_homogeneous", "channel_energies", "twin_factors", "attainable", "verdict", "scan",
           "committed_verdicts", "VERDICTS"]

#: The verdicts ``benchmarks/lighting_twin.py --write`` commits, one ``<scene>.json`` per scene.
VERDICTS = Path(__file__).resolve().parents[2] / "baselines" / "lighting_twin"


def mirror_light(position, centre, camera):
    """``position`` mirrored through the plane through ``centre`` normal to the camera's view axis."""
    p = np.asarray(position, np.float64)
    c = np.asarray(centre, np.float64)
    v = np.asarray(camera.target, np.float64) - np.asarray(camera.origin, np.float64)
    v = v / np.linalg.norm(v)
    return p - 2.0 * float((p - c) @ v) * v


def lighting_twin(scene):
    """``scene`` with every point light mirrored to the other side of its mesh (same intensity).

    The mesh's centre is the mean of its vertices. A light lying in the mirror plane would stay put:
    it is refused, since such a scene has no other side to light."""
    centre = np.asarray(scene.mesh.vertices, np.float64).mean(axis=0)
    lights = []
    for light in scene.lights:
        q = mirror_light(light.position, centre, scene.camera)
        if np.allclose(q, light.position, rtol=0.0, atol=1e-9 * (1.0 + np.abs(q).max())):
            raise InputError(_file(scene), "lights.position", "lies in the plane through the object's centre normal to the "
                             "view axis, so it has no mirror image", "use a scene lit from in front or behind")
        lights.append(dataclasses.replace(light, position=tuple(float(x) for x in q)))
    return dataclasses.replace(scene, lights=tuple(lights))


def check_homogeneous(scene):
    """One line (:class:`InputError`) unless ``sigma_t``, albedo and ``g`` are each one value per channel
    (:func:`harness.reference.path_length.constant_channels`)."""
    for name in ("sigma_t", "albedo", "g"):
        constant_channels(getattr(scene.medium, name), name, _file(scene),
                          why="each cell would have its own calibrated scale")


def _file(scene):
    """The scene's file for an error line (its name where it was built in memory)."""
    return scene.path / "scene.toml" if scene.path is not None else scene.name


def channel_energies(image, mask):
    """The masked sum of each colour channel of ``image`` (H, W, 3) -> (3,)."""
    img = np.asarray(image, np.float64)
    return img[np.asarray(mask, bool)].sum(axis=0)


def twin_factors(e_a, t_a, e_b, t_b):
    """(W2) per channel: ``[e_A / T_A] / [e_B / T_B]``; ``nan`` where the twin's render is dark."""
    e_a, t_a, e_b, t_b = (np.asarray(x, np.float64) for x in (e_a, t_a, e_b, t_b))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(e_b > 0.0, (e_a / t_a) / (e_b / t_b), np.nan)


def attainable(q):
    """(W3): the interval of ``rho_A / rho_B`` over every ``s`` scanned and channel.

    ``q`` is (n_s, 3) twin factors (rows: the scan's ``s``); rows with a ``nan`` (a dark or failed
    render) are left out. Returns ``(low, high, row of low, row of high)``, ``None`` for all four
    when no row is usable."""
    q = np.asarray(q, np.float64)
    ok = np.isfinite(q).all(axis=1)
    if not ok.any():
        return None, None, None, None
    hi_rows = np.where(ok[:, None], q, -np.inf).max(axis=1)
    lo_rows = np.where(ok[:, None], q, np.inf).min(axis=1)
    i_hi, i_lo = int(np.argmax(hi_rows)), int(np.argmin(lo_rows))
    return float(lo_rows[i_lo]), float(hi_rows[i_hi]), i_lo, i_hi


def verdict(low, high, target=(0.8, 1.25)):
    """(W4): can both scenes lie in ``target``, and what does ``A`` in range force on the twin?

    Returns ``{"band", "possible", "twin_at_least", "twin_at_most"}``: ``band`` the interval
    ``[lo / hi, hi / lo]`` that ``rho_A / rho_B`` must meet (closed), ``possible`` whether the
    attainable ``[low, high]`` meets it, and the bounds (W4) on the twin's energy ratio when ``A``
    lies in ``target``."""
    lo, hi = target
    band = (lo / hi, hi / lo)
    possible = high >= band[0] and low <= band[1]
    return {"band": band, "possible": bool(possible),
            "twin_at_least": lo / high if high > 0 else float("inf"),
            "twin_at_most": hi / low if low > 0 else float("inf")}


def scan(renderer, scene_a, scene_b, params, sigma_scales, budgets, mask):
    """Per-channel masked energies of both scenes at every ``s`` and budget.

    ``params``: an :class:`sslpv_gl.params.SSLPVParams` whose ``sigma_scale`` is replaced; ``budgets``:
    step counts and/or ``"steady"``. Returns ``{budget: (e_a, e_b)}`` with ``e_*`` (n_s, 3); a render
    that fails (a steady solve that does not converge) gives a row of ``nan``."""
    for sc in (scene_a, scene_b):
        check_homogeneous(sc)
    ints = sorted(b for b in budgets if b != "steady")
    out = {b: (np.full((len(sigma_scales), 3), np.nan), np.full((len(sigma_scales), 3), np.nan)) for b in budgets}
    for i, s in enumerate(sigma_scales):
        for j, sc in enumerate((scene_a, scene_b)):
            if ints:
                p = params.replace(sigma_scale=float(s), steps=max(ints))
                for k, r in zip(ints, renderer.render_steps(sc, p, ints)):
                    out[k][j][i] = channel_energies(r.subsurface, mask)
            if "steady" in budgets:
                try:
                    r = renderer.render(sc, params.replace(sigma_scale=float(s), steps="steady"))
                except ValueError:
                    continue
                out["steady"][j][i] = channel_energies(r.subsurface, mask)
    return out


def no_verdicts(name):
    """Why a scene has no lighting-twin verdicts, with the command that measures them."""
    return (f"no committed lighting twin of this scene; `python benchmarks/lighting_twin.py --scene {name} --write` "
            "measures one for a homogeneous scene")


def committed_verdicts(scene, grid, folder=None):
    """The committed lighting-twin verdicts of ``scene`` (a :class:`~harness.scene.Scene`) at grid ``grid`` ->
    ``{"measured": True, "page", "command", "commit", "budgets": {steps: {"possible", "of", "closest", "largest",
    "twin_at_least"}}}``: per budget, how many of the scanned settings can put the scene and its lighting twin both
    in the energy range (W3), the setting whose attainable ratio reaches highest (``closest``, its ``largest``
    ratio) and the least energy ratio of the twin when the scene is in range with it (W4). Else ``{"measured":
    False, "why"}``: no file, a file for another grid, or a scene that changed since the file was written (its
    content hash)."""
    path = Path(folder or VERDICTS) / f"{scene.name}.json"
    if not path.is_file():
        return {"measured": False, "why": no_verdicts(scene.name)}
    data = json.loads(path.read_text())
    if data.get("grid") != grid:
        return {"measured": False, "why": f"the committed lighting twin is at N = {data.get('grid')}, not {grid}"}
    if data.get("content_hash") != scene.content_hash:
        return {"measured": False, "why": "the scene changed since its lighting twin was measured"}
    budgets = {}
    for steps, rows in data["budgets"].items():
        usable = {name: r for name, r in rows.items() if r.get("usable")}
        if not usable:
            continue
        closest = max(usable, key=lambda name: usable[name]["high"])
        budgets[steps] = {"possible": sum(1 for r in usable.values() if r["possible"]), "of": len(rows),
                          "closest": closest, "largest": usable[closest]["high"],
                          "twin_at_least": usable[closest]["twin_at_least"]}
    return {"measured": True, "page": data.get("page"), "command": data.get("command"), "commit": data.get("commit"),
            "budgets": budgets}
