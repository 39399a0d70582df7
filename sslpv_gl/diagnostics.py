"""Where the light of an SSLPV render is: the injected flux, what is still propagating, the share outside the mesh.

Flux is measured on band-0 SH coefficients, ``sum sqrt(4 pi) |c00|`` per colour
(:func:`_flux`); :func:`_diagnostics` fills :attr:`sslpv_gl.renderer.RenderResult.diagnostics`
and is read outside the stage timers.
"""

import numpy as np


def _flux(c00):
    """Total flux per colour of an SH grid's band-0 coefficients ``(..., 3)``: ``sum sqrt(4 pi) |c00|``.

    abs: a lattice grid may dip below 0.
    """
    return np.sqrt(4.0 * np.pi) * np.abs(np.asarray(c00)).reshape(-1, 3).sum(axis=0, dtype=np.float64)


def _diagnostics(inj, final, accum, outside_mask, steps_used):
    """Where the light is: injected flux, what is still propagating, and the accumulated share outside the mesh.

    ``inj`` is the injected flux per colour (:func:`_flux` of the injected grid, once per render);
    ``final`` and ``accum`` are band-0 coefficients ``(N, N, N, 3)`` (:func:`read_c00`) of the last
    propagation and the accumulation grid; ``outside_mask`` is True for the cells outside the mesh.
    """
    acc = np.abs(np.asarray(accum))                                     # (N, N, N, 3), sums in float64
    total = acc.reshape(-1, 3).sum(axis=0, dtype=np.float64)
    outside = acc[outside_mask].sum(axis=0, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        remaining = None if final is None else float(np.max(np.where(inj > 0, _flux(final) / inj, 0.0)))
        share = float(np.sum(outside) / np.sum(total)) if np.sum(total) > 0 else 0.0
    return {"steps_used": steps_used, "injected_flux": inj.tolist(), "remaining_fraction": remaining,
            "outside_share": share}
