"""``sslpv-harness compare REF TEST [--mask M] [--json]``: every metric of one test
EXR against one reference EXR.

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


def run_compare(ref_path, test_path, mask_path=None, as_json=False):
    """Compare a test EXR with a reference EXR by every registered metric.

    Parameters
    ----------
    ref_path, test_path : str or Path
        EXR files with R, G, B channels, read with :func:`harness.io.images.read_exr`.
    mask_path : str or Path, optional
        A mask (see :func:`read_mask`); all pixels when ``None``.
    as_json : bool, default False
        When True the result holds only JSON types (lists, not tuples; NaN as
        None), ready for ``json.dumps``. The numbers are the same either way.

    Returns
    -------
    dict
        ``{"ref": str, "test": str, "mask": str | None, "noise_floor_from":
        [half_a, half_b] | None, "metrics": {name: {"value", "per_channel",
        "noise_floor", "params", "higher_is_better", "target"}}}``.

    Raises
    ------
    InputError
        A missing or unreadable file, NaN/Inf values (from ``read_exr``, naming
        the file), or images (or a mask) of different sizes, naming both files.
    """
    ref_path, test_path = Path(ref_path), Path(test_path)
    ref = read_exr(ref_path)["rgb"]
    test = read_exr(test_path)["rgb"]
    if test.shape != ref.shape:
        raise InputError(test_path, "size", f"is {test.shape[1]}x{test.shape[0]} but the reference "
                         f"{ref_path} is {ref.shape[1]}x{ref.shape[0]}",
                         "render the test at the reference's size")
    mask = None if mask_path is None else read_mask(mask_path, ref.shape[:2])

    halves = None
    if ref_path.name in _HALVES_BELONG_TO:
        pa, pb = ref_path.with_name("half_a.exr"), ref_path.with_name("half_b.exr")
        if pa.is_file() and pb.is_file():
            halves = (read_exr(pa, expect_shape=ref.shape[:2])["rgb"],
                      read_exr(pb, expect_shape=ref.shape[:2])["rgb"])
            halves_from = [str(pa), str(pb)]
    rows = compare_images(test, ref, mask, *(halves or (None, None)))
    result = {
        "ref": str(ref_path),
        "test": str(test_path),
        "mask": None if mask_path is None else str(mask_path),
        "noise_floor_from": halves_from if halves else None,
        "metrics": {r["metric"]: {k: r[k] for k in ("value", "per_channel", "noise_floor", "params",
                                                     "higher_is_better", "target")}
                    for r in rows},
    }
    if as_json:
        result = _jsonable(result)
        json.dumps(result, allow_nan=False)  # guaranteed serialisable
    return result


def _fmt(v):
    if v is None:
        return "-"
    return f"{v:.4g}"


def format_table(result):
    """Render a :func:`run_compare` result as a plain-text table (via ``rich``)."""
    from rich.console import Console
    from rich.table import Table

    title = f"test {result['test']}\nvs ref {result['ref']}"
    if result.get("mask"):
        title += f"\nmask {result['mask']}"
    table = Table(title=title, title_justify="left")
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
    lines = ["\n".join(line.rstrip() for line in buf.getvalue().rstrip().splitlines())]
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
    sp.add_argument("ref", type=Path, help="reference EXR")
    sp.add_argument("test", type=Path, help="test EXR")
    sp.add_argument("--mask", type=Path, help="EXR whose R channel > 0.5 marks the pixels to compare")


def run(args):
    result = run_compare(args.ref, args.test, mask_path=args.mask, as_json=args.json)
    return result, None if args.json else format_table(result), 0
