"""The synthetic results store and report site shared by ``test_report`` and ``test_report_browser``.

Building them takes tens of seconds (real metrics, FLIP maps, plots), so the
session fixture ``synthetic_site`` in ``conftest.py`` builds them once.
"""

import json
from pathlib import Path

import numpy as np

from harness.io import images as imageio
from harness.store import Store

H, W = 40, 56
GRIDS, STEPS, MAPPINGS = (16, 32), (8, 16, 32), ("paper", "exact")


def _blob(h, w, centre, colour):
    y, x = np.mgrid[0:h, 0:w]
    r2 = ((x - centre[0] * w) ** 2 + (y - centre[1] * h) ** 2) / (0.25 * w) ** 2
    return (np.exp(-r2)[..., None] * np.asarray(colour)[None, None, :]).astype(np.float32)


def make_synthetic_store(root, scenes=("slab", "bunny head"), failed=True):
    """A store with one sweep run over GRIDS x STEPS x MAPPINGS per scene, real metrics
    (harness.metrics.compare_images with noise floors) and small EXRs under ``root``."""
    from harness.metrics import compare_images

    root = Path(root)
    rng = np.random.default_rng(7)
    store_path = root / "results.sqlite"
    with Store(store_path) as st:
        run = st.start_run("sweep", {"grids": GRIDS, "steps": STEPS}, gl_renderer="llvmpipe (synthetic)",
                           git_commit="0123456789abcdef0123456789abcdef01234567")
        for si, scene in enumerate(scenes):
            ref_dir = root / "refs" / scene
            sub = _blob(H, W, (0.45 + 0.1 * si, 0.5), (1.0, 0.5, 0.25))
            full = sub + 0.05
            half_a = np.clip(sub + rng.normal(0, 0.01, sub.shape), 0, None).astype(np.float32)
            half_b = np.clip(2 * sub - half_a, 0, None).astype(np.float32)
            mask = (sub.mean(axis=-1) > 1e-3).astype(np.float32)
            imageio.write_exr(ref_dir / "subsurface.exr", sub, se=np.full_like(sub, 0.01), extra={"mask": mask})
            imageio.write_exr(ref_dir / "full.exr", full)
            imageio.write_png(ref_dir / "preview.png", full, imageio.auto_exposure(full))
            (ref_dir / "reference.json").write_text(json.dumps({"spp": 4096, "variant": "llvm_ad_rgb"}))
            for g in GRIDS:
                for s in STEPS:
                    for mp in MAPPINGS:
                        params = {"N": g, "steps": s, "mapping": mp, "skip": 2, "inject_offset": 0.0}
                        rdir = root / "renders" / scene / f"g{g}_s{s}_{mp}"
                        # Energy is lost at few steps (paper Fig. 8), blur grows with a coarse grid.
                        scale = {8: 1 / 3, 16: 1 / 2, 32: 1 / 1.2}[s] * (1.0 if mp == "paper" else 0.9)
                        t_sub = (scale * _blob(H, W, (0.45 + 0.1 * si + 0.2 / g, 0.5), (1.0, 0.5, 0.25))
                                 + rng.normal(0, 0.002, (H, W, 3))).clip(0).astype(np.float32)
                        t_full = (t_sub + 0.05).astype(np.float32)
                        imageio.write_exr(rdir / "subsurface.exr", t_sub)
                        imageio.write_exr(rdir / "full.exr", t_full)
                        (rdir / "render.json").write_text("{}")
                        rows = []
                        for image, t, y in (("subsurface", t_sub, sub), ("full", t_full, full)):
                            ha, hb = (half_a, half_b) if image == "subsurface" else (half_a + 0.05, half_b + 0.05)
                            for r in compare_images(t, y, mask > 0.5, ha, hb):
                                rows.append({**r, "image": image})
                        prop = g ** 3 * s * 2e-5
                        timings = {"rsm": 0.3, "injection": 0.2, "propagation": prop, "shading": 0.5}
                        timings["total"] = sum(timings.values())
                        st.record_config(run, scene, f"hash-{si}", params, "ok", metrics=rows, timings=timings,
                                         render_dir=rdir, reference_dir=ref_dir)
            if failed:
                st.record_config(run, scene, f"hash-{si}", {"N": 64, "steps": 64, "mapping": "paper", "skip": 2, "inject_offset": 0.0},
                                 "failed", error="GL_OUT_OF_MEMORY <allocating 64^3 grid>", reference_dir=ref_dir)
        st.finish_run(run, "ok")
    return store_path, run
