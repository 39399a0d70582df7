"""The main job as a newcomer meets it: a fresh clone, three nights, timed; writes ``docs/main_job.md``.

    python benchmarks/bench_nightly.py [--repo .] [--out docs/main_job.md] [--keep DIR]

1. ``git clone`` the repository's committed HEAD into a temporary folder (nothing of this
   checkout travels: no ``.venv``, no ``cache/``, no reports).
2. **First night:** ``time bash scripts/nightly.sh --json`` there: setup (the virtual
   environment is created and installed), the whole standard matrix, the verdict against
   the committed baselines, the report.
3. **Second night**, nothing changed: the same command the next day.
4. **A shader edited:** one constant of ``sslpv_gl/shaders/shade.frag`` (the subsurface
   output times 1.01), the night after: which configurations are rendered again (the
   result cache's exact invalidation) and what the verdict says of them.

Each night's wall time (the command's, setup included), exit status, verdict, and the
configurations rendered and reused (``night.json``) go into a Markdown table, headed by
the command and the commit. Nothing here is typed by hand.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from datetime import date, timedelta
from pathlib import Path

EDIT = ("sslpv_gl/shaders/shade.frag", "out_sub  = vec4(sub, 1.0);", "out_sub  = vec4(sub * 1.01, 1.0);")


def _night(clone, day, log):
    t0, t0_wall = time.perf_counter(), time.time()
    with open(log, "w") as err:
        proc = subprocess.run(["bash", "scripts/nightly.sh", "--json", "--date", day], cwd=clone, text=True,
                              stdout=subprocess.PIPE, stderr=err)
    wall = time.perf_counter() - t0
    try:
        result = json.loads(proc.stdout.strip().splitlines()[-1])
    except (IndexError, ValueError):
        result = {}
    info = {}
    night_json = clone / "reports" / "nightly" / day / "night.json"
    if night_json.is_file():
        info = json.loads(night_json.read_text())
    return {"date": day, "wall_s": wall, "exit": proc.returncode, "verdict": result.get("verdict"),
            "phases": _phases(log, t0_wall, wall),
            "configurations": result.get("configurations"), "failed": result.get("failed"),
            "rendered": len(info.get("rendered", [])), "reused": info.get("reused"),
            "regressions": result.get("regressions"), "improvements": result.get("improvements"),
            "changed_images": result.get("changed_images"), "rendered_methods": info.get("rendered_methods", {}),
            "rendered_list": info.get("rendered", [])}


def _phases(log, t0, wall):
    """Where a night's time went, from its log's timestamped lines: setup (until the nightly's first line),
    the references and the sweep (until "sweep finished"), the verdicts, the sweep report, the trends,
    and the rest (the night's page, the index, the process's exit)."""
    import re
    from datetime import datetime, timezone

    stamps, secs = {}, {}
    for line in Path(log).read_text().splitlines():
        m = re.match(r"(\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ) (.*)", line)
        if not m:
            continue
        t = datetime.strptime(m.group(1), "%Y-%m-%dT%H:%M:%SZ").replace(tzinfo=timezone.utc).timestamp() - t0
        msg = m.group(2)
        if msg.startswith("nightly:"):
            stamps.setdefault("start", t)
        if "sweep finished" in msg:
            stamps["swept"] = t
        if (v := re.search(r"image comparisons in ([\d.]+) s", msg)):
            secs["verdicts"] = float(v.group(1))
        if (v := re.search(r"the sweep report in ([\d.]+) s; (\d+) trend figures in ([\d.]+) s", msg)):
            secs["report"], secs["trends"] = float(v.group(1)), float(v.group(3))
    if "start" not in stamps or "swept" not in stamps:
        return {}
    out = {"setup": stamps["start"], "sweep": stamps["swept"] - stamps["start"], **secs}
    out["rest"] = wall - sum(out.values())
    return out


def _fmt_s(s):
    return f"{int(s // 60)} min {s % 60:04.1f} s"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repo", type=Path, default=Path(__file__).resolve().parent.parent)
    ap.add_argument("--out", type=Path, default=None, help="Markdown file to write (default: docs/main_job.md)")
    ap.add_argument("--keep", type=Path, default=None, help="clone here and keep it (default: a temporary folder)")
    args = ap.parse_args(argv)
    repo = args.repo.resolve()
    out = args.out or repo / "docs" / "main_job.md"
    commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=repo, capture_output=True, text=True,
                            check=True).stdout.strip()
    root = args.keep or Path(tempfile.mkdtemp(prefix="bench_nightly_"))
    clone = root / "clone"
    if clone.exists():
        print(f"error: {clone}: clone: exists; give an empty --keep folder", file=sys.stderr)
        return 2
    subprocess.run(["git", "clone", "-q", str(repo), str(clone)], check=True)
    first = date.today()
    nights = []
    nights.append(_night(clone, first.isoformat(), root / "night1.log"))
    print(json.dumps({k: v for k, v in nights[-1].items() if k != "rendered_list"}), file=sys.stderr)
    nights.append(_night(clone, (first + timedelta(days=1)).isoformat(), root / "night2.log"))
    print(json.dumps({k: v for k, v in nights[-1].items() if k != "rendered_list"}), file=sys.stderr)
    path, old, new = EDIT
    f = clone / path
    text = f.read_text()
    assert text.count(old) == 1, f"{path}: the line to edit is gone; update EDIT"
    f.write_text(text.replace(old, new))
    nights.append(_night(clone, (first + timedelta(days=2)).isoformat(), root / "night3.log"))
    print(json.dumps({k: v for k, v in nights[-1].items() if k != "rendered_list"}), file=sys.stderr)

    names = ("first night (fresh clone, setup included)", "second night (nothing changed)",
             f"after editing one line of `{path}`")
    lines = [
        "# The main job, measured",
        "",
        f"Written by `python benchmarks/bench_nightly.py` at commit `{commit[:12]}` on a "
        f"{_cpus()}-core machine without a GPU (llvmpipe). Each night is `bash scripts/nightly.sh --json "
        "--date D` in a fresh `git clone` of that commit, timed from the outside (setup included).",
        "",
        "| night | wall time | exit | verdict | configurations | rendered | reused | failed |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, n in zip(names, nights):
        lines.append(f"| {name} | {_fmt_s(n['wall_s'])} | {n['exit']} | {n['verdict']} | {n['configurations']} | "
                     f"{n['rendered']} | {n['reused']} | {n['failed']} |")
    lines += ["", "Where the time went (from each night's log; whole seconds for the phases the log stamps):", "",
              "| night | setup | references and sweep | verdicts | sweep report | trend figures | the rest |",
              "|---|---|---|---|---|---|---|"]
    for name, n in zip(names, nights):
        ph = n["phases"]
        cells = [f"{ph[k]:.1f} s" if k in ph else "—" for k in ("setup", "sweep", "verdicts", "report", "trends",
                                                                  "rest")]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    third = nights[2]
    lines += ["", f"After the edit (`{old}` → `{new}`) the night rendered "
              + ", ".join(f"{v} configurations of {k}" for k, v in sorted(third["rendered_methods"].items()))
              + f" and reused the rest; its verdict: {third['verdict']} ({third['regressions']} regressions, "
              f"{third['improvements']} improvements, {third['changed_images']} changed images).", ""]
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}", file=sys.stderr)
    if args.keep is None:
        shutil.rmtree(root, ignore_errors=True)
    return 0


def _cpus():
    import os

    return os.cpu_count() or 1


if __name__ == "__main__":
    sys.exit(main())
