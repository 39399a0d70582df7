"""SSLPV accuracy regression tests: each case renders SSLPV at its committed small size (64x64, or
the scene's aspect: wide_slab 60x36) and compares it with
its committed image (``baselines/images/``); only a changed image is judged, as paired
differences of the headline metrics against the committed reference
(``baselines/refs/<scene>``). Run alone with ``pytest -m accuracy``.

A case fails on a regression and on an improvement (the printout gives Delta, its
standard error, z and the threshold of every metric, and the command that accepts the
new values and image); a change within noise passes with a warning. A failure writes
the image, the reference and the error map to ``test-artifacts/accuracy/<scene>/<config>/``.
"""

import warnings

import pytest

from harness.errors import InputError
from harness.regression.accuracy import cases, check_case
from harness.runs.params import config_label

pytestmark = [pytest.mark.accuracy, pytest.mark.gl]

CASES = cases()


@pytest.fixture(scope="module")
def renderer():
    from sslpv_gl.renderer import SSLPVRenderer

    return SSLPVRenderer()


@pytest.mark.parametrize("scene,params,tolerance", CASES,
                         ids=[f"{s}-{config_label(p)}" for s, p, _ in CASES])
def test_accuracy(renderer, scene, params, tolerance):
    try:
        result = check_case(renderer, scene, params, tolerance)
    except InputError as exc:
        pytest.fail(f"error: {exc}", pytrace=False)
    if result.verdict == "changed-within-noise":
        warnings.warn(result.message(), stacklevel=1)
    assert result.verdict in ("unchanged", "changed-within-noise"), result.message()
    if result.checks:
        assert len(result.checks) == 4, f"expected four headline metrics, got {result.checks}"
