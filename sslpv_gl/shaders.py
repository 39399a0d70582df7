"""Load GLSL stage files from ``sslpv_gl/shaders/`` with a tiny include mechanism.

A line ``#include "name.glsl"`` is replaced by that file (from the including
file's folder, else from the next folder of ``dirs``), once per program;
``defines`` are inserted as ``#define`` lines right after ``#version``. Shaders
live in files, one per stage; nothing is compiled from Python strings.
``dirs`` (default: this package's ``shaders/``) lets another renderer keep its
own stage files and include SSLPV's shared ones (``optics.glsl``, ``shadow.glsl``).
"""

from __future__ import annotations

import re
from pathlib import Path

__all__ = ["SHADER_DIR", "load_source", "compute", "program", "check_uniforms", "set_uniform"]

SHADER_DIR = Path(__file__).resolve().parent / "shaders"
_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$')


def _expand(path, seen, dirs):
    out = []
    for lineno, line in enumerate(path.read_text().splitlines(), 1):
        m = _INCLUDE.match(line)
        if m:
            found = [d / m.group(1) for d in (path.parent, *dirs) if (d / m.group(1)).is_file()]
            if not found:
                raise FileNotFoundError(f"{path.name}:{lineno}: included file {m.group(1)!r} not found")
            inc = found[0]
            if inc not in seen:
                seen.add(inc)
                out.append(_expand(inc, seen, dirs))
            continue
        out.append(line)
    return "\n".join(out)


def load_source(name, defines=None, dirs=(SHADER_DIR,)):
    """Source of ``<dir>/<name>`` (the first of ``dirs`` that has it) with includes expanded and ``defines`` added."""
    dirs = tuple(Path(d) for d in dirs)
    path = next((d / name for d in dirs if (d / name).is_file()), dirs[0] / name)
    text = _expand(path, {path}, dirs)
    lines = text.splitlines()
    if not lines or not lines[0].startswith("#version"):
        raise ValueError(f"{name}: the first line must be #version")
    extra = [f"#define {k} {v}" for k, v in (defines or {}).items()]
    return "\n".join([lines[0], *extra, *lines[1:]]) + "\n"


def program(ctx, vertex, fragment, defines=None, dirs=(SHADER_DIR,), **kwargs):
    """A render program from two stage files."""
    return ctx.program(vertex_shader=load_source(vertex, defines, dirs),
                       fragment_shader=load_source(fragment, defines, dirs), **kwargs)


def compute(ctx, name, defines=None, dirs=(SHADER_DIR,)):
    """A compute program from one stage file."""
    return ctx.compute_shader(load_source(name, defines, dirs))


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
