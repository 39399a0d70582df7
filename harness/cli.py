"""``sslpv-harness``: the command line.

Every subcommand takes ``--json`` and then prints exactly one JSON object on
stdout: what it wrote (paths) and what it measured (figures). Bad input prints
one line on stderr (``error: <file or setting>: <field>: <problem>; <fix>``)
and exits with status 2; a missing system component (LLVM, OpenGL) exits 3.
"""

import argparse
import json
import sys
from pathlib import Path

from harness.errors import EnvironmentProblem, InputError

REPO = Path(__file__).resolve().parent.parent


def _emit(args, result, text=None):
    if args.json:
        print(json.dumps(result, indent=None, default=str))
    elif text is not None:
        print(text)
    else:
        print(json.dumps(result, indent=2, default=str))


def _positive_int(value):
    try:
        out = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{value!r} is not an integer") from None
    if out <= 0:
        raise argparse.ArgumentTypeError(f"{value!r} must be > 0")
    return out


# --------------------------------------------------------------------------- subcommands

def cmd_scenes(args):
    from harness.scene import list_scenes, load_scene

    rows = []
    for name in list_scenes():
        s = load_scene(name)
        rows.append({"name": name, "boundary": s.boundary.kind, "lights": len(s.lights),
                     "grid": list(s.medium.resolution), "size": [s.camera.width, s.camera.height],
                     "hash": s.content_hash[:12], "description": s.description})
    width = max(len(r["name"]) for r in rows) if rows else 4
    text = "\n".join(f"{r['name']:<{width}}  {r['boundary']:<13} {r['lights']} light{'s' if r['lights'] > 1 else ' '} "
                     f"{r['hash']}  {r['description']}" for r in rows)
    _emit(args, {"scenes": rows}, text)


def cmd_reference(args):
    from harness.reference.cache import run_reference_cmd

    result = run_reference_cmd(args.scene, out_dir=args.out, target=args.target, spp=args.spp,
                               variant=args.variant, force=args.force)
    _emit(args, result)


def cmd_render(args):
    from harness.runs.render import run_render

    from harness.runs.params import params_from_cli

    params = params_from_cli(vars(args))
    result = run_render(args.scene, args.out, params, as_json=args.json)
    _emit(args, result)


def cmd_compare(args):
    from harness.compare_cmd import format_table, run_compare

    result = run_compare(args.ref, args.test, mask_path=args.mask, as_json=args.json)
    _emit(args, result, None if args.json else format_table(result))


def cmd_sweep(args):
    from harness.runs.sweep import run_sweep_cli

    _emit(args, run_sweep_cli(args))


def cmd_report(args):
    from harness.report_cmd import run_report_cli

    _emit(args, run_report_cli(args))


def cmd_export(args):
    from harness.report_cmd import resolve_store
    from harness.store import Store

    with Store(resolve_store(args.source)) as st:
        rows = st.export(args.out, run_id=args.run, scene=args.scene)
    _emit(args, {"store": str(args.source), "out": str(args.out), "rows": rows})


def cmd_nightly(args):
    from harness.regression.nightly import run_nightly_cli

    result = run_nightly_cli(args)
    _emit(args, result)
    return 1 if result.get("verdict") == "regression" else 0


def cmd_baselines(args):
    from harness.regression.baselines import run_baselines_cli

    result, text = run_baselines_cli(args)
    _emit(args, result, text)


# --------------------------------------------------------------------------- parser

