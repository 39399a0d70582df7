"""A benchmark's own page of figures: ``docs/benchmarks/<name>.md``, headed by its command and commit.

Every figure in ``docs/benchmarks/`` is written here by the benchmark that measured it; nothing is
copied by hand. A benchmark builds a :class:`Page` as it measures, adds prose, tables and figures
to it, and writes it when run with ``--write``::

    from page import Page                      # benchmarks/ is on sys.path when a benchmark runs
    page = Page("bench_sslpv", "SSLPV stage timings on this machine's OpenGL")
    page.para("One light, 256 x 256 ...")
    page.table(["config", "RSM [ms]"], [["32^3, 8 steps", "12.6"]])
    page.write()                               # or page.finish(args.write): prints, and writes if asked

or, for a benchmark whose figures are its fixed-width printout, ``with page.capture(): ...``
(stdout goes to the terminal and, as one preformatted block, to the page).

The header states what a reader needs to judge the figures (:func:`header`):

* the command exactly as run (``python benchmarks/<script> <arguments>``);
* the commit, and ``(with uncommitted changes)`` when the tree differed from it outside
  ``docs/`` (a page's own output is not a change); a committed page must not say so
  (``tests/test_benchmark_pages.py``): commit the code, then run the benchmark;
* the UTC date, the machine (cores, CPU model, and the GPU where ``nvidia-smi`` names one), the
  load average when the page was begun and when it was written (a timing taken beside other work
  is visibly so), and the GL renderer when the benchmark set :attr:`Page.gl_renderer`.

``python benchmarks/page.py`` rewrites the index ``docs/benchmarks.md`` from the pages' headers
(:func:`write_index`); :meth:`Page.write` does it too. The index also lists the benchmarks that
write a page of their own elsewhere in ``docs/`` (:data:`OTHER_PAGES`) and every script of
``benchmarks/`` that has no page yet, with the command that would write it.

Limits: a page records one run. Timings on a shared machine are only as good as the load average
beside them says; ratios measured in one run are the figures to quote.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import shlex
import subprocess
import sys
from datetime import datetime, timezone
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGES = ROOT / "docs" / "benchmarks"
INDEX = ROOT / "docs" / "benchmarks.md"

#: The first line of every page: what the index and the page test recognise.
MARK = "<!-- written by a benchmark (benchmarks/page.py); re-run its command to change it -->"
#: The header's line of provenance, parsed back by :func:`read_header`.
_PROVENANCE = re.compile(r"^Written by `(?P<command>[^`]+)` at commit `(?P<commit>[0-9a-f]{7,40})`"
                         r"(?P<dirty> \(with uncommitted changes\))? on (?P<date>\d{4}-\d\d-\d\d \d\d:\d\d UTC)")

#: Benchmarks that write a page of their own outside ``docs/benchmarks/``: (page, script).
OTHER_PAGES = (("docs/main_job.md", "bench_nightly.py"), ("docs/reference_cost.md", "bench_reference_cost.py"),
               ("docs/reference_pilot.md", "bench_reference_cost.py"))
#: Files of ``benchmarks/`` that are not benchmarks.
NOT_BENCHMARKS = ("page.py",
                  "reseeded_references.py",       # renders references for accuracy_sensitivity.py; prints no figure
                  "single_refs.py")               # renders tests/data/single/ for the S1 tests; prints no figure


def _shown(path):
    """``path`` relative to the repository where it lies inside it."""
    try:
        return str(Path(path).resolve().relative_to(ROOT))
    except ValueError:
        return str(path)


def _git(*args):
    out = subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=False)
    return out.stdout.strip() if out.returncode == 0 else ""


#: A copy of the tree without its ``.git`` (a machine the checkout is sent to) names the commit it was copied
#: from here: ``<commit>`` after its caller checked every tracked file's blob hash against that commit's.
COPIED_COMMIT = "HARNESS_COPIED_COMMIT"


def commit_state():
    """``(short commit, dirty)``: dirty when a tracked or new file outside ``docs/`` differs from HEAD.

    Outside a git checkout, the commit named by :data:`COPIED_COMMIT` (clean, as its caller checked), else
    ``unknown``."""
    head = _git("rev-parse", "--short=10", "HEAD")
    if not head:
        return (os.environ.get(COPIED_COMMIT) or "unknown")[:10], False
    changes = _git("status", "--porcelain", "--untracked-files=normal", "--", ".", ":!docs")
    return head, bool(changes)


def _gpu():
    """The GPUs ``nvidia-smi`` names (", "-joined), or "" where there is none."""
    try:
        out = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"], capture_output=True,
                             text=True, check=False, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return ""
    return ", ".join(s.strip() for s in out.stdout.splitlines() if s.strip()) if out.returncode == 0 else ""


def _cpu_model():
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "unknown CPU"


def _load():
    try:
        return "/".join(f"{x:.1f}" for x in os.getloadavg())
    except OSError:
        return "?"


def command_line(argv=None):
    """The command as a reader would type it: ``python benchmarks/<script> <args>`` (without ``--write``)."""
    argv = [a for a in (sys.argv if argv is None else argv) if a != "--write"]
    script = Path(argv[0])
    try:
        script = script.resolve().relative_to(ROOT)
    except ValueError:
        script = Path("benchmarks") / script.name
    return " ".join(["python", str(script), *(shlex.quote(a) for a in argv[1:])])


class Page:
    """One benchmark's page, built as it measures; ``print`` echoes every block to stdout."""

    def __init__(self, name, title, argv=None, echo=True):
        if not re.fullmatch(r"[a-z0-9_]+", name):
            raise ValueError(f"page name {name!r}: lower case, digits and _ only")
        self.name, self.title, self.echo = name, title, echo
        self.command = command_line(argv)
        self.load_start = _load()
        self.gl_renderer = None
        self.blocks = []

    def _add(self, text):
        self.blocks.append(text)
        if self.echo:
            print(text + "\n", flush=True)

    def para(self, text):
        """A paragraph (or any markdown block) as given."""
        self._add(text.strip())

    def heading(self, text):
        self._add(f"## {text}")

    def bullets(self, items):
        self._add("\n".join(f"* {item}" for item in items))

    def table(self, header, rows, note=None):
        """A markdown table; cells are written with ``str``: format numbers before passing them."""
        lines = ["| " + " | ".join(map(str, header)) + " |", "|" + "---|" * len(header)]
        for row in rows:
            if len(row) != len(header):
                raise ValueError(f"table row {row!r}: {len(row)} cells for {len(header)} columns")
            lines.append("| " + " | ".join(str(c).replace("|", "\\|") for c in row) + " |")
        self._add("\n".join(lines) + (f"\n\n{note.strip()}" if note else ""))

    def code(self, text):
        """A preformatted block (a benchmark's own fixed-width printout)."""
        self._add("```\n" + text.rstrip("\n") + "\n```")

    @contextlib.contextmanager
    def capture(self, markdown=False):
        """Everything printed to stdout inside the block goes to the terminal and, as one
        preformatted block, to the page: for a benchmark whose figures are its printout
        (``markdown``: the printout is markdown already and goes in as it is)."""
        buf = io.StringIO()

        class _Tee(io.TextIOBase):
            def write(self, s):
                buf.write(s)
                return sys.__stdout__.write(s)

            def flush(self):
                sys.__stdout__.flush()

        old, sys.stdout = sys.stdout, _Tee()
        try:
            yield
        finally:
            sys.stdout = old
        text = buf.getvalue().strip("\n")
        if text.strip():
            self.blocks.append(text if markdown else "```\n" + text + "\n```")

    def figure(self, path, alt):
        """An image already written under ``docs/``; linked relative to the page."""
        rel = os.path.relpath(Path(path).resolve(), PAGES)
        self._add(f"![{alt}]({rel})")

    def text(self):
        commit, dirty = commit_state()
        now = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
        gpu = _gpu()
        machine = f"{os.cpu_count()} cores ({_cpu_model()})" + (f", GPU {gpu}" if gpu else "")
        gl = f"; OpenGL: {self.gl_renderer}" if self.gl_renderer else ""
        head = [MARK, f"# {self.title}", "",
                f"Written by `{self.command}` at commit `{commit}`{' (with uncommitted changes)' if dirty else ''} "
                f"on {now}; {machine}, load average {self.load_start} when begun and {_load()} when written{gl}.",
                ""]
        return "\n".join(head) + "\n" + "\n\n".join(self.blocks) + "\n"

    def write(self):
        """Write ``docs/benchmarks/<name>.md`` (whole or not at all) and the index."""
        PAGES.mkdir(parents=True, exist_ok=True)
        path = PAGES / f"{self.name}.md"
        tmp = path.with_name(f".{path.name}.tmp")
        tmp.write_text(self.text())
        os.replace(tmp, path)
        write_index()
        print(f"wrote {_shown(path)}", file=sys.stderr)
        return path

    def finish(self, write):
        """Write the page when ``write`` (a benchmark's ``--write``); the blocks were printed already."""
        return self.write() if write else None


