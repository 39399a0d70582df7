"""``sslpv-harness calibrate --family F --out DIR``: fit a mapping family to the references, per budget."""

from harness.cli.options import add_no_cache, add_out, add_progress, add_scenes, add_size
from harness.errors import InputError

HELP = "fit a mapping family's sigma_scale and radiance_scale to the references, per (N, steps) budget"


def configure(sp):
    from harness.calibration.families import FAMILIES

    sp.add_argument("--family", required=True, metavar="FAMILY", help=f"mapping family: {' | '.join(FAMILIES)}")
    add_out(sp, "calibrated.toml, calibration.json, index.html, floor.json; new, empty, or written by calibrate before",
            required=True)
    add_scenes(sp, default="every index-matched suite scene; at least 2")
    sp.add_argument("--grid", default="32", metavar="N,...",
                    help="comma-separated LPV grid resolutions N of the budgets, each in [4, 256] (default: 32)")
    sp.add_argument("--steps", default="8,16,32,64,steady", metavar="K,...",
                    help="comma-separated step counts of the budgets, each in [0, 1024], and/or steady "
                         "(default: 8,16,32,64,steady)")
    add_size(sp, ("WxH",), default="each scene's committed small reference; a reference at that size must exist")
    sp.add_argument("--sigma-range", dest="sigma_range", metavar="MIN,MAX",
                    help="the scanned sigma_scale range, 0 < MIN < MAX (default: the family's, 0.0625,64)")
    sp.add_argument("--points", default="11", metavar="N", help="scanned sigma_scale values, log-spaced, an integer "
                    "in [5, 64] (default: 11)")
    sp.add_argument("--skip", metavar="SKIP", help="renderer setting of the fit: first propagation steps not "
                    "accumulated, in [0, steps] (default: the family's)")
    sp.add_argument("--outside", metavar="OUTSIDE", help="renderer setting of the fit: vacuum | material | absorb | "
                    "extrapolated | interior (default: the family's)")
    sp.add_argument("--boundary-reflect", dest="boundary_reflect", metavar="MODE", help="renderer setting of the "
                    "fit, an extension: none | rdr (R_dr of the light reaching the surface returns into the medium; "
                    "default: the family's, none)")
    sp.add_argument("--phase-scaling", dest="phase_scaling", metavar="MODE", help="renderer setting of the fit, an "
                    "extension: none | delta-eddington (default: the family's, none)")
    sp.add_argument("--exitance", metavar="MODE", help="renderer setting of the fit, an extension: isotropic | "
                    "boundary (diffusion theory's exitance at the extrapolated boundary; the diffusion family with "
                    "--outside extrapolated only; default: the family's, isotropic)")
    sp.add_argument("--inject-depth", dest="inject_depth", metavar="MFP", help="renderer setting of the fit, an "
                    "extension: inject each texel this many reduced mean free paths deep, in [0, 16] (sslpv_gl.inject "
                    "Eq. (J1); default: the family's, 0)")
    sp.add_argument("--shade-depth", dest="shade_depth", metavar="CELLS", help="renderer setting of the fit, an "
                    "extension: read the grid this many cells inwards of each shaded point, in [0, 4] (sslpv_gl.shade "
                    "Eq. (S1); default: the family's, 0)")
    sp.add_argument("--lookup", metavar="LOOKUP", help="renderer setting of the fit: the shading's read of the "
                    "accumulation grid, cell (each cell's own coefficients, the paper's) | trilinear (an extension: "
                    "interpolated between cell centres; default: the family's, cell)")
    add_progress(sp)
    add_no_cache(sp)


def _numbers(flag, text, kind):
    try:
        return [kind(x) for x in str(text).split(",")]
    except ValueError:
        raise InputError(flag, flag.lstrip("-"), f"{text!r} is not a comma-separated list of "
                         f"{'integers' if kind is int else 'numbers'}", "write e.g. 32 or 0.0625,64") from None


def _steps(text):
    out = []
    for x in str(text).split(","):
        x = x.strip()
        try:
            out.append(int(x))
        except ValueError:
            out.append(x)
    return out


def run(args):
    from harness.calibration.run import print_summary, run_calibrate
    from harness.runs.sweep import parse_size, resolve_scenes

    settings = {}
    if args.skip is not None:
        settings["skip"] = _numbers("--skip", args.skip, int)[0]
    if args.inject_depth is not None:
        settings["inject_depth"] = _numbers("--inject-depth", args.inject_depth, float)[0]
    if args.shade_depth is not None:
        settings["shade_depth"] = _numbers("--shade-depth", args.shade_depth, float)[0]
    for key in ("outside", "boundary_reflect", "phase_scaling", "exitance", "lookup"):
        if getattr(args, key) is not None:
            settings[key] = getattr(args, key)
    rng = None
    if args.sigma_range is not None:
        rng = _numbers("--sigma-range", args.sigma_range, float)
        if len(rng) != 2:
            raise InputError("--sigma-range", "sigma-range", f"{args.sigma_range!r} is not MIN,MAX",
                             "write e.g. 0.0625,64")
    points = _numbers("--points", args.points, int)
    if len(points) != 1:
        raise InputError("--points", "points", f"{args.points!r} is not one integer", "write e.g. 11")
    size = parse_size(args.size)
    summary = run_calibrate(family=args.family, out=args.out,
                            scenes=resolve_scenes(args.scenes) if args.scenes else None,
                            grids=_numbers("--grid", args.grid, int), steps=_steps(args.steps),
                            size=tuple(size) if size else None, sigma_range=rng, points=points[0],
                            settings=settings, progress=args.progress, argv=args.argv, cache=not args.no_cache)
    return summary, None if args.json else print_summary(summary), 0
