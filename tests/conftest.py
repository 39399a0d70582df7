"""Shared fixtures.

``gl_renderer``: ONE :class:`sslpv_gl.renderer.SSLPVRenderer` (one EGL context)
for the whole session, so that the GL test modules do not each build a
context and compile every program again. When no OpenGL 4.3 context can be
created, every test that asks for it FAILS with the one-line reason: OpenGL
4.3 through EGL is a requirement of the project (llvmpipe is enough), and a
suite that silently skipped its GL tests would report a pass it never earned.
The renderer keeps per-(N, precision) grids and caches between tests; tests
must not rely on state left by another test beyond what they rendered
themselves.

``synthetic_site``: ONE synthetic results store and its report site
(:mod:`tests.synthetic_store`) for the session, shared by the report tests and the
browser tests; tests that need another site build it in their own ``tmp_path``,
and a test that adds a page to this one removes it again.

Every test has a result cache and a report memo of its own (``SSLPV_RESULT_CACHE`` and
``SSLPV_REPORT_CACHE`` in its ``tmp_path``: :mod:`harness.runs.cache`, :mod:`harness.report.memo`): a sweep in one test never serves another test's renders, and
nothing is written to the repository's ``cache/``.
"""

import pytest


@pytest.fixture(autouse=True)
def _own_result_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("SSLPV_RESULT_CACHE", str(tmp_path / "result-cache"))
    monkeypatch.setenv("SSLPV_REPORT_CACHE", str(tmp_path / "report-cache"))


def _renderer(make, release):
    from sslpv_gl.context import GLContextError

    try:
        renderer = make()
    except GLContextError as exc:
        pytest.fail(str(exc), pytrace=False)
    yield renderer
    release(renderer)


@pytest.fixture(scope="session")
def gl_renderer():
    from sslpv_gl.renderer import SSLPVRenderer

    yield from _renderer(SSLPVRenderer, lambda r: r.ctx.release())


@pytest.fixture(scope="session")
def dipole_renderer():
    """ONE :class:`dipole_gl.renderer.DipoleRenderer` (its own EGL context) for the session, as ``gl_renderer``."""
    from dipole_gl.renderer import DipoleRenderer

    yield from _renderer(DipoleRenderer, lambda r: r.release())


@pytest.fixture(scope="session")
def synthetic_site(tmp_path_factory):
    from harness.report import build_report

    from .synthetic_store import make_synthetic_store

    root = tmp_path_factory.mktemp("report")
    store_path, run = make_synthetic_store(root)
    info = build_report(store_path, root / "site")
    return root, store_path, run, info