def named_by(base, option):
    """A page name that follows an option of the command: ``named_by("x", "--outside")`` names the run
    ``x`` by default and ``x_absorb`` under ``--outside absorb`` (one page per value)."""
    def name(argv):
        return base + (f"_{argv[argv.index(option) + 1]}" if option in argv[:-1] else "")
    return name


def run(main, name, title, markdown=False):
    """Run a benchmark's ``main()`` with its printout captured on the page ``name``.

    For the benchmarks whose figures are what they print: ``raise SystemExit(run(main, NAME, TITLE))``
    in place of ``main()``. ``--write`` (taken off the arguments before ``main`` parses them) writes
    the page; the page is written only when ``main`` returns 0 or None, so a failed run leaves the
    committed page as it was (and says so, except after bad input, exit 2, whose one line is the
    benchmark's own). The command on the page is the one run, without ``--write``.
    ``name`` and ``title`` may be functions of the arguments (a benchmark in parts: one page per part).
    """
    argv = list(sys.argv)
    write = "--write" in argv[1:]
    sys.argv = [a for a in argv if a != "--write"]
    name = name(sys.argv[1:]) if callable(name) else name
    title = title(sys.argv[1:]) if callable(title) else title
    if any(a in ("-h", "--help") for a in argv[1:]):
        print(f"--write: also write docs/benchmarks/{name}.md (benchmarks/page.py)\n")
        return main()
    page = Page(name, title, argv=sys.argv, echo=False)
    with page.capture(markdown=markdown):
        status = main()
    if status not in (None, 0):
        if status != 2:     # exit 2 is bad input, which the benchmark has said in its one line
            print(f"{name}: exit {status}; page not written", file=sys.stderr)
        return status
    page.finish(write)
    return 0


