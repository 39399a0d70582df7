"""The project's source files as hashes that ignore what cannot change a result: docstrings, comments, layout.

Shared by the result cache's code fingerprints (:mod:`harness.runs.fingerprint`) and the report's
artefact memo (:mod:`harness.report.memo`).

* :func:`python_source_hash`: a module's syntax tree without docstrings (comments and layout
  never reach the tree), so editing a docstring or a comment changes nothing, a statement does.
* :func:`glsl_source_hash`: GLSL without ``//`` and ``/* */`` comments, blank space collapsed.
* :func:`import_closure`: the project's modules that some entry modules import, transitively,
  from ``grimp``'s import graph (the library under ``import-linter``; it also sees imports
  inside functions).
"""

from __future__ import annotations

import ast
import functools
import hashlib
import re
from pathlib import Path

from harness import paths

__all__ = ["module_path", "python_source_hash", "glsl_source_hash", "parsed", "import_closure", "ROOTS"]

#: The project's top-level packages.
ROOTS = ("harness", "sslpv_gl", "dipole_gl")
_GLSL_COMMENT = re.compile(r"//[^\n]*|/\*.*?\*/", re.S)


def module_path(module):
    """The file of a project module (``sslpv_gl/shaders.py`` beside the folder ``sslpv_gl/shaders/``)."""
    base = paths.REPO.joinpath(*module.split("."))
    file = base.with_suffix(".py")
    return file if file.is_file() else base / "__init__.py"


def _strip_docstrings(tree):
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
                    and isinstance(body[0].value.value, str):
                node.body = body[1:] or [ast.Pass()]
    return tree


@functools.lru_cache(maxsize=None)
def parsed(path):
    """The syntax tree of a Python file without its docstrings (cached per path)."""
    return _strip_docstrings(ast.parse(Path(path).read_text(), filename=str(path)))


def python_source_hash(path):
    """sha256 of a module's syntax tree without docstrings."""
    return hashlib.sha256(ast.dump(parsed(str(path)), include_attributes=False).encode()).hexdigest()


def glsl_source_hash(text):
    """sha256 of GLSL source without its comments and with its blank space collapsed."""
    body = " ".join(_GLSL_COMMENT.sub(" ", text).split())
    return hashlib.sha256(body.encode()).hexdigest()


@functools.lru_cache(maxsize=1)
def _graph():
    import grimp

    return grimp.build_graph(*ROOTS, cache_dir=None)


def import_closure(entries):
    """The project modules ``entries`` import, transitively, with the entries themselves (sorted)."""
    graph = _graph()
    mods = set(entries)
    for e in entries:
        mods |= graph.find_upstream_modules(e)
    return sorted(m for m in mods if m.split(".")[0] in ROOTS)
