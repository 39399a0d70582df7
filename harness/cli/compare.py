"""``sslpv-harness compare REF TEST [--mask M | --all-pixels] [--json]``: every metric of one test
EXR against one reference EXR.

Which pixels: those of ``--mask M`` when given; else, when the reference's coverage is
beside it (its ``mask`` layer, or the ``mask.exr`` of a reference folder:
:func:`harness.runs.sweep.reference_coverage`), the fully covered pixels
(:func:`harness.metrics.coverage.comparison_mask`), the same mask as a sweep's, so one
render compared here gives the numbers a sweep records for it; else, or with
``--all-pixels``, every pixel. The result says which rule chose the pixels and how many.

When the reference is a reference render's ``subsurface.exr`` with
``half_a.exr`` and ``half_b.exr`` beside it (see ``docs/conventions.md``), each
metric also gets its noise floor: the same metric between the two halves.
"""

import io
import json
import math
from pathlib import Path

import numpy as np

from harness.errors import InputError
from harness.io.images import read_exr
from harness.metrics import compare_images
from harness.metrics.coverage import FULL_COVERAGE, comparison_mask

#: Reference file names whose folder's half_a/half_b are halves of that image.
_HALVES_BELONG_TO = ("subsurface.exr",)


def read_mask(path, shape):
    """Read a mask file as a boolean ``(H, W)`` array matching ``shape`` (H, W).

    ``.npy``: a boolean or 0/1 array. ``.png`` and other PIL formats: non-zero
    in any channel is inside. ``.exr``: R > 0.5 is inside.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file", "does not exist", "check the mask path")
    suffix = path.suffix.lower()
    if suffix == ".exr":
        mask = read_exr(path)["rgb"][..., 0] > 0.5
    elif suffix == ".npy":
        try:
            arr = np.load(path, allow_pickle=False)
        except Exception as exc:
            raise InputError(path, "file", f"not a readable .npy array ({exc})",
                             "save it with numpy.save") from exc
        if arr.dtype != bool and not (np.issubdtype(arr.dtype, np.number)
                                      and np.all((arr == 0) | (arr == 1))):
            raise InputError(path, "values", f"dtype {arr.dtype} with values other than 0 and 1",
                             "save a boolean (H, W) array")
        mask = arr.astype(bool)
    else:
        from PIL import Image
        try:
            with Image.open(path) as im:
                arr = np.asarray(im)
        except Exception as exc:
            raise InputError(path, "file", f"not a readable image ({exc})",
                             "give a .png, .npy or .exr mask") from exc
        mask = arr.reshape(arr.shape[0], arr.shape[1], -1).any(axis=-1)
    if mask.ndim != 2 or mask.shape != tuple(shape):
        got = "x".join(str(s) for s in mask.shape[::-1])
        raise InputError(path, "size", f"is {got}, the images are {shape[1]}x{shape[0]}",
                         "make the mask the images' size")
    if not mask.any():
        raise InputError(path, "values", "selects no pixels", "mark the pixels to compare")
    return mask


def _jsonable(v):
    """Plain JSON types: tuples -> lists, non-finite floats -> None."""
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, (np.floating, float)):
        return float(v) if math.isfinite(v) else None
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.bool_):
        return bool(v)
    return v


def run_compare(ref_path, test_path, mask_path=None, as_json=False, all_pixels=False):
    """Compare a test EXR with a reference EXR by every registered metric.

    Parameters
    ----------
    ref_path, test_path : str or Path
        EXR files with R, G, B channels, read with :func:`harness.io.images.read_exr`.
    mask_path : str or Path, optional
        A mask (see :func:`read_mask`). When ``None``: the fully covered pixels of the
        reference's coverage where it has one (as a sweep), else every pixel.
    all_pixels : bool, default False
        Every pixel, even where the reference's coverage is beside it; not with ``mask_path``.
    as_json : bool, default False
        When True the result holds only JSON types (lists, not tuples; NaN as
        None), ready for ``json.dumps``. The numbers are the same either way.

    Returns
    -------
    dict
        ``{"ref": str, "test": str, "mask": str | None, "mask_rule": str,
        "mask_threshold": float | None, "mask_pixels": int, "pixels": int,
        "noise_floor_from": [half_a, half_b] | None, "metrics": {name: {"value",
        "per_channel", "noise_floor", "params", "higher_is_better", "target"}}}``.
        ``mask_rule`` is ``"file"`` (``mask`` is the file), ``"full_coverage"`` (``mask``
        names the coverage, ``mask_threshold`` the coverage a pixel reaches) or
        ``"all_pixels"`` (asked for) or ``"no_coverage"`` (the reference has none beside it;
        ``mask`` is None for both); ``mask_pixels`` of ``pixels`` were compared.

    Raises
    ------
    InputError
        A missing or unreadable file, NaN/Inf values (from ``read_exr``, naming
        the file), or images (or a mask) of different sizes, naming both files.
    """
    ref_path, test_path = Path(ref_path), Path(test_path)
    ref_layers = read_exr(ref_path)
    ref = ref_layers["rgb"]
    test = read_exr(test_path)["rgb"]
    if test.shape != ref.shape:
        raise InputError(test_path, "size", f"is {test.shape[1]}x{test.shape[0]} but the reference "
                         f"{ref_path} is {ref.shape[1]}x{ref.shape[0]}",
                         "render the test at the reference's size")
    mask, rule = _choose_mask(ref_path, ref_layers, mask_path, all_pixels)

    halves = None
    if ref_path.name in _HALVES_BELONG_TO:
        pa, pb = ref_path.with_name("half_a.exr"), ref_path.with_name("half_b.exr")
        if pa.is_file() and pb.is_file():
            halves = (read_exr(pa, expect_shape=ref.shape[:2])["rgb"],
                      read_exr(pb, expect_shape=ref.shape[:2])["rgb"])
            halves_from = [str(pa), str(pb)]
    rows = compare_images(test, ref, mask[0], *(halves or (None, None)))
    result = {
        "ref": str(ref_path),
        "test": str(test_path),
        "mask": mask[1],
        "mask_rule": rule,
        "mask_threshold": FULL_COVERAGE if rule == "full_coverage" else None,
        "mask_pixels": int(ref.shape[0] * ref.shape[1] if mask[0] is None else mask[0].sum()),
        "pixels": int(ref.shape[0] * ref.shape[1]),
        "noise_floor_from": halves_from if halves else None,
        "metrics": {r["metric"]: {k: r[k] for k in ("value", "per_channel", "noise_floor", "params",
                                                     "higher_is_better", "target")}
                    for r in rows},
    }
    if as_json:
        result = _jsonable(result)
        json.dumps(result, allow_nan=False)  # guaranteed serialisable
    return result


def _choose_mask(ref_path, ref_layers, mask_path, all_pixels):
    """``((mask or None, source or None), rule)``: which pixels a comparison uses (see the module)."""
    shape = ref_layers["rgb"].shape[:2]
    if mask_path is not None:
        if all_pixels:
            raise InputError("--all-pixels", "all_pixels", "cannot be combined with --mask",
                             "give one of them")
        return (read_mask(mask_path, shape), str(mask_path)), "file"
    if all_pixels:
        return (None, None), "all_pixels"
    from harness.runs.sweep import reference_coverage

    coverage, source = reference_coverage(ref_path, ref_layers, shape)
    if coverage is None:
        return (None, None), "no_coverage"
    mask = comparison_mask(coverage)
    if not mask.any():
        raise InputError(source, "mask", f"the reference's coverage reaches {FULL_COVERAGE:g} on no pixel",
                         "give --mask M, or --all-pixels")
    return (mask, source), "full_coverage"


def mask_line(result):
    """One line saying which pixels a :func:`run_compare` result used, and how many."""
    n, of = result["mask_pixels"], result["pixels"]
    if result["mask_rule"] == "file":
        return f"mask {result['mask']}: {n} of {of} pixels"
    if result["mask_rule"] == "full_coverage":
        return (f"mask {result['mask']}: coverage >= {result['mask_threshold']:g} (fully covered, as a sweep "
                f"compares): {n} of {of} pixels; --all-pixels for every pixel")
    why = ("--all-pixels" if result["mask_rule"] == "all_pixels"
           else "the reference has no coverage beside it: no mask layer, no mask.exr")
    return f"mask: none, all {of} pixels ({why})"


def _fmt(v):
    if v is None:
        return "-"
    return f"{v:.4g}"


def format_table(result):
    """Render a :func:`run_compare` result as a plain-text table (via ``rich``)."""
    from rich.console import Console
    from rich.table import Table

    table = Table()
    for col, justify in (("metric", "left"), ("value", "right"), ("R", "right"),
                         ("G", "right"), ("B", "right"), ("noise floor", "right"),
                         ("ideal", "right")):
        table.add_column(col, justify=justify)
    for name, m in result["metrics"].items():
        pc = list(m["per_channel"]) if m["per_channel"] is not None else [None] * 3
        ideal = f"{m['target']:g}" + (" (higher better)" if m["higher_is_better"] else "")
        table.add_row(name, _fmt(m["value"]), *(_fmt(v) for v in pc), _fmt(m["noise_floor"]),
                      ideal)
    buf = io.StringIO()
    Console(file=buf, width=110, color_system=None, force_terminal=False).print(table)
    # The heading is printed apart from the table: rich would wrap a long path inside its title.
    lines = [f"ref  {result['ref']}", f"test {result['test']}", mask_line(result),
             "\n".join(line.rstrip() for line in buf.getvalue().rstrip().splitlines())]
    notes = []
    for name, m in result["metrics"].items():
        keys = {"relmse": ("eps",), "smape": ("eps",), "si_relmse": ("eps", "scales"),
                "ssim": ("exposure",), "flip": ("ppd", "startExposure", "stopExposure",
                                                "numExposures", "tonemapper"),
                "ciede2000_mean": ("white",)}.get(name, ())
        shown = ", ".join(f"{k}={_param(m['params'][k])}" for k in keys if k in m["params"])
        if shown:
            notes.append(f"  {name}: {shown}")
    if notes:
        lines.append("parameters:\n" + "\n".join(notes))
    if result.get("noise_floor_from") is None:
        lines.append("noise floor: none (no half_a.exr/half_b.exr beside a subsurface.exr reference)")
    return "\n".join(lines) + "\n"


def _param(v):
    if isinstance(v, (list, tuple)):
        return "(" + ", ".join(_param(x) for x in v) + ")"
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


HELP = "print every metric between two EXR files"


def configure(sp):
    sp.add_argument("ref", type=Path, help="the reference EXR (first: the heading and --json name it first)")
    sp.add_argument("test", type=Path, help="the test EXR, compared with the reference")
    sp.add_argument("--mask", type=Path, help="mask of the pixels to compare (.exr: R > 0.5; .png; .npy) (default: "
                    "the pixels the reference covers fully when its coverage is beside it (its mask layer or "
                    "mask.exr), as a sweep compares, else every pixel)")
    sp.add_argument("--all-pixels", dest="all_pixels", action="store_true",
                    help="compare every pixel, even where the reference's coverage is beside it")


def run(args):
    try:
        result = run_compare(args.ref, args.test, mask_path=args.mask, as_json=args.json,
                             all_pixels=args.all_pixels)
    except InputError:
        raise
    except ValueError as exc:
        # A metric that cannot be computed on these images (smaller than SSIM's window, a black
        # reference, a mask in SSIM's border): the metric's own sentence, as one line.
        raise InputError(args.test, "metrics", str(exc).split(";")[0],
                         "compare larger images, or other pixels (--mask, --all-pixels)") from None
    return result, None if args.json else format_table(result), 0
