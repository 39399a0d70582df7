"""Independently re-seeded small references for the false-alarm measurement (never rendered in CI).

Renders ``--count`` references of each ``--scenes`` scene at the committed size (64x64)
and the committed references' noise target, each with its own seeds (``seed_base =
10000 + 16 j``: seeds ``seed_base .. seed_base + 7``, pilot and absorber seeds offset by
2^16 and 2^17 as in :func:`harness.reference.render.render_reference`), into
``cache/refs_reseeded/<scene>/<j>/``. Finished references are kept, so the command can
be interrupted and resumed. ``benchmarks/accuracy_sensitivity.py`` reads them.

    .venv/bin/python benchmarks/reseeded_references.py --count 20
"""

import argparse
import json
import time
from pathlib import Path

from harness import paths
from harness.regression.accuracy import small_scene

ROOT = paths.REPO / "cache" / "refs_reseeded"
SCENES = ("thin_ring", "absorbing_sphere", "two_lights")
SEED0, SEED_STEP = 10000, 16


def reference_dirs(scene, root=ROOT):
    """The finished re-seeded references of ``scene``, in seed order."""
    d = Path(root) / scene
    done = [p for p in d.glob("*") if (p / "reference.json").is_file()] if d.is_dir() else []
    return sorted(done, key=lambda p: int(p.name))


def render(scenes=SCENES, count=20, root=ROOT):
    from harness.reference.render import render_reference

    for name in scenes:
        scene = small_scene(name)
        target = scene.tolerances.get("small_reference_rel_se")
        kwargs = {"target_rel_se": float(target)} if target else {}
        for j in range(count):
            out = Path(root) / name / str(j)
            if (out / "reference.json").is_file():
                continue
            t0 = time.perf_counter()
            info = render_reference(scene, out, seed_base=SEED0 + SEED_STEP * j, **kwargs)
            print(f"{name} #{j}: seeds {info['seeds'][0]}..{info['seeds'][-1]}, median rel. SE "
                  f"{info['median_rel_se_subsurface']:.4f}, {time.perf_counter() - t0:.1f} s", flush=True)
    return {n: [str(p) for p in reference_dirs(n, root)] for n in scenes}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--count", type=int, default=20)
    args = ap.parse_args()
    print(json.dumps(render(args.scenes.split(","), args.count), indent=1))


if __name__ == "__main__":
    main()
