"""How much does the silhouette bias the comparison, with the old mask and with the new one?

Mitsuba box-filters each pixel; the GL renderer shades the pixel centre. On a pixel
that the silhouette crosses, the reference averages the surface with the black
background and is darker than SSLPV by about the covered fraction ``c``. For every
case of ``baselines/accuracy_matrix.toml`` (SSLPV at 64x64 against the committed
reference) this prints, per scene:

* the share of the old mask (``coverage > 0.5``) that is only partly covered, and their
  mean coverage (the reference's 16-ray ``mask.exr``);
* ``edge/ring``: ``sum(ref)/sum(SSLPV)`` on those pixels over the same ratio on the fully
  covered pixels next to them (their 8-neighbours): how much darker the reference is
  there, measured (1 = no bias), mean over the scene's cases;
* ``energy bias``: the reference energy the coverage takes away, relative to a
  centre-sampled image of the same surface, ``sum_p ref_p (1/c_p - 1) / sum_p ref_p``
  over the mask, with ``c_p`` measured with 16 x 16 rays per pixel (finer than the
  reference's 4 x 4), before (old mask) and after
  (:func:`harness.metrics.coverage.comparison_mask`, ``coverage >= 0.999``: what is left
  is pixels that all 16 of the reference's rays hit but that the silhouette still grazes);
* the mean relative change of relMSE and of ``|energy ratio - 1|`` from the old mask to
  the new one.

    .venv/bin/python benchmarks/silhouette_bias.py
"""

import numpy as np

from harness.metrics import compute
from harness.metrics.coverage import comparison_mask
from harness.regression.accuracy import cases, case_reference, small_scene
from sslpv_gl.renderer import SSLPVRenderer


def _ratio(ref, test, sel):
    return float(ref[sel].sum() / max(test[sel].sum(), 1e-30))


def _neighbours(sel):
    """Pixels 8-adjacent to ``sel``."""
    pad = np.pad(sel, 1, constant_values=False)
    out = np.zeros_like(sel)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            out |= pad[1 + dy:pad.shape[0] - 1 + dy, 1 + dx:pad.shape[1] - 1 + dx]
    return out & ~sel


def _energy_bias(y, fine, sel):
    lum = y.mean(axis=-1)
    c = np.maximum(fine[sel], 1e-6)
    return float((lum[sel] * (1.0 / c - 1.0)).sum() / lum[sel].sum())


def main():
    from harness.reference.mitsuba_scene import coverage_mask, use_variant

    use_variant()
    renderer = SSLPVRenderer()
    rows = {}
    for scene_name, params, _ in cases():
        scene = small_scene(scene_name)
        ref = case_reference(scene)
        cov = ref["coverage"]
        old, new = cov > 0.5, comparison_mask(cov)
        partial = old & ~new
        img = renderer.render(scene, params).subsurface.astype(np.float64)
        y = ref["subsurface"].astype(np.float64)
        ring = _neighbours(partial) & new
        edge = _ratio(y, img, partial) / _ratio(y, img, ring) if partial.any() and ring.any() else float("nan")
        d_rel = (compute("relmse", img, y, old).value / compute("relmse", img, y, new).value) - 1.0
        e_old = abs(compute("energy_ratio", img, y, old).value - 1.0)
        e_new = abs(compute("energy_ratio", img, y, new).value - 1.0)
        if scene_name not in rows:
            fine = coverage_mask(scene, sub=16)
            rows[scene_name] = {"share": float(partial.sum() / old.sum()),
                                "cov": float(cov[partial].mean()) if partial.any() else float("nan"),
                                "bias_before": _energy_bias(y, fine, old), "bias_after": _energy_bias(y, fine, new),
                                "edge": [], "relmse": [], "energy": []}
        r = rows[scene_name]
        r["edge"].append(edge)
        r["relmse"].append(d_rel)
        r["energy"].append(e_old / max(e_new, 1e-12) - 1.0)
    print(f"{'scene':<20} {'partial share':>13} {'mean cov':>8} {'edge/ring':>9} {'energy bias before':>18} "
          f"{'after':>9} {'relMSE old/new-1':>17} {'|E-1| old/new-1':>16}")
    for name, r in rows.items():
        edge = f"{np.mean(r['edge']):9.3f}" if np.isfinite(r["edge"]).any() else f"{'-':>9}"
        cov = f"{r['cov']:8.3f}" if np.isfinite(r["cov"]) else f"{'-':>8}"
        print(f"{name:<20} {r['share']:>13.4f} {cov} {edge} {r['bias_before']:>+18.4f} "
              f"{r['bias_after']:>+9.4f} {np.mean(r['relmse']):>+17.3f} {np.mean(r['energy']):>+16.3f}")
    edges = [e for r in rows.values() for e in r["edge"] if np.isfinite(e)]
    print(f"suite: on partly covered pixels the reference is {np.mean(edges):.3f} x as bright (relative to "
          f"SSLPV) as on their fully covered neighbours ({len(edges)} cases); energy bias over the mask "
          f"{np.mean([r['bias_before'] for r in rows.values()]):+.4f} before, "
          f"{np.mean([r['bias_after'] for r in rows.values()]):+.4f} after (mean over {len(rows)} scenes)")


if __name__ == "__main__":
    from page import run

    raise SystemExit(run(main, "silhouette_bias", 'How much the silhouette biases the comparison, with the old mask and the new one'))
