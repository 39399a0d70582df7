"""Atomic outputs: a failed write leaves nothing, and a user's folder is never replaced."""

import pytest

from harness.io.atomic import MARKER, atomic_dir, atomic_write
from harness.errors import InputError


def test_failed_write_leaves_nothing(tmp_path):
    with pytest.raises(RuntimeError):
        with atomic_write(tmp_path / "a.json") as tmp:
            tmp.write_text("half")
            raise RuntimeError("crash")
    assert list(tmp_path.iterdir()) == []


def test_failed_folder_keeps_the_old_one(tmp_path):
    out = tmp_path / "out"
    with atomic_dir(out) as tmp:
        (tmp / "x.exr").write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_dir(out) as tmp:
            (tmp / "x.exr").write_text("new")
            raise RuntimeError("crash")
    assert (out / "x.exr").read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_replaces_its_own_output(tmp_path):
    out = tmp_path / "out"
    for text in ("one", "two"):
        with atomic_dir(out) as tmp:
            (tmp / "x.exr").write_text(text)
    assert (out / "x.exr").read_text() == "two" and (out / MARKER).is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_refuses_a_users_folder_and_a_file(tmp_path):
    mine = tmp_path / "Documents"
    mine.mkdir()
    (mine / "notes.txt").write_text("precious")
    with pytest.raises(InputError, match="non-empty folder that the harness did not write"):
        with atomic_dir(mine):
            pass
    assert (mine / "notes.txt").read_text() == "precious"
    (tmp_path / "f").write_text("x")
    with pytest.raises(InputError, match="exists and is not a folder"):
        with atomic_dir(tmp_path / "f"):
            pass
