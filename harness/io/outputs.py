"""Where the harness may write: output folders it owns, paths it can write, and its own leftovers.

Three rules, shared by every command that writes:

* **Only our folders.** An output folder must be new, empty, or written by the harness
  before. A folder that :func:`harness.io.atomic.atomic_dir` wrote holds :data:`MARKER`
  and is replaced as a whole; a sweep's folder (store, renders, ``sweep.json``) holds
  :data:`SWEEP_MARKER` and the nightly's reports folder :data:`NIGHTLY_MARKER`; both are
  added to, never replaced. :func:`check_replaceable`, :func:`claim_sweep_folder` and
  :func:`check_nightly_folder` refuse anything else with one line, so ``--out ~/Documents``
  neither wipes nor litters a user's folder.
* **Writable before any work.** :func:`check_writable` finds the nearest existing folder
  of an output path and creates (and at once removes) an unnamed file there, so a
  read-only folder, ``/proc/...`` or a path under a file is refused with one line before
  minutes of rendering, not with a traceback after them.
* **Our leftovers, and only ours.** Temporary names carry :data:`TMP_TAG`, the host and
  the process id (``.report.sslpv-tmp.myhost.4242.x1y2``). :func:`remove_leftovers` deletes
  those of a dead process of this host that were meant for the same output, and leaves
  everything else alone, including the temporaries of a process that is still running.

A sweep folder is also a lock: :func:`claim_sweep_folder` holds an exclusive ``flock`` on
:data:`SWEEP_MARKER` for as long as the sweep runs. A second sweep into the same folder is
refused; the kernel drops the lock when the first process ends, even by ``kill -9``.
"""

import contextlib
import errno
import fcntl
import json
import os
import re
import secrets
import shutil
import socket
import tempfile
import time
from pathlib import Path

from harness.errors import InputError

__all__ = ["MARKER", "SWEEP_MARKER", "NIGHTLY_MARKER", "TMP_TAG", "check_owned_folder", "check_nightly_folder", "check_replaceable", "check_writable", "check_sweep_folder",
           "claim_sweep_folder", "temp_name", "remove_leftovers"]

#: In every folder :func:`harness.io.atomic.atomic_dir` wrote; only such folders (or empty ones) are replaced.
MARKER = ".sslpv-output"
#: In every sweep folder; also the sweep's lock file.
SWEEP_MARKER = ".sslpv-sweep"
#: In the nightly job's reports folder (``reports/nightly``), which it adds to night by night.
NIGHTLY_MARKER = ".sslpv-nightly"
#: In the name of every temporary file or folder the harness makes beside an output.
TMP_TAG = "sslpv-tmp"


def _host():
    return re.sub(r"[^A-Za-z0-9-]", "-", socket.gethostname() or "host")[:40] or "host"


# --------------------------------------------------------------------------- our folders

def check_replaceable(path):
    """Refuse ``path`` unless it is missing, an empty folder, or a folder :data:`MARKER` marks as ours."""
    path = Path(path)
    if not path.exists():
        return
    if not path.is_dir():
        raise InputError(path, "output", "exists and is not a folder", "choose a new folder name")
    if any(path.iterdir()) and not (path / MARKER).exists():
        raise InputError(path, "output", "is a non-empty folder that the harness did not write",
                         "choose an empty or new folder")


def _is_old_sweep_folder(path):
    """A sweep folder written before :data:`SWEEP_MARKER` existed: its ``sweep.json`` is one of ours."""
    try:
        data = json.loads((path / "sweep.json").read_text())
    except (OSError, ValueError):
        return False
    return isinstance(data, dict) and {"scenes", "params", "out"} <= set(data)


def _is_old_nightly_folder(path):
    """A nightly reports folder written before :data:`NIGHTLY_MARKER` existed."""
    return any(path.glob("runs/*/sweep.json")) or any(path.glob("*/night.json"))


