"""SSLPV accuracy checks against committed baselines (used by ``pytest -m accuracy``).

For one (scene, configuration) case: render SSLPV at the small size and compare it
with the case's committed image (``baselines/images/``), in the two steps of
:mod:`harness.regression.verdict`:

1. **changed?** equal within the floating-point tolerance of two OpenGL drivers
   (:func:`~harness.regression.verdict.image_change`): *unchanged*, the case passes with
   no statistics;
2. otherwise every headline metric of the subsurface image is judged as a paired
   difference against the committed small reference: ``Delta = badness(new) -
   badness(old)``, its standard error from the reference's per-pixel standard error,
   ``z`` and the threshold ``tol + t SE`` (Bonferroni over every metric of every case
   of ``baselines/accuracy_matrix.toml``, whose per-scene tolerances give ``tol``).

A **regression** fails the case; so does an **improvement** (as a snapshot test does:
the committed image and values must be updated, so a baseline never goes stale and a
later regression is never hidden behind an old, worse baseline). A change within
noise passes with a warning. A failure writes the images, the reference, an error map
and a one-configuration results store to an artifacts folder, and names the command
that accepts the new values and image.
"""

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from harness import paths
from harness.errors import InputError
from harness.reference.committed import small_scene as _small
from harness.regression.baselines import committed_image, committed_reference, find_entry, load_matrix, read_baseline
from harness.regression.verdict import HEADLINE, image_change, judge_images, overall
from harness.runs.params import config_label, expand, file_label, parse_lists
from harness.scene import load_scene

REPO = paths.REPO
ARTIFACTS = REPO / "test-artifacts" / "accuracy"


@dataclass
class CaseResult:
    scene: str
    config: str
    image: object = None                          # verdict.ImageChange against the committed image
    checks: list = field(default_factory=list)    # verdict.Change per headline metric (changed images only)
    verdict: str = "unchanged"
    notes: list = field(default_factory=list)     # one line each (another GL renderer, ...)
    artifacts: Path = None
    command: str = ""

    @property
    def failed(self):
        return [c for c in self.checks if c.verdict in ("regression", "improvement")]

    def message(self):
        lines = [f"{self.scene} {self.config}: {self.verdict}"]
        lines += [f"  note: {n}" for n in self.notes]
        if self.image is not None:
            lines.append(f"  image: {self.image.line()}")
        lines += [f"  {c.line()}" for c in self.checks]
        if self.artifacts:
            lines.append(f"  images, reference and error map: {self.artifacts}")
        if self.command:
            what = "the improvement" if self.verdict == "improvement" else "the change, if it is intended,"
            lines.append(f"  accept {what} (new values and image) with: {self.command}")
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
    """The suite scene at its committed small size (64x64; a non-square scene keeps its aspect)."""
    return _small(load_scene(name))


def case_reference(scene):
    """The committed small reference of ``scene`` (arrays of :func:`harness.runs.sweep.load_reference`)."""
    from harness.runs.sweep import load_reference

    return load_reference(committed_reference(scene), (scene.camera.height, scene.camera.width))


def load_case_reference(scene):
    """The committed small reference of ``scene`` and its noise floors (for measuring, not judging)."""
    from harness.runs.worker import reference_floors

    ref = case_reference(scene)
    return ref, reference_floors(ref)


def family_size(matrix=None):
    """Comparisons one accuracy run can judge: every headline metric of every case."""
    return len(cases(matrix)) * len(HEADLINE)


def reference_se(ref, part="subsurface"):
    """The reference's per-pixel standard error of ``part``, or one line saying it has none."""
    se = ref.get("se" if part == "subsurface" else "se_full")
    if se is None:
        src = Path(ref.get("dir") or "reference") / f"{part}.exr"
        raise InputError(src, "se", "has no per-pixel standard error (channels R_se, G_se, B_se), so a change "
                         "cannot be judged against its noise", "re-render it: `sslpv-harness baselines "
                         "regenerate-references`")
    return se


def check_case(renderer, scene_name, params, tolerance, ref=None, floors=None, artifacts=ARTIFACTS,
               write_artifacts=True, family=None, old=None):
    """Render one case and judge it against its committed image; returns a :class:`CaseResult`.

    ``ref`` replaces the committed reference (the arrays of ``load_reference``; the
    benchmarks pass re-seeded ones), ``old`` the committed ``(image, mask)``, ``family``
    the Bonferroni family (default :func:`family_size`). ``floors`` is accepted for
    callers of the former rule and ignored.
    """
    scene = small_scene(scene_name)
    entries = read_baseline(scene_name)
    label = config_label(params)
    size = [scene.camera.width, scene.camera.height]
    entry = find_entry(entries, size, params.as_dict())
    if entry is None:
        raise InputError(f"baselines/{scene_name}.json", f"{label} at {size[0]}x{size[1]}",
                         "has no baseline for this configuration",
                         "create it with `sslpv-harness sweep --size small ...` and "
                         "`sslpv-harness baselines update --store ...`")
    old_img, old_mask = old if old is not None else committed_image(scene_name, entry)
    res = renderer.render(scene, params)
    if old_img.shape != res.subsurface.shape:
        raise InputError(f"baselines/{entry['image']}", "size", f"is {old_img.shape[1]}x{old_img.shape[0]}, the "
                         f"render is {res.subsurface.shape[1]}x{res.subsurface.shape[0]}",
                         "accept a render of the matrix's size with `sslpv-harness baselines update`")
    result = CaseResult(scene_name, label)
    if entry.get("gl_renderer") and entry["gl_renderer"] != res.gl_renderer:
        result.notes.append(f"the committed image was rendered by {entry['gl_renderer']!r}, this run by "
                            f"{res.gl_renderer!r}")
    result.image = image_change(res.subsurface, old_img, res.mask, old_mask)
    if not result.image.changed:
        return result
    if ref is None:
        ref = case_reference(scene)
    result.checks = judge_images(scene_name, label, "subsurface", res.subsurface, old_img, ref["subsurface"],
                                 reference_se(ref), ref["mask"], tolerance,
                                 family if family is not None else family_size(), "baseline", k=ref.get("K"))
    result.verdict = overall(result.checks, image_changed=True)
    if result.failed and write_artifacts:
        from harness.runs.worker import measure, reference_floors

        rows = measure({"subsurface": res.subsurface, "full": res.full}, ref, reference_floors(ref))
        result.artifacts = _write_artifacts(artifacts, scene, params, res, ref, rows)
        result.command = (f"sslpv-harness baselines update --scenes {scene_name} "
                          f"--store {result.artifacts / 'store.sqlite'}")
    return result


def _write_artifacts(root, scene, params, res, ref, rows):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from harness.io.images import auto_exposure, write_exr, write_png
    from harness.store import Store

    out = Path(root) / scene.name / file_label(config_label(params))
    out.mkdir(parents=True, exist_ok=True)
    exposure = auto_exposure(ref["subsurface"])
    # the layout of a render folder, so that `baselines update` takes the image from here
    write_exr(out / "subsurface.exr", res.subsurface, extra={"mask": res.mask.astype("f4")})
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
                         reference_dir=str(ref.get("dir") or committed_reference(scene)))
        st.finish_run(rid, "finished", gl_renderer=res.gl_renderer)
    (out / "values.json").write_text(json.dumps(rows, indent=1, default=float))
    return out
