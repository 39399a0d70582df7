"""Shared fixtures.

``gl_renderer``: ONE :class:`sslpv_gl.renderer.SSLPVRenderer` (one EGL context)
for the whole session, so that the GL test modules do not each build a
context and compile every program again. When no OpenGL 4.3 context can be
created, every test that asks for it is skipped with the one-line reason.
The renderer keeps per-(N, precision) grids and caches between tests; tests
must not rely on state left by another test beyond what they rendered
themselves.
"""

import pytest


@pytest.fixture(scope="session")
def gl_renderer():
    from sslpv_gl.context import GLContextError
    from sslpv_gl.renderer import SSLPVRenderer

    try:
        renderer = SSLPVRenderer()
    except GLContextError as exc:
        pytest.skip(str(exc))
    yield renderer
    renderer.ctx.release()
