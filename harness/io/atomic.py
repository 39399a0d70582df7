"""Write-then-rename, so that an interrupted or failed write never leaves a
half-written result under the final name."""

import contextlib
import os
import shutil
import tempfile
from pathlib import Path


@contextlib.contextmanager
def atomic_write(path):
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix or ".tmp", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


#: Written into every folder :func:`atomic_dir` produces; only such folders (or empty
#: ones) may be replaced, so ``--out ~/Documents`` can never wipe a user's folder.
MARKER = ".sslpv-output"


def _check_replaceable(path):
    from harness.errors import InputError

    if not path.exists():
        return
    if not path.is_dir():
        raise InputError(path, "output", "exists and is not a folder", "choose a new folder name")
    if any(path.iterdir()) and not (path / MARKER).exists():
        raise InputError(path, "output", "is a non-empty folder that the harness did not write",
                         "choose an empty or new folder")


@contextlib.contextmanager
def atomic_dir(path):
    """Yield a temporary folder beside ``path``; it replaces ``path`` on success.

    ``path`` must be new, empty, or a folder this function wrote before. The old
    folder is moved aside before the new one is renamed in, so at every moment
    ``path`` is either the complete old output or the complete new one.
    """
    path = Path(path)
    _check_replaceable(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", dir=path.parent))
    old = None
    try:
        yield tmp
        (tmp / MARKER).write_text("written by sslpv-harness; this folder is replaced as a whole\n")
        if path.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{path.name}.old.", dir=path.parent))
            os.replace(path, old / path.name)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
