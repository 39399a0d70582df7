"""Where the rivals' stage files are: ``dipole_gl/shaders/`` first, then SSLPV's shared ones."""

from pathlib import Path

from sslpv_gl.shaders import SHADER_DIR as SSLPV_SHADER_DIR
from sslpv_gl.rsm import MAX_LIGHTS

SHADER_DIR = Path(__file__).resolve().parent / "shaders"
#: Our files first, then SSLPV's (sh.glsl, optics.glsl, shadow.glsl, reflection.glsl, shade.vert).
DIRS = (SHADER_DIR, SSLPV_SHADER_DIR)

__all__ = ["SHADER_DIR", "DIRS", "MAX_LIGHTS"]
