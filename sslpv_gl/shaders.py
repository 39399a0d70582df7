"""Load GLSL stage files from ``sslpv_gl/shaders/`` with a tiny include mechanism.

A line ``#include "name.glsl"`` is replaced by that file (from the same
folder), once per program; ``defines`` are inserted as ``#define`` lines
right after ``#version``. Shaders live in files, one per stage; nothing is
compiled from Python strings.
"""

from __future__ import annotations

import re
from pathlib import Path

__all__ = ["SHADER_DIR", "load_source", "compute", "program", "check_uniforms", "set_uniform"]

SHADER_DIR = Path(__file__).resolve().parent / "shaders"
_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$')


def _expand(path, seen):
    out = []
    for lineno, line in enumerate(path.read_text().splitlines(), 1):
        m = _INCLUDE.match(line)
        if m:
            inc = path.parent / m.group(1)
            if not inc.is_file():
                raise FileNotFoundError(f"{path.name}:{lineno}: included file {m.group(1)!r} not found")
            if inc not in seen:
                seen.add(inc)
                out.append(_expand(inc, seen))
            continue
        out.append(line)
    return "\n".join(out)


def load_source(name, defines=None):
    """Source of ``shaders/<name>`` with includes expanded and ``defines`` added."""
    path = SHADER_DIR / name
    text = _expand(path, {path})
    lines = text.splitlines()
    if not lines or not lines[0].startswith("#version"):
        raise ValueError(f"{name}: the first line must be #version")
    extra = [f"#define {k} {v}" for k, v in (defines or {}).items()]
    return "\n".join([lines[0], *extra, *lines[1:]]) + "\n"


def program(ctx, vertex, fragment, defines=None, **kwargs):
    """A render program from two stage files."""
    return ctx.program(vertex_shader=load_source(vertex, defines),
                       fragment_shader=load_source(fragment, defines), **kwargs)


def compute(ctx, name, defines=None):
    """A compute program from one stage file."""
    return ctx.compute_shader(load_source(name, defines))


def check_uniforms(prog, names, label, warnings):
    """Append a warning for each uniform the compiler optimised away; return the present ones."""
    present = []
    for name in names:
        if name in prog:
            present.append(name)
        else:
            warnings.append(f"{label}: uniform '{name}' is not active (optimised away by the GLSL compiler)")
    return present


def set_uniform(prog, name, value):
    """Set a uniform that the program uses; an inactive one was reported once by :func:`check_uniforms`."""
    if name in prog:
        prog[name].value = value
