"""Find an LLVM that Mitsuba's ``llvm_*`` variants can use.

Dr.Jit needs LLVM >= 16; Debian bookworm's default is 15 and crashes at the first
kernel (``../shared/NOTES.md``). This must run before ``import mitsuba``.
"""

import glob
import os

from harness.errors import EnvironmentProblem

_CANDIDATES = (
    "/usr/lib/x86_64-linux-gnu/libLLVM.so.{v}*",
    "/usr/lib/aarch64-linux-gnu/libLLVM.so.{v}*",
    "/usr/lib/llvm-{v}/lib/libLLVM.so*",
    "/usr/lib/llvm-{v}/lib/libLLVM-{v}.so*",
)
INSTALL_HINT = "install Debian's libllvm19 (apt-get install -y libllvm19) or set DRJIT_LIBLLVM_PATH to a libLLVM >= 16"


def find_libllvm():
    """Return the path of the newest libLLVM >= 16 found, or None."""
    for version in range(22, 15, -1):
        for pattern in _CANDIDATES:
            hits = sorted(glob.glob(pattern.format(v=version)))
            if hits:
                return hits[0]
    return None


def ensure_libllvm():
    """Set ``DRJIT_LIBLLVM_PATH`` unless the user already did; raise if none is found."""
    current = os.environ.get("DRJIT_LIBLLVM_PATH")
    if current and os.path.exists(current):
        return current
    found = find_libllvm()
    if found is None:
        raise EnvironmentProblem(f"no libLLVM >= 16 found for Mitsuba's llvm_ad_rgb variant; {INSTALL_HINT}")
    os.environ["DRJIT_LIBLLVM_PATH"] = found
    return found
