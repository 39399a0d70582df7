"""Henyey-Greenstein phase function with a spatially varying asymmetry (``gridhg``).

.. list-table::
   :header-rows: 1

   * - Parameter
     - Type
     - Description
   * - g
     - |volume| (single channel)
     - Mean cosine of the scattering angle at each point of the medium, in
       (-1, 1). Usually a ``gridvolume`` with ``filter_type = "nearest"`` and
       the medium's ``to_world``, so that it sees exactly the scene's voxels.
       A plain float is accepted too (constant g). Default: 0.

This plugin implements the phase function of Henyey and Greenstein (1941,
"Diffuse radiation in the galaxy", ApJ 93, 70-83),

    p(cos t) = (1 - g^2) / (4 pi (1 + g^2 - 2 g cos t)^(3/2)),

with ``g`` looked up at the interaction point ``mei.p``. Mitsuba 3.9's stock
``hg`` takes only a scalar g (``../shared/NOTES.md``). Sampling inverts the
CDF exactly and uses the same arithmetic, in the same order, as the stock
``hg`` plugin: with g given as a float it renders images bit-identical to
``hg``. With g read from a grid the formula runs on a runtime value instead of
a JIT literal, which is rounded differently in the last bit for some g (e.g.
-0.4; exact for 0 and 0.5), so images agree to float rounding
(``tests/test_reference_validation.py`` checks both). The harness uses the
stock ``hg`` whenever g is one constant.

Limits:

* **One g per point, not per colour.** Mitsuba's RGB variants trace one
  direction for all three colour channels of a path, so the scattering
  direction cannot depend on the channel. The harness passes the *mean of the
  three channels* of the scene's RGB g grid (``mitsuba_scene.phase_g_grid``)
  and records the largest channel spread in ``reference.json``; every g grid
  of the suite is grey, so the mean is exact there.
* ``sample`` returns weight 1 (perfect importance sampling); ``eval_pdf``
  returns value = pdf.
"""

from harness.reference.llvm import ensure_libllvm

try:  # must precede ``import mitsuba``; a CUDA-only machine may have no LLVM (use_variant checks again)
    ensure_libllvm()
except RuntimeError:
    pass

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

PLUGIN_NAME = "gridhg"


class GridHGPhaseFunction(mi.PhaseFunction):
    """Henyey-Greenstein phase function whose g is read from a volume; see the module docstring."""

    def __init__(self, props):
        mi.PhaseFunction.__init__(self, props)
        g = props.get("g", 0.0)
        if isinstance(g, (int, float)):
            if not -1.0 < g < 1.0:
                raise ValueError(f"gridhg: g = {g} must lie in (-1, 1)")
            self.g_const, self.g_volume = float(g), None
        else:
            self.g_const, self.g_volume = None, g
        self.m_flags = mi.PhaseFunctionFlags.Anisotropic

    # ------------------------------------------------------------------ helpers

    def _g(self, mei, active):
        if self.g_volume is None:
            return mi.Float(self.g_const)
        return self.g_volume.eval_1(mei, active)

    @staticmethod
    def _eval_hg(g, cos_theta):
        # Henyey & Greenstein (1941), Eq. (1); same operation order as Mitsuba's hg.cpp.
        temp = 1.0 + dr.square(g) + 2.0 * g * cos_theta
        return dr.inv_four_pi * (1.0 - dr.square(g)) / (temp * dr.sqrt(temp))

    # ------------------------------------------------------------------ interface

    def sample(self, ctx, mei, sample1, sample2, active=True):
        g = self._g(mei, active)
        # Inverse CDF of the HG distribution of cos(theta) (theta measured from the propagation direction).
        sqr_term = (1.0 - dr.square(g)) / (1.0 - g + 2.0 * g * sample2.x)
        cos_theta = (1.0 + dr.square(g) - dr.square(sqr_term)) / (2.0 * g)
        cos_theta = dr.select(dr.abs(g) < dr.epsilon(mi.Float), 1.0 - 2.0 * sample2.x, cos_theta)  # isotropic fallback

        sin_theta = dr.safe_sqrt(1.0 - dr.square(cos_theta))
        sin_phi, cos_phi = dr.sincos(2.0 * dr.pi * sample2.y)
        # The shading frame's normal is mei.wi (towards the previous vertex): forward is -z.
        wo = mei.to_world(mi.Vector3f(sin_theta * cos_phi, sin_theta * sin_phi, -cos_theta))
        return wo, mi.Spectrum(1.0), self._eval_hg(g, -cos_theta)

    def eval_pdf(self, ctx, mei, wo, active=True):
        g = self._g(mei, active)
        pdf = self._eval_hg(g, dr.dot(wo, mei.wi))
        return mi.Spectrum(pdf), pdf

    def to_string(self):
        src = f"g = {self.g_const}" if self.g_volume is None else f"g = {self.g_volume}"
        return f"GridHGPhaseFunction[{src}]"


_REGISTERED = set()


def register():
    """Register ``gridhg`` for the active Mitsuba variant (once per variant)."""
    variant = mi.variant()
    if variant is None:
        raise RuntimeError("gridhg: set a Mitsuba variant (mi.set_variant) before registering the plugin")
    if variant not in _REGISTERED:
        mi.register_phase(PLUGIN_NAME, lambda props: GridHGPhaseFunction(props))
        _REGISTERED.add(variant)
    return PLUGIN_NAME
