"""``sslpv-harness calibrate --family F --out DIR``: fit a mapping family to the references, per budget."""

from pathlib import Path

from harness.errors import InputError

HELP = "fit a mapping family's sigma_scale and radiance_scale to the references, per (N, steps) budget"


def configure(sp):
    from harness.calibration.families import FAMILIES

    sp.add_argument("--family", required=True, help=f"mapping family: {' | '.join(FAMILIES)}")
    sp.add_argument("--out", type=Path, required=True, help="output folder (calibrated.toml, calibration.json, "
                    "index.html); new, empty, or written by calibrate before")
    sp.add_argument("--scenes", help="comma-separated scene names, at least 2 (default: every index-matched "
                    "suite scene)")
    sp.add_argument("--grid", default="32", help="comma-separated LPV grid resolutions N of the budgets (default 32)")
    sp.add_argument("--steps", default="8,16,32,64,steady",
                    help="comma-separated step counts of the budgets, and/or steady (default 8,16,32,64,steady)")
    sp.add_argument("--size", help="image size WxH of the references to fit against (default: each scene's "
                    "committed small reference); a reference at that size must exist")
    sp.add_argument("--sigma-range", dest="sigma_range", help="MIN,MAX of the scanned sigma_scale (default: the "
                    "family's, 0.0625,64)")
    sp.add_argument("--points", default="11", help="scanned sigma_scale values, log-spaced (default 11)")
    sp.add_argument("--skip", help="renderer setting of the fit (default: the family's)")
    sp.add_argument("--outside", help="renderer setting of the fit: vacuum | material | absorb | extrapolated | interior")
    sp.add_argument("--no-progress", action="store_true", help="no progress on stderr")


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
    if args.outside is not None:
        settings["outside"] = args.outside
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
                            settings=settings, progress=not args.no_progress, argv=args.argv)
    return summary, None if args.json else print_summary(summary), 0
