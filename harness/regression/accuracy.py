"""SSLPV accuracy checks against committed baselines (used by ``pytest -m accuracy``).

For one (scene, configuration) case: render SSLPV at the small size, measure every
metric against the committed small reference, and compare each headline metric of
the subsurface part with its baseline. A case fails when

    badness(value) > badness(baseline) + badness(noise floor) + tolerance,

``tolerance = max(abs, rel * badness(baseline))`` as stated per scene in
``baselines/accuracy_matrix.toml`` (:mod:`harness.regression.verdict` defines badness). On a
failure the images, the reference, an error map and a one-configuration results
store are written to an artifacts folder, and the message names the command that
accepts the new values.
"""

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from harness import paths
from harness.regression.baselines import SMALL_SIZE, committed_reference, find_entry, load_matrix, read_baseline
from harness.runs.params import config_label, parse_lists, expand
from harness.scene import load_scene
from harness.regression.verdict import HEADLINE, badness

REPO = paths.REPO
ARTIFACTS = REPO / "test-artifacts" / "accuracy"


@dataclass
class CaseResult:
    scene: str
    config: str
    checks: list = field(default_factory=list)   # (metric, value, threshold, baseline, floor, ok)
    artifacts: Path = None
    command: str = ""

    @property
    def failed(self):
        return [c for c in self.checks if not c[5]]

    def message(self):
        lines = [f"{self.scene} {self.config}: accuracy regression"]
        for metric, value, threshold, base, floor, ok in self.checks:
            mark = "FAIL" if not ok else "ok  "
            lines.append(f"  {mark} {metric:<13} value {value:.6g} vs threshold {threshold:.6g} "
                         f"(baseline {base:.6g} + floor {floor:.3g} + tolerance)")
        if self.artifacts:
            lines.append(f"  images, reference and error map: {self.artifacts}")
        if self.command:
            lines.append(f"  if the change is intended, accept the new values with: {self.command}")
        return "\n".join(lines)


def cases(matrix=None):
    """(scene name, SSLPVParams, tolerance) for every case of the accuracy matrix."""
    matrix = matrix or load_matrix()
    # [params] and each [[also]] table are cartesian products; a case appears once
    params = []
    for table in [matrix["params"]] + list(matrix.get("also", [])):
        params += [p for p in expand(parse_lists(table)) if p not in params]
    default_tol = dict({"rel": 0.03, "abs": 1e-4}, **matrix.get("tolerance", {}).get("default", {}))
    out = []
    for scene in matrix["scenes"]:
        tol = dict(default_tol, **matrix.get("tolerance", {}).get(scene, {}))
        out.extend((scene, p, tol) for p in params)
    return out


def small_scene(name):
    return load_scene(name).with_resolution(*SMALL_SIZE)


def load_case_reference(scene):
    from harness.runs.sweep import load_reference
    from harness.runs.worker import reference_floors

    ref = load_reference(committed_reference(scene), (scene.camera.height, scene.camera.width))
    return ref, reference_floors(ref)


def check_case(renderer, scene_name, params, tolerance, ref=None, floors=None, artifacts=ARTIFACTS,
               write_artifacts=True):
    """Render one case and judge it against its baseline; returns a :class:`CaseResult`."""
    from harness.errors import InputError
    from harness.runs.worker import measure

    scene = small_scene(scene_name)
    entries = read_baseline(scene_name)
    label = config_label(params)
    entry = find_entry(entries, list(SMALL_SIZE), params.as_dict())
    if entry is None:
        raise InputError(f"baselines/{scene_name}.json", label, "has no baseline for this configuration",
                         "create it with a sweep at 64x64 and `sslpv-harness baselines update --store ...`")
    if ref is None:
        ref, floors = load_case_reference(scene)
    res = renderer.render(scene, params)
    images = {"subsurface": res.subsurface, "full": res.full}
    rows = measure(images, ref, floors)
    result = CaseResult(scene_name, label)
    for r in rows:
        if r["image"] != "subsurface" or r["metric"] not in HEADLINE:
            continue
        base = entry["metrics"]["subsurface"][r["metric"]]
        b_base, b_floor = badness(r["metric"], base["value"]), badness(r["metric"], r["noise_floor"])
        threshold = b_base + b_floor + max(tolerance["abs"], tolerance["rel"] * b_base)
        value = badness(r["metric"], r["value"])
        result.checks.append((r["metric"], value, threshold, b_base, b_floor, bool(value <= threshold)))
    if result.failed and write_artifacts:
        result.artifacts = _write_artifacts(artifacts, scene, params, res, ref, rows)
        result.command = (f"sslpv-harness baselines update --scene {scene_name} "
                          f"--store {result.artifacts / 'store.sqlite'}")
    return result


def _write_artifacts(root, scene, params, res, ref, rows):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from harness.io.images import auto_exposure, write_exr, write_png
    from harness.store import Store

    out = Path(root) / scene.name / config_label(params)
    out.mkdir(parents=True, exist_ok=True)
    exposure = auto_exposure(ref["subsurface"])
    write_exr(out / "sslpv_subsurface.exr", res.subsurface)
    write_exr(out / "reference_subsurface.exr", ref["subsurface"], se=ref.get("se"))
    write_png(out / "sslpv_subsurface.png", res.subsurface, exposure)
    write_png(out / "reference_subsurface.png", ref["subsurface"], exposure)
    y = ref["subsurface"].mean(-1)
    err = np.abs(res.subsurface.mean(-1) - y) / (y + 1e-2)
    err[~ref["mask"]] = 0
    fig, ax = plt.subplots(figsize=(4, 3.4))
    im = ax.imshow(err, cmap="magma")
    fig.colorbar(im, ax=ax, label="|SSLPV - ref| / (ref + 0.01)")
    ax.set_axis_off()
    fig.savefig(out / "error_map.png", dpi=100)
    plt.close(fig)
    # A one-configuration store, so `baselines update --store` can accept these values.
    store_path = out / "store.sqlite"
    if store_path.exists():
        store_path.unlink()
    with Store(store_path) as st:
        rid = st.start_run("accuracy", {"scene": scene.name, "params": params.as_dict()})
        st.record_config(rid, scene.name, scene.content_hash, params.as_dict(), "ok", metrics=rows,
                         timings={k: v for k, v in res.timings_ms.items()
                                  if k in ("rsm", "injection", "propagation", "shading") and np.isfinite(v)},
                         render_dir=str(out),
                         reference_dir=str(committed_reference(scene)))
        st.finish_run(rid, "finished")
    (out / "values.json").write_text(json.dumps(rows, indent=1, default=float))
    return out
