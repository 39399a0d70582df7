"""How far the best calibration is from what its family can reach: the floors of the committed calibrated families.

Reads every committed floor (``baselines/calibrated/*/floor.json``, written by ``python -m harness.calibration.floor``
from the calibration's own scan; Eqs. L1, L2 of :mod:`harness.calibration.floor`) and the committed selection of the
best calibration (``baselines/calibrated/best/selection.json``), and prints:

* per family and budget: the median over the scenes of each scene at its own best scales per colour channel (L1),
  and with one pair per scene (L2, the calibration's oracle); the least median any calibration of the family can
  reach (:func:`harness.calibration.floor.median_bound`: the scenes whose terms vary on the grid, and those whose
  least lies at the scan's end where the loss had not levelled off, taken as 0), with both kinds of scene named;
* at the grid the selection ranks: the best calibration's held-out median beside its family's floor and the study's
  relMSE limit (:mod:`harness.study.target`: half the lowest held-out median among the selection's scalar
  calibrations), and which part of the gap is the lattice (the floor) and which the calibration (held out against
  the floor);
* per scene, for the best's family at that grid: the floor beside the best's held-out relMSE and energy ratio.

It computes nothing but medians and ratios of the committed figures.

Run: ``.venv/bin/python benchmarks/calibration_floor.py [--write]``
"""

import argparse
import json
import statistics
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CAL = ROOT / "baselines" / "calibrated"


def _g(x):
    return "–" if x is None else f"{x:.3g}"


def _floors():
    out = {}
    for path in sorted(CAL.glob("*/floor.json")):
        out[path.parent.name] = json.loads(path.read_text())
    return out


def _least(b):
    from harness.calibration.floor import median_bound

    return median_bound(b)


def _family_table(floors):
    print("| family | budget | floor, per channel (L1) | floor, one pair (L2) | least any calibration reaches | "
          "scenes whose terms vary | not levelled off at the scan's end |")
    print("|---|---|---|---|---|---|---|")
    for name, f in floors.items():
        for label, b in f["budgets"].items():
            vary = [n for n, r in b["scenes"].items() if not r["uniform"]]
            open_end = [n for n, r in b["scenes"].items() if not all(c.get("settled", True) for c in r["channels"])]
            print(f"| `{name}` | {label} | {_g(b['median'])} | {_g(b['median_scalar'])} | {_g(_least(b))} | "
                  f"{len(vary)} of {len(b['scenes'])} | {', '.join(open_end) or 'none'} |")


def _limit(sel, label):
    """The study's relMSE limit at ``label`` (:mod:`harness.study.target`, T4), or None."""
    from harness.study.target import RELMSE_FACTOR, _baseline

    base = _baseline(sel, label)
    return RELMSE_FACTOR * base[1] if base else None


def _best(floors):
    sel = json.loads((CAL / "best" / "selection.json").read_text())
    win = Path(sel["winner"]).name
    report = json.loads((CAL / win / "calibration.json").read_text())
    sources = [Path(s).name for s in report.get("sources", [])] or [win]
    print(f"\nThe best calibration (`best/selection.json` names `{win}`; its family's floors are those of "
          f"{', '.join(f'`{s}`' for s in sources)}), held out, against its family's floor and the study's relMSE "
          "limit (half the lowest held-out median among the selection's scalar calibrations):\n")
    print("| budget | best, held out | floor, per channel | least any calibration reaches | limit | "
          "held out / floor | limit reachable |")
    print("|---|---|---|---|---|---|---|")
    rows = []
    for label, res in report["results"].items():
        b = next((floors[s]["budgets"][label] for s in sources if s in floors and label in floors[s]["budgets"]), None)
        if b is None:
            continue
        held = statistics.median(v["relmse"] for v in res["held_out"].values())
        limit = _limit(sel, label)
        least = _least(b)
        print(f"| {label} | {_g(held)} | {_g(b['median'])} | {_g(least)} | {_g(limit)} | {_g(held / b['median'])} | "
              f"{'–' if limit is None else ('yes' if least <= limit else '**no**')} |")
        rows.append((label, res, b))
    for label, res, b in rows:
        if not label.startswith(f"N={sel.get('grid', 32)} "):
            continue
        print(f"\n{label}, per scene: the best held out (energy ratio / relMSE) beside the floor (relMSE per channel, "
              "one pair; energy ratio at the former):\n")
        print("| scene | best, held out | floor per channel | floor one pair | energy at the floor | held out / floor |"
              " terms |")
        print("|---|---|---|---|---|---|---|")
        for n, h in sorted(res["held_out"].items(), key=lambda kv: kv[1]["relmse"] / b["scenes"][kv[0]]["relmse"]):
            f = b["scenes"][n]
            print(f"| {n} | {_g(h['energy_ratio'])} / {_g(h['relmse'])} | {_g(f['relmse'])} | "
                  f"{_g(f['scalar']['relmse'])} | {_g(f['energy_ratio'])} | {_g(h['relmse'] / f['relmse'])} | "
                  f"{'uniform' if f['uniform'] else 'vary'} |")


def main(argv=None):
    from page import Page

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", action="store_true", help="write docs/benchmarks/calibration_floor.md")
    args = ap.parse_args(argv)
    floors = _floors()
    if not floors:
        print(f"error: {CAL}: floor.json: none committed; run python -m harness.calibration.floor --from DIR",
              file=sys.stderr)
        return 2
    page = Page("calibration_floor", "How far the best calibration is from what its family can reach")
    page.para("Each scene at its own best `sigma_scale` and `radiance_scale` per colour channel (Eq. L1 of "
              "`harness.calibration.floor`), from the calibration's own scan: no calibration of the family (its mapping "
              "and renderer settings), scalar or a form of the material, does better on a scene whose terms are "
              "uniform on the grid. Floors written by `python -m harness.calibration.floor --from DIR`; each "
              "`floor.json` names its command and GL renderer.")
    with page.capture(markdown=True):
        _family_table(floors)
        _best(floors)
    page.finish(args.write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
