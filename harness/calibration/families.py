"""Mapping families that ``sslpv-harness calibrate`` fits, and the renderer settings each is fitted with.

A family is a mapping of :data:`sslpv_gl.material.MAPPINGS` plus two free parameters per
budget: ``sigma_scale`` (a factor on the mapped ``sigma_lpv``) and ``radiance_scale`` (a
global factor on the subsurface radiance). The rest of the renderer's settings are fixed
for the fit and written into the calibrated file (:data:`sslpv_gl.calibrated.SETTINGS`);
each family starts from the settings its own derivation asks for:

==============  =========  ====================================================================
family          mapping    settings (others: ``SSLPVParams`` defaults)
==============  =========  ====================================================================
``diffusion``   diffusion  ``skip = 0``: its radiance scale, Eq. (18)-(21) of
                           ``docs/diffusion_mapping.md``, counts every step (Sec. 6 there)
``collision``   collision  the paper's ``skip = 2`` (Sec. 4)
``transport``   transport  ``skip = 2``, ``outside = absorb``: an extension (one step is one cell of
                           path, ``docs/diffusion_mapping.md`` Sec. 11) that needs an outside
                           treatment taking light out of the propagation; of the two it supports,
                           the study's extension table ranks ``absorb`` first (``docs/results.md``)
==============  =========  ====================================================================

The paper's mappings keep ``outside = vacuum``: the calibration asks how well the mapping does as
SSLPV defines it; ``--outside`` and ``--skip`` change that, and the file records the choice.
The scan range of ``sigma_scale`` is wide enough for either family to reach its optimum at
the suite's budgets (an optimum on the range's edge is flagged in the output).
"""

from __future__ import annotations

from dataclasses import dataclass

from harness.errors import InputError

__all__ = ["Family", "FAMILIES", "family", "COMPARED", "fit_extensions"]


@dataclass(frozen=True)
class Family:
    name: str
    mapping: str                    # key of sslpv_gl.material.MAPPINGS
    settings: dict                  # overrides of SSLPVParams defaults for the fit
    sigma_range: tuple = (1.0 / 16.0, 64.0)
    doc: str = ""


FAMILIES = {
    "diffusion": Family("diffusion", "diffusion", {"skip": 0},
                        doc="diffusion mapping (docs/diffusion_mapping.md) with a global radiance scale and a "
                            "scale on sigma_lpv"),
    "collision": Family("collision", "collision", {"skip": 2},
                        doc="collision mapping (sslpv_gl.material) with a global radiance scale and a scale on "
                            "sigma_lpv"),
    "transport": Family("transport", "transport", {"skip": 2, "outside": "absorb"},
                        doc="transport mapping (an extension: one step is one cell of path) with a global radiance "
                            "scale and a scale on sigma_lpv"),
}

#: The fixed mappings every calibration page compares with, each at its own recommended settings and the fit's
#: others; the shading's exitance read is the paper's for the mappings that support no other.
COMPARED = {"literal": {"skip": 2, "exitance": "isotropic"}, "collision": {"skip": 2, "exitance": "isotropic"},
            "diffusion": {"skip": 0}}


def fit_extensions(family_name, settings):
    """``{setting: value}``: the extensions (:data:`sslpv_gl.params.PAPER_SETTINGS`) among a calibration's renderer
    ``settings`` whose value is not its family's own (the family's setting, else the paper's): what makes a
    calibration of the family with other extensions another calibration. An unknown family has no settings of
    its own."""
    from sslpv_gl.params import PAPER_SETTINGS

    own = FAMILIES[family_name].settings if family_name in FAMILIES else {}
    return {k: v for k, v in settings.items() if k in PAPER_SETTINGS and v != own.get(k, PAPER_SETTINGS[k])}


def family(name):
    """The :class:`Family` called ``name``, or a one-line error listing the known ones."""
    try:
        return FAMILIES[name]
    except (KeyError, TypeError):
        raise InputError("--family", "family", f"unknown mapping family {name!r}",
                         f"use one of: {', '.join(FAMILIES)}") from None
