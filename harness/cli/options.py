"""Argument helpers that several commands share."""

import argparse
import math


def positive_int(value):
    """argparse type: an integer > 0."""
    try:
        out = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer > 0, got {value!r}") from None
    if out <= 0:
        raise argparse.ArgumentTypeError(f"must be an integer > 0, got {value!r}")
    return out


def positive_number(value):
    """argparse type: a finite number > 0 (``nan``, ``inf`` and ``-1`` are refused)."""
    try:
        out = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number > 0, got {value!r}") from None
    if not math.isfinite(out) or out <= 0:
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {value!r}")
    return out


def add_sslpv_args(sp, multi):
    """Renderer parameters; a sweep takes each as a comma-separated list."""
    kind = "comma-separated list of " if multi else ""
    sp.add_argument("--grid", help=f"{kind}LPV grid resolution N (cells per axis)")
    sp.add_argument("--steps", help=f"{kind}propagation steps K, or auto (to convergence) or steady (solved)")
    sp.add_argument("--mapping", help=f"{kind}parameter mapping: literal | collision | diffusion | calibrated:PATH")
    sp.add_argument("--resample", help=f"{kind}material resampling: box | point")
    sp.add_argument("--outside", help=f"{kind}cells outside the mesh: vacuum | material | absorb | extrapolated | interior")
    sp.add_argument("--lookup", help=f"{kind}shading lookup: cell | trilinear")
    sp.add_argument("--skip", help=f"{kind}propagation steps not accumulated (paper: 2)")
    sp.add_argument("--inject-offset", dest="inject_offset", help=f"{kind}injection offset along -n (scene units)")
    sp.add_argument("--precision", help=f"{kind}grid precision: fp32 | fp16")
    sp.add_argument("--rsm-size", dest="rsm_size", help=f"{kind}shadow-map resolution")
    sp.add_argument("--inject-size", dest="inject_size", help=f"{kind}injection RSM resolution")
    sp.add_argument("--eta2", help=f"{kind}true: divide outgoing radiance by eta^2 (not in the paper's Eq. 4)")
    sp.add_argument("--sigma-scale", dest="sigma_scale", help=f"{kind}factor on the mapping's sigma_lpv (calibration)")
    sp.add_argument("--radiance-scale", dest="radiance_scale", help=f"{kind}factor on the subsurface radiance")
    sp.add_argument("--converge-tol", dest="converge_tol", help=f"{kind}steps=auto: remaining flux fraction to stop at")
    sp.add_argument("--max-steps", dest="max_steps", help=f"{kind}steps=auto: step cap")


def add_method_args(sp, multi):
    """``--method`` and the parameters of every method other than SSLPV (``harness.methods``), from their docs."""
    from harness.methods import METHOD_NAMES, get_method

    kind = "comma-separated list of " if multi else ""
    sp.add_argument("--method", help=f"{kind}method: {' | '.join(METHOD_NAMES)} (default sslpv); each method takes "
                                     "only its own parameters")
    seen = set(get_method("sslpv").cli)
    for name in METHOD_NAMES:
        m = get_method(name)
        for cli, field in m.cli.items():
            if cli in seen:
                continue
            seen.add(cli)
            owners = ", ".join(n for n in METHOD_NAMES if cli in get_method(n).cli)
            sp.add_argument("--" + cli.replace("_", "-"), dest=cli, help=f"{kind}[{owners}] {m.doc(field)}")
