"""Headless OpenGL 4.3+ context for the SSLPV renderer (EGL; llvmpipe is enough).

``create_context()`` returns a moderngl context or raises
:class:`GLContextError` with one line that names what is missing. The
renderer string is logged, and every result carries it, so that a result
can never silently come from the wrong device (``../shared/NOTES.md``).
"""

from __future__ import annotations

import logging

from harness.errors import EnvironmentProblem

__all__ = ["GLContextError", "create_context", "REQUIRED_GL"]

log = logging.getLogger(__name__)

REQUIRED_GL = 430  # compute shaders, image load/store


class GLContextError(EnvironmentProblem):
    """No usable OpenGL context; the message is one line (the CLI exits with code 3)."""

    def __init__(self, message):
        super().__init__(" ".join(str(message).split()))


def _first_line(exc):
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def create_context():
    """A standalone EGL moderngl context with OpenGL >= 4.3 (compute shaders)."""
    try:
        import moderngl
    except ImportError as exc:  # pragma: no cover - moderngl is a dependency
        raise GLContextError(f"cannot create an EGL OpenGL context (moderngl is not installed: {exc})") from exc
    try:
        ctx = moderngl.create_standalone_context(backend="egl", require=REQUIRED_GL)
    except Exception as exc:
        # Tell an old GL apart from no GL at all: try again without the requirement.
        version = None
        try:
            probe = moderngl.create_standalone_context(backend="egl")
            version = probe.version_code
            probe.release()
        except Exception:
            pass
        if version is not None and version < REQUIRED_GL:
            raise GLContextError(f"OpenGL 4.3 is required, got {version // 100}.{version % 100 // 10}") from exc
        raise GLContextError(f"cannot create an EGL OpenGL context ({_first_line(exc)}); "
                             "install Mesa's EGL (libegl1, libgl1-mesa-dri) or a GPU driver") from exc
    if ctx.version_code < REQUIRED_GL:
        version = ctx.version_code
        ctx.release()
        raise GLContextError(f"OpenGL 4.3 is required, got {version // 100}.{version % 100 // 10}")
    log.info("OpenGL context: %s (GL %s)", ctx.info.get("GL_RENDERER"), ctx.version_code)
    return ctx
