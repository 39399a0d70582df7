"""SSLPV accuracy regression tests: each case renders SSLPV at 64x64 and compares its
headline metrics with the committed baseline (``baselines/<scene>.json``), measured
against the committed reference (``baselines/refs/<scene>``). Run alone with
``pytest -m accuracy``.

A case fails when a headline metric exceeds baseline + noise floor + tolerance; it
then writes the image, the reference and the error map to
``test-artifacts/accuracy/<scene>/<config>/`` and prints the command that accepts
the new values.
"""

import pytest

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
    result = check_case(renderer, scene, params, tolerance)
    assert len(result.checks) == 4, f"expected four headline metrics, got {result.checks}"
    assert not result.failed, result.message()
