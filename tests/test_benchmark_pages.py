"""The benchmarks' pages are written by the benchmarks, and the index says so (``benchmarks/page.py``).

* ``docs/benchmarks.md`` is exactly what ``python benchmarks/page.py`` writes from the pages today;
* every page of ``docs/benchmarks/`` has the header only :class:`page.Page` writes (first line,
  command, commit, date), names a script that exists, and was written from a clean tree: a
  page that says "with uncommitted changes" is not committed;
* every script of ``benchmarks/`` writes a page (it uses ``page``), or writes its own elsewhere in
  ``docs/`` (``page.OTHER_PAGES``), or is declared not a benchmark (``page.NOT_BENCHMARKS``);
* :func:`page.run` writes nothing without ``--write`` or when the benchmark fails, and writes the
  command it ran.
"""

import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _page_module():
    spec = importlib.util.spec_from_file_location("bench_page", ROOT / "benchmarks" / "page.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


page = _page_module()


def committed_page_problems(path):
    """Why a page may not be committed as it is (empty when it may)."""
    h = page.read_header(path)
    if h is None:
        return [f"{path.name}: no header written by benchmarks/page.py"]
    out = []
    if h["dirty"]:
        out.append(f"{path.name}: written with uncommitted changes; commit the code, then run the benchmark")
    script = h["command"].split()[1] if len(h["command"].split()) > 1 else ""
    if not (ROOT / script).is_file():
        out.append(f"{path.name}: its command runs {script!r}, which does not exist")
    return out


def test_the_index_is_what_page_py_writes():
    assert (ROOT / "docs" / "benchmarks.md").read_text() == page.index_text(), \
        "docs/benchmarks.md is stale: run `python benchmarks/page.py`"


def test_every_committed_page_is_a_benchmarks_own():
    pages = sorted((ROOT / "docs" / "benchmarks").glob("*.md"))
    problems = [p for path in pages for p in committed_page_problems(path)]
    assert not problems, problems


def test_every_benchmark_writes_a_page():
    elsewhere = {script for _, script in page.OTHER_PAGES}
    silent = [p.name for p in sorted((ROOT / "benchmarks").glob("*.py"))
              if p.name not in page.NOT_BENCHMARKS and p.name not in elsewhere
              and "from page import" not in p.read_text()]
    assert not silent, f"benchmarks that write no page: {silent}"


@pytest.fixture
def pages_in(tmp_path, monkeypatch):
    monkeypatch.setattr(page, "PAGES", tmp_path / "benchmarks")
    monkeypatch.setattr(page, "INDEX", tmp_path / "benchmarks.md")
    return tmp_path


def test_a_hand_typed_page_is_refused(pages_in):
    """Power: a page without the writer's header stops the index, and fails the committed-page check."""
    (pages_in / "benchmarks").mkdir()
    typed = pages_in / "benchmarks" / "typed.md"
    typed.write_text("# Figures\n\nWritten by `python benchmarks/dipole_plane.py` at commit `abc1234` on "
                     "2026-12-01 10:00 UTC; typed.\n\n| a | b |\n|---|---|\n| 1 | 2 |\n")
    with pytest.raises(ValueError, match="not a page written by benchmarks/page.py"):
        page.index_text()
    assert committed_page_problems(typed)


def test_a_page_from_a_dirty_tree_is_refused(pages_in, monkeypatch):
    """Power: the header's "(with uncommitted changes)" fails the committed-page check."""
    monkeypatch.setattr(page, "_git", lambda *a: "" if a[0] == "status" else "abc1234567")
    p = page.Page("bench_sslpv", "T", argv=["benchmarks/bench_sslpv.py"], echo=False)
    p.para("x")
    text = p.text()
    line = next(x for x in text.splitlines() if x.startswith("Written by"))
    dirty = line.replace("` on ", "` (with uncommitted changes) on ", 1) if "uncommitted" not in line else line
    path = pages_in / "dirty.md"
    path.write_text(text.replace(line, dirty))
    assert page.read_header(path)["dirty"]
    assert any("uncommitted" in why for why in committed_page_problems(path))


def test_uncommitted_changes_outside_docs_are_stated(monkeypatch):
    """The header says "(with uncommitted changes)" exactly when git reports a change outside docs/."""
    calls = []

    def fake_git(*args, status=""):
        calls.append(args)
        return status if args[0] == "status" else "abc1234567"

    monkeypatch.setattr(page, "_git", lambda *a: fake_git(*a, status=" M harness/scene/model.py"))
    p = page.Page("toy", "Toy", argv=["benchmarks/toy.py"], echo=False)
    assert page.commit_state() == ("abc1234567", True) and "(with uncommitted changes)" in p.text()
    assert ":!docs" in next(c for c in calls if c[0] == "status")
    monkeypatch.setattr(page, "_git", lambda *a: fake_git(*a, status=""))
    assert page.commit_state() == ("abc1234567", False) and "uncommitted" not in p.text()


def test_a_copied_tree_names_its_commit_only_through_the_variable(monkeypatch):
    """Outside a git checkout (a copy of the tree sent to another machine) the commit is HARNESS_COPIED_COMMIT's,
    "unknown" without it; inside one the variable is ignored. The GPU's name joins the machine where nvidia-smi
    names one."""
    monkeypatch.setattr(page, "_git", lambda *a: "")
    monkeypatch.delenv(page.COPIED_COMMIT, raising=False)
    assert page.commit_state() == ("unknown", False)
    monkeypatch.setenv(page.COPIED_COMMIT, "0123456789abcdef")
    assert page.commit_state() == ("0123456789", False)
    monkeypatch.setattr(page, "_git", lambda *a: "" if a[0] == "status" else "abc1234567")
    assert page.commit_state() == ("abc1234567", False)
    monkeypatch.setattr(page, "_gpu", lambda: "NVIDIA H200")
    assert ", GPU NVIDIA H200," in page.Page("toy", "Toy", argv=["benchmarks/toy.py"], echo=False).text()


def _toy(status, printed="| a |\n|---|\n| 1.5 |"):
    def main():
        print(printed)
        return status
    return main


def test_run_writes_only_with_write_and_on_success(pages_in, monkeypatch, capsys):
    monkeypatch.setattr(page, "OTHER_PAGES", ())
    monkeypatch.setattr(page, "_git", lambda *a: "" if a[0] == "status" else "abc1234567")
    monkeypatch.setattr(sys, "argv", [str(ROOT / "benchmarks" / "toy.py"), "--n", "3"])
    assert page.run(_toy(0), "toy", "Toy") == 0
    assert not (pages_in / "benchmarks").exists()                    # no --write: nothing written
    monkeypatch.setattr(sys, "argv", [str(ROOT / "benchmarks" / "toy.py"), "--write", "--n", "3"])
    assert page.run(_toy(1), "toy", "Toy") == 1
    assert not (pages_in / "benchmarks").exists()                    # a failed run: nothing written
    assert "toy: exit 1; page not written" in capsys.readouterr().err
    assert page.run(_toy(2), "toy", "Toy") == 2                      # bad input: the benchmark's one line only
    assert not (pages_in / "benchmarks").exists() and capsys.readouterr().err == ""
    monkeypatch.setattr(sys, "argv", [str(ROOT / "benchmarks" / "toy.py"), "--write", "--n", "3"])
    assert page.run(_toy(None), "toy", "Toy", markdown=True) == 0
    written = pages_in / "benchmarks" / "toy.md"
    h = page.read_header(written)
    assert h["command"] == "python benchmarks/toy.py --n 3" and h["title"] == "Toy"
    assert "| 1.5 |" in written.read_text()
    assert "[Toy](benchmarks/toy.md)" in (pages_in / "benchmarks.md").read_text()


@pytest.mark.gl
def test_bench_sslpv_gpu_refuses_a_software_renderer(gl_renderer):
    """``bench_sslpv.py --gpu`` on llvmpipe: the error line names the setting and the renderer, exit 2, and no page
    is written (on another driver it may run, so the test is skipped there)."""
    import subprocess

    if "llvmpipe" not in gl_renderer.gl_renderer.lower():    # named here, not read from the benchmark's list
        pytest.skip(f"not llvmpipe ({gl_renderer.gl_renderer}): --gpu may run the benchmark")
    before = (ROOT / "docs" / "benchmarks" / "bench_sslpv_gpu.md").read_bytes()
    out = subprocess.run([sys.executable, "benchmarks/bench_sslpv.py", "--gpu", "--write"], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 2
    assert out.stderr.splitlines()[0].startswith("error: --gpu: GL_RENDERER: ")
    assert "is a software renderer" in out.stderr and out.stdout == ""
    assert (ROOT / "docs" / "benchmarks" / "bench_sslpv_gpu.md").read_bytes() == before


def test_mnee_chains_runs_write_distinct_pages(monkeypatch):
    """``mnee_chains.py``'s three kinds of run (the eta -> 1 printout by its scenes, the area-light limit,
    ``--decompose`` over a scene set) write different pages; ``--decompose`` writes its own page, not the
    printout's."""
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    spec = importlib.util.spec_from_file_location("bench_mnee_chains", ROOT / "benchmarks" / "mnee_chains.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    decompose = [mod.page_name(mod.SMOOTH_SCENES), mod.page_name(["bunny_dielectric"])]
    printouts = [mod.printout_page([]), mod.printout_page(["--area-limit", "0.25"]),
                 mod.printout_page(["--scene", "torus_hole", "bunny_dielectric", "--size", "32"])]
    assert mod.printout_page(["--decompose", "--scenes", "bunny_dielectric"]) is None
    assert printouts[0] == "mnee_chains_eta_one"
    assert printouts[2] == "mnee_chains_eta_one_torus_hole_bunny_dielectric"
    assert decompose == ["mnee_chains", "mnee_chains_bunny_dielectric"]
    assert len(set(decompose + printouts)) == 5


def test_calibration_pages_are_named_after_their_extensions(monkeypatch):
    """``calibration_table.py`` names one page per committed calibration: every folder's page name differs, and a
    setting that is not the family's own (outside, phase scaling, R_dr, the exitance read, the injection's and the
    shading's depths, the trilinear lookup) is in the name."""
    import json
    import tomllib

    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    mods = {}
    for name in ("calibration_table", "calibration_form"):
        spec = importlib.util.spec_from_file_location(f"bench_{name}", ROOT / "benchmarks" / f"{name}.py")
        mods[name] = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mods[name])
    names = {}
    for folder in sorted((ROOT / "baselines" / "calibrated").iterdir()):
        if folder.name == "best":
            continue                                    # the selection: the winner's own page
        kind = "calibration_form" if "form" in tomllib.loads((folder / "calibrated.toml").read_text()) \
            else "calibration_table"
        names[folder.name] = mods[kind].page_name(json.loads((folder / "calibration.json").read_text()))[0]
    assert len(set(names.values())) == len(names), names
    expected = {                                        # the page each folder's settings name
        "diffusion_exitance": "calibration_diffusion_extrapolated_boundary",
        "collision_extrapolated": "calibration_collision_extrapolated",
        "collision_loss_form": "calibration_form_collision_loss",
        "collision_extrapolated_loss_form": "calibration_form_collision_extrapolated_loss",
        "collision_interior_shade": "calibration_collision_interior_depth1_shade1",
        "collision_interior_shade15": "calibration_collision_interior_depth1_shade1p5",
        "collision_interior_shade_trilinear": "calibration_collision_interior_depth1_shade1_trilinear",
        "collision_interior_shade_trilinear_loss_form": "calibration_form_collision_interior_depth1_shade1_trilinear_loss",
        "collision_interior_shade_trilinear_radiance_form": "calibration_form_collision_interior_depth1_shade1_trilinear_radiance",
        "collision_interior_shade05_trilinear": "calibration_collision_interior_depth1_shade0p5_trilinear",
        "collision_interior_shade05_trilinear_loss_form": "calibration_form_collision_interior_depth1_shade0p5_trilinear_loss",
        "collision_interior_shade_trilinear_n64": "calibration_collision_interior_depth1_shade1_trilinear_n64",
        "collision_interior_depth05_shade_trilinear": "calibration_collision_interior_depth0p5_shade1_trilinear",
        "collision_interior_depth05_shade_trilinear_loss_form": "calibration_form_collision_interior_depth0p5_shade1_trilinear_loss",
        "collision_interior_depth05_shade_trilinear_radiance_form": "calibration_form_collision_interior_depth0p5_shade1_trilinear_radiance",
        "collision_interior_depth05_shade_trilinear_n64": "calibration_collision_interior_depth0p5_shade1_trilinear_n64",
    }
    assert {k: names.get(k) for k in expected} == expected
    for page in names.values():                         # every committed calibration's page is committed
        if page != "calibration_collision_n16" and page != "calibration_diffusion_n16":
            assert (ROOT / "docs" / "benchmarks" / f"{page}.md").is_file(), page
