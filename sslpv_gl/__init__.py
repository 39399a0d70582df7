"""SSLPV (Borlum et al., HPG 2011): GL renderer and its NumPy twin.

Kept import-light: no moderngl at package import time.
"""

from .sh import propagation_matrices

__all__ = ["propagation_matrices"]