def read_header(path):
    """``{title, command, commit, dirty, date}`` of a page written here, or None when it is not one."""
    lines = Path(path).read_text().splitlines()
    if not lines or lines[0] != MARK:
        return None
    title = lines[1][2:] if len(lines) > 1 and lines[1].startswith("# ") else ""
    for line in lines[2:6]:
        m = _PROVENANCE.match(line)
        if m:
            return {"title": title, "command": m["command"], "commit": m["commit"], "dirty": bool(m["dirty"]),
                    "date": m["date"]}
    return None


def _first_heading(path):
    for line in Path(path).read_text().splitlines():
        if line.startswith("# "):
            return line[2:]
    return path.name


def index_text():
    """The index of ``docs/benchmarks.md``, from the pages' headers and the scripts of ``benchmarks/``."""
    rows, written = [], set()
    for path in sorted(PAGES.glob("*.md")):
        h = read_header(path)
        if h is None:
            raise ValueError(f"{_shown(path)}: not a page written by benchmarks/page.py (first line)")
        rows.append(f"| [{h['title']}](benchmarks/{path.name}) | `{h['command']}` | `{h['commit']}`"
                    f"{' (uncommitted changes)' if h['dirty'] else ''} | {h['date']} |")
        written.add(h["command"].split()[1].split("/")[-1])
    other = []
    for page, script in OTHER_PAGES:
        other.append(f"| [{_first_heading(ROOT / page)}]({Path(page).name}) | `benchmarks/{script}` |")
        written.add(script)
    scripts = sorted(p.name for p in (ROOT / "benchmarks").glob("*.py") if p.name not in NOT_BENCHMARKS)
    missing = [s for s in scripts if s not in written]
    out = ["# Benchmarks and their figures", "",
           "Each page below is written by the benchmark that measured it, headed by the command, the commit, the "
           "machine and its load (`benchmarks/page.py`); nothing is copied in by hand. Re-run a page's command with "
           "`--write` to check or renew it. The accuracy map is `docs/results.md` (`sslpv-harness study --docs`); "
           "the main job's times are `docs/main_job.md`. This index is written by `python benchmarks/page.py`.", "",
           "| page | command | commit | written |", "|---|---|---|---|", *rows, "",
           "Benchmarks that write a page of their own elsewhere in `docs/`:", "",
           "| page | benchmark |", "|---|---|", *other]
    if missing:
        out += ["", "Benchmarks without a page yet (run with `--write` to make one): "
                + ", ".join(f"`{s}`" for s in missing) + "."]
    return "\n".join(out) + "\n"


def write_index():
    tmp = INDEX.with_name(f".{INDEX.name}.tmp")
    tmp.write_text(index_text())
    os.replace(tmp, INDEX)


if __name__ == "__main__":
    write_index()
    print(f"wrote {_shown(INDEX)}")
