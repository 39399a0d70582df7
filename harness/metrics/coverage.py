"""Which pixels a comparison of SSLPV with a path-traced reference may use.

The two renderers reconstruct a pixel differently: Mitsuba box-filters it (each
sample falls somewhere in the pixel's square, so a pixel that the silhouette
crosses averages the surface with the black background), while the GL renderer
shades the pixel *centre* only. On a pixel that the object covers partly, the
reference is darker than SSLPV by about the covered fraction, whatever SSLPV's
own accuracy; a mask of ``coverage > 0.5`` kept those pixels and biased every
metric (measured by ``benchmarks/silhouette_bias.py``). Only fully covered pixels
are compared: the reference's coverage (the ``mask.exr`` of a reference folder,
the fraction of 4 x 4 stratified camera rays per pixel that hit the mesh,
:func:`harness.reference.mitsuba_scene.coverage_mask`) must reach
:data:`FULL_COVERAGE`, i.e. every one of the 16 rays hits.

:func:`comparison_mask` is the one place that decides this; the sweep's
:func:`harness.runs.sweep.load_reference` (and through it the sweep, the nightly,
the accuracy tests, the verdicts and the calibration), ``sslpv-harness compare`` and the
report use it.
"""

import numpy as np

#: A pixel is fully covered when at least this fraction of its footprint sees the mesh.
FULL_COVERAGE = 0.999


def comparison_mask(coverage, threshold=FULL_COVERAGE):
    """Boolean ``(H, W)`` mask of the pixels to compare: ``coverage >= threshold``.

    Parameters
    ----------
    coverage : array_like, (H, W)
        Fraction of each pixel's footprint covered by the object, in [0, 1].
    threshold : float, default :data:`FULL_COVERAGE`

    Examples
    --------
    >>> import numpy as np
    >>> comparison_mask(np.array([[1.0, 0.9375], [0.5, 0.0]])).tolist()
    [[True, False], [False, False]]
    """
    cov = np.asarray(coverage, dtype=np.float64)
    if cov.ndim != 2:
        raise ValueError(f"comparison_mask: expected an (H, W) coverage, got shape {cov.shape}")
    return cov >= float(threshold)
