"""SSLPV's classical rivals in GLSL: the standard dipole (Jensen et al. 2001) and the directional
dipole (Frisvad, Hachisuka & Kjeldsen 2014), gathered over the whole surface (``dense``) or per
vertex over a precomputed neighbourhood (``vertex``, Hao & Varshney 2004); NumPy twin beside.

Kept import-light: no moderngl at package import time. ``docs/dipole_rivals.md`` derives the
kernels and states every choice; :mod:`dipole_gl.renderer` is the front door.
"""

__all__ = []