def build_parser():
    p = argparse.ArgumentParser(prog="sslpv-harness", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)

    def add(name, func, help_):
        sp = sub.add_parser(name, help=help_, description=help_)
        sp.add_argument("--json", action="store_true", help="print one JSON object on stdout")
        sp.set_defaults(func=func)
        return sp

    add("scenes", cmd_scenes, "list the scene suite, one line each")

    sp = add("reference", cmd_reference, "render (or fetch from the cache) a scene's Mitsuba ground truth")
    sp.add_argument("scene", help="suite scene name or path to a scene folder / scene.toml")
    sp.add_argument("--out", type=Path, help="also copy the reference into this folder")
    sp.add_argument("--target", type=float, help="median relative standard error to reach over lit pixels")
    sp.add_argument("--spp", type=_positive_int, help="fixed samples per pixel per seed (skips the pilot)")
    sp.add_argument("--variant", choices=["llvm_ad_rgb", "cuda_ad_rgb", "scalar_rgb"], help="Mitsuba variant")
    sp.add_argument("--force", action="store_true", help="re-render even if a cached reference exists")

    sp = add("render", cmd_render, "render a scene with the SSLPV GLSL renderer")
    sp.add_argument("scene", help="suite scene name or path")
    sp.add_argument("--out", type=Path, required=True, help="output folder")
    _add_sslpv_args(sp, multi=False)

    sp = add("compare", cmd_compare, "print every metric between two EXR files")
    sp.add_argument("ref", type=Path, help="reference EXR")
    sp.add_argument("test", type=Path, help="test EXR")
    sp.add_argument("--mask", type=Path, help="EXR whose R channel > 0.5 marks the pixels to compare")

    sp = add("sweep", cmd_sweep, "render every SSLPV configuration of a sweep and store its metrics")
    sp.add_argument("--scenes", help="comma-separated scene names (default: the whole suite)")
    sp.add_argument("--config", type=Path, help="re-run a sweep from the sweep.json it wrote")
    sp.add_argument("--out", type=Path, help="output folder (holds store.sqlite, renders/, sweep.json)")
    sp.add_argument("--store", type=Path, help="results store (default: OUT/store.sqlite)")
    sp.add_argument("--scheduler", help="address of an existing Dask scheduler (default: a LocalCluster)")
    sp.add_argument("--workers", type=_positive_int, help="LocalCluster workers (default: CPU cores)")
    sp.add_argument("--size", help="image size WxH for SSLPV and reference (default: the scene's)")
    sp.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    _add_sslpv_args(sp, multi=True)

    sp = add("report", cmd_report, "build the static HTML report of a store or a sweep folder")
    sp.add_argument("source", type=Path, help="store.sqlite or a sweep folder")
    sp.add_argument("--out", type=Path, required=True, help="output folder for the site")
    sp.add_argument("--run", type=int, help="run id (default: the latest)")
    sp.add_argument("--budget-ms", type=float, help="SSLPV cost budget for the summary (default: median cost)")

    sp = add("export", cmd_export, "export a store's results to CSV (or Parquet, with pyarrow) for analysis")
    sp.add_argument("source", type=Path, help="store.sqlite or a sweep folder")
    sp.add_argument("--out", type=Path, required=True, help="output file: .csv or .parquet")
    sp.add_argument("--run", type=int, help="only this run id")
    sp.add_argument("--scene", help="only this scene")

    sp = add("nightly", cmd_nightly, "run the standard matrix, append to the store, write the nightly report")
    sp.add_argument("--matrix", type=Path, default=REPO / "harness" / "regression" / "nightly_matrix.toml",
                    help="the standard matrix file")
    sp.add_argument("--store", type=Path, default=REPO / "reports" / "nightly.sqlite", help="results store")
    sp.add_argument("--out", type=Path, default=REPO / "reports" / "nightly", help="reports folder")
    sp.add_argument("--date", help="night's date, YYYY-MM-DD (default: today)")
    sp.add_argument("--scheduler", help="address of an existing Dask scheduler")

    sp = add("baselines", cmd_baselines, "manage the committed accuracy baselines")
    sp.add_argument("action", choices=["update", "show", "regenerate-references"])
    sp.add_argument("--scene", help="only this scene")
    sp.add_argument("--store", type=Path, help="store holding the new values (update)")
    sp.add_argument("--into", type=Path, help="regenerate-references: write the checked new reference here "
                    "instead of replacing the committed one")
    return p


def _add_sslpv_args(sp, multi):
    """Renderer parameters; a sweep takes each as a comma-separated list."""
    kind = "comma-separated list of " if multi else ""
    sp.add_argument("--grid", help=f"{kind}LPV grid resolution N (cells per axis)")
    sp.add_argument("--steps", help=f"{kind}propagation steps K")
    sp.add_argument("--mapping", help=f"{kind}parameter mapping: literal | collision")
    sp.add_argument("--resample", help=f"{kind}material resampling: box | point")
    sp.add_argument("--outside", help=f"{kind}cells outside the mesh: vacuum | material")
    sp.add_argument("--lookup", help=f"{kind}shading lookup: cell | trilinear")
    sp.add_argument("--skip", help=f"{kind}propagation steps not accumulated (paper: 2)")
    sp.add_argument("--inject-offset", dest="inject_offset", help=f"{kind}injection offset along -n (scene units)")
    sp.add_argument("--precision", help=f"{kind}grid precision: fp32 | fp16")
    sp.add_argument("--rsm-size", dest="rsm_size", help=f"{kind}shadow-map resolution")
    sp.add_argument("--inject-size", dest="inject_size", help=f"{kind}injection RSM resolution")
    sp.add_argument("--eta2", help=f"{kind}true: divide outgoing radiance by eta^2 (not in the paper's Eq. 4)")


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        code = args.func(args)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except EnvironmentProblem as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 3
    except KeyboardInterrupt:
        print("interrupted; finished results are kept, run the same command again to resume", file=sys.stderr)
        return 130
    return int(code or 0)


if __name__ == "__main__":
    sys.exit(main())