def check_owned_folder(path, marker, older=None, what="a sweep's", fix="give --out a new or empty folder"):
    """Refuse ``path`` unless it is new, empty, holds ``marker``, or ``older(path)`` recognises it;
    then check that it can be written."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InputError(path, "output", "exists and is not a folder", "give --out a folder name")
    ours = (path / marker).exists() or (older is not None and path.is_dir() and older(path))
    if path.is_dir() and any(path.iterdir()) and not ours:
        raise InputError(path, "output", f"is a non-empty folder that is not {what} (the harness adds to "
                         "no other folder)", fix)
    check_writable(path, "--out")


def check_sweep_folder(path):
    """Refuse ``path`` as a sweep's output unless it is new, empty, or a sweep's (or not writable)."""
    check_owned_folder(path, SWEEP_MARKER, _is_old_sweep_folder, "a sweep's", "give --out a new or empty "
                       "folder, or the folder of an earlier sweep to resume it")


def check_nightly_folder(path, mark=False):
    """Refuse ``path`` as the nightly reports folder unless it is new, empty, or the nightly's;
    ``mark=True`` then creates and marks it."""
    path = Path(path)
    check_owned_folder(path, NIGHTLY_MARKER, _is_old_nightly_folder, "the nightly's reports folder",
                       "give --out a new or empty folder, or the nightly's reports folder")
    if mark:
        path.mkdir(parents=True, exist_ok=True)
        (path / NIGHTLY_MARKER).touch()


@contextlib.contextmanager
def claim_sweep_folder(path):
    """Hold ``path`` as a sweep's output folder while the block runs; refuse a user's folder or a busy one.

    The folder must be new, empty, or a sweep's (:data:`SWEEP_MARKER`, or an older sweep's
    ``sweep.json``); it is created, marked, and locked with ``flock`` until the block ends.
    Folders it created are removed again if the block wrote nothing into them (bad input).
    """
    path = Path(path)
    check_sweep_folder(path)
    top = path
    while not top.parent.exists():
        top = top.parent
    created = None if path.exists() else top
    path.mkdir(parents=True, exist_ok=True)
    lock_path = path / SWEEP_MARKER
    try:
        fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as exc:
        raise InputError(path, "output", f"cannot write in it ({exc.strerror})",
                         "give --out a folder you can write to") from exc
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 4096, 0).decode("utf-8", "replace").strip() or "another process"
            raise InputError(path, "output", f"is in use by another sweep ({holder})",
                             "wait until it has finished, or give --out another folder") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, (f"pid {os.getpid()} on {socket.gethostname()} since "
                       f"{time.strftime('%Y-%m-%dT%H:%M:%S%z')}").encode(), 0)
        yield path
    finally:
        try:
            if created is not None and {p.name for p in path.iterdir()} <= {SWEEP_MARKER}:
                shutil.rmtree(created, ignore_errors=True)
        finally:
            os.close(fd)                             # releases the lock


# --------------------------------------------------------------------------- writable paths

def check_writable(path, setting="--out"):
    """Refuse an output ``path`` (a file or a folder, existing or not) that cannot be written.

    Probes the folder that would receive it (the nearest existing one) with an unnamed
    temporary file, which leaves nothing behind; root's permission bypass, read-only
    mounts and immutable folders are all caught that way, where ``os.access`` is not.
    """
    path = Path(path)
    folder = path if path.is_dir() else path.parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    if not folder.is_dir():
        raise InputError(path, "output", f"cannot be created: {folder} is a file, not a folder",
                         f"give {setting} a path inside a folder")
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        why = {errno.EROFS: "is on a read-only file system", errno.EACCES: "is not writable",
               errno.EPERM: "is not writable"}.get(exc.errno, f"cannot be written ({exc.strerror})")
        raise InputError(path, "output", f"{folder} {why}", f"give {setting} a place you can write to") from None


# --------------------------------------------------------------------------- temporaries

def temp_name(target, kind=""):
    """A temporary name beside ``target`` that :func:`remove_leftovers` can recognise as ours."""
    target = Path(target)
    return target.parent / f".{target.name}.{TMP_TAG}.{_host()}.{os.getpid()}.{kind}{secrets.token_hex(4)}"


def _alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:                          # someone else's live process
        return True
    return True


def remove_leftovers(target):
    """Delete the temporaries that a dead process of this host left for ``target``; returns their names."""
    target = Path(target)
    prefix = f".{target.name}.{TMP_TAG}.{_host()}."
    removed = []
    try:
        entries = list(target.parent.iterdir())
    except OSError:
        return removed
    for entry in entries:
        if not entry.name.startswith(prefix):
            continue
        pid = entry.name[len(prefix):].split(".", 1)[0]
        if not pid.isdigit() or int(pid) == os.getpid() or _alive(int(pid)):
            continue
        try:
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry)
            else:
                entry.unlink()
            removed.append(entry.name)
        except OSError:
            pass
    return removed
