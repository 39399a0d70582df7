"""``sslpv-harness reference SCENE``: a scene's Mitsuba ground truth, from the cache or rendered on Dask."""

from harness.cli.options import (add_cluster, add_out, add_progress, add_scene, add_size, add_sms_split,
                                 positive_int)

HELP = "render (or fetch from the cache) a scene's Mitsuba ground truth"


def configure(sp):
    add_scene(sp)
    add_out(sp, "a copy of the reference (subsurface.exr, full.exr, half_a.exr, half_b.exr, mask.exr, "
            "reference.json)", default="none; the reference stays in cache/references/")
    sp.add_argument("--target", type=float, metavar="SE", help="median relative standard error to reach over lit "
                    "pixels, in (0, 1) (default: the scene's reference_rel_se tolerance, else 0.05)")
    sp.add_argument("--spp", type=positive_int, metavar="N", help="fixed samples per pixel per seed, an integer > 0; "
                    "skips the pilot (default: the pilot chooses)")
    sp.add_argument("--variant", choices=["llvm_ad_rgb", "cuda_ad_rgb", "scalar_rgb"],
                    help="Mitsuba variant: llvm_ad_rgb | cuda_ad_rgb | scalar_rgb (default: llvm_ad_rgb)")
    sp.add_argument("--force", action="store_true", help="re-render even if a cached reference exists")
    add_sms_split(sp)
    add_size(sp, ("WxH",))
    sp.add_argument("--max-minutes", dest="max_minutes", metavar="M", help="cap on the wall time, minutes > 0; the "
                    "result records the noise it reached, and a sweep refuses a reference that missed its target "
                    "(default: no cap)")
    sp.add_argument("--estimate", action="store_true", help="print the predicted time to the target (cost "
                    "model, harness/reference/cost_model.json) without rendering")
    add_cluster(sp, serial=True)
    add_progress(sp)


def run(args):
    from harness.runs.references import run_reference_cmd

    result = run_reference_cmd(args.scene, out_dir=args.out, target=args.target, spp=args.spp,
                               variant=args.variant, force=args.force, max_minutes=args.max_minutes,
                               estimate=args.estimate, size=args.size, workers=args.workers,
                               scheduler=args.scheduler, serial=args.serial, progress=args.progress,
                               sms_split=args.sms_split)
    return result, result.get("summary") if args.estimate else None, 0
