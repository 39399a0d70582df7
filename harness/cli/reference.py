"""``sslpv-harness reference SCENE``: a scene's Mitsuba ground truth, from the cache or rendered on Dask."""

from pathlib import Path

from harness.cli.options import positive_int

HELP = "render (or fetch from the cache) a scene's Mitsuba ground truth"


def configure(sp):
    sp.add_argument("scene", help="suite scene name or path to a scene folder / scene.toml")
    sp.add_argument("--out", type=Path, help="also copy the reference into this folder")
    sp.add_argument("--target", type=float, help="median relative standard error to reach over lit pixels")
    sp.add_argument("--spp", type=positive_int, help="fixed samples per pixel per seed (skips the pilot)")
    sp.add_argument("--variant", choices=["llvm_ad_rgb", "cuda_ad_rgb", "scalar_rgb"], help="Mitsuba variant")
    sp.add_argument("--force", action="store_true", help="re-render even if a cached reference exists")
    sp.add_argument("--size", help="image size WxH (default: the scene's)")
    sp.add_argument("--max-minutes", dest="max_minutes", help="cap on the wall time; the result records the "
                    "noise it reached, and a sweep refuses a reference that missed its target")
    sp.add_argument("--estimate", action="store_true", help="print the predicted time to the target (cost "
                    "model, harness/reference/cost_model.json) without rendering")
    sp.add_argument("--scheduler", help="address of an existing Dask scheduler whose workers have this project "
                    "(default: a LocalCluster)")
    sp.add_argument("--workers", type=positive_int, help="LocalCluster workers (default: CPU cores)")
    sp.add_argument("--serial", action="store_true", help="render in this process, without Dask")
    sp.add_argument("--no-progress", action="store_true", help="print no progress on stderr")


def run(args):
    from harness.runs.references import run_reference_cmd

    result = run_reference_cmd(args.scene, out_dir=args.out, target=args.target, spp=args.spp,
                               variant=args.variant, force=args.force, max_minutes=args.max_minutes,
                               estimate=args.estimate, size=args.size, workers=args.workers,
                               scheduler=args.scheduler, serial=args.serial,
                               progress=not args.no_progress)
    return result, result.get("summary") if args.estimate else None, 0
