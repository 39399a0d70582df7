"""``sslpv-harness reference SCENE``: a scene's Mitsuba ground truth, from the cache or rendered."""

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


def run(args):
    from harness.reference.cache import run_reference_cmd

    result = run_reference_cmd(args.scene, out_dir=args.out, target=args.target, spp=args.spp,
                               variant=args.variant, force=args.force)
    return result, None, 0
