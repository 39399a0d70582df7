"""Where and with what a run was made: git commit, package versions, machine.

Each run row of the store records these, so that a result can be traced to the code
and the renderer versions that produced it.
"""

import importlib.metadata
import os
import platform
import socket
import subprocess
from pathlib import Path

#: Packages whose versions :func:`versions` records.
VERSIONED_PACKAGES = ("mitsuba", "drjit", "moderngl", "numpy")


def git_commit(path=None):
    """The commit hash of the git checkout at ``path`` (default: this harness's folder), or None."""
    cwd = Path(path) if path is not None else Path(__file__).resolve().parent
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=cwd, capture_output=True, text=True,
                             timeout=10, check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    sha = out.stdout.strip()
    return sha if out.returncode == 0 and sha else None


def versions():
    """Versions of the renderers and the harness: ``{name: version or None}``."""
    out = {}
    for name in VERSIONED_PACKAGES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = None
    from harness import __version__
    out["harness"] = __version__
    return out


def machine():
    """Host name, CPU count and platform of this machine."""
    return {"hostname": socket.gethostname(), "cpu_count": os.cpu_count(),
            "platform": platform.platform(), "python": platform.python_version()}
