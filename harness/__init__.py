"""Validation harness: measures how far SSLPV (Borlum et al., HPG 2011) is from
physically based ground truth rendered with Mitsuba 3."""

__version__ = "0.1.0"
