"""Write-then-rename, so that an interrupted or failed write never leaves a
half-written result under the final name.

Temporary names come from :func:`harness.io.outputs.temp_name`, and every write first
removes the temporaries that a killed earlier run left for the same output
(:func:`harness.io.outputs.remove_leftovers`), never anyone else's.
"""

import contextlib
import os
import shutil
from pathlib import Path

from harness.io.outputs import MARKER, check_replaceable, remove_leftovers, temp_name

__all__ = ["atomic_write", "atomic_dir", "MARKER"]

#: The folder rule's old name (``harness.calibration`` checks its ``--out`` with it).
_check_replaceable = check_replaceable


@contextlib.contextmanager
def atomic_write(path):
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_leftovers(path)
    tmp = Path(f"{temp_name(path)}{path.suffix or '.tmp'}")  # writers that go by the extension
    tmp.touch()
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


@contextlib.contextmanager
def atomic_dir(path):
    """Yield a temporary folder beside ``path``; it replaces ``path`` on success.

    ``path`` must be new, empty, or a folder this function wrote before. The old
    folder is moved aside before the new one is renamed in, so at every moment
    ``path`` is either the complete old output or the complete new one.
    """
    path = Path(path)
    check_replaceable(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_leftovers(path)
    tmp = temp_name(path)
    tmp.mkdir()
    old = None
    try:
        yield tmp
        (tmp / MARKER).write_text("written by sslpv-harness; this folder is replaced as a whole\n")
        if path.exists():
            old = temp_name(path, "old")
            old.mkdir()
            os.replace(path, old / path.name)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
