"""What a method's result depends on, as hashes: its code, its shaders and the packages that shape an image.

The result cache (:mod:`harness.runs.cache`) keys every configuration by, among others,
the *code fingerprint* of the method that rendered it:

* **Python.** The modules the method's entry points import, transitively, inside this
  project (``harness``, ``sslpv_gl``, ``dipole_gl``), found by ``grimp``'s import graph
  (the library under ``import-linter``, which checks the layers; it also sees imports
  inside functions), plus :data:`ALWAYS` (the sweep worker that turns a render into a
  result). Each module is hashed as its abstract syntax tree with the docstrings removed,
  so a docstring or a comment changes nothing, while any statement does.
* **Shaders.** Every stage file named by a string constant in those modules
  (``"propagate.comp"``), looked up in the shader folders of :data:`SHADER_DIRS` in that
  order, and every file they ``#include``, recursively. Each is hashed with its comments
  and blank space removed.
* **Packages.** The versions of :data:`PACKAGES` (the ones that compute or read an image)
  and Python's.

Limits
------
* A shader name built at run time (``f"{stage}.frag"``) is not seen; :func:`method_shaders`
  lists what was found, and ``tests/test_result_cache.py`` checks it against each package's
  shader folder.
* A change outside the import graph (a data file read at run time, an environment
  variable) is not part of the fingerprint. Scene files and references are keyed by
  their own content hashes (:mod:`harness.runs.cache`).
"""

from __future__ import annotations

import ast
import functools
import hashlib
import importlib.metadata
import platform
import re

from harness import paths
from harness.io.source import glsl_source_hash, import_closure, module_path, parsed, python_source_hash

__all__ = ["ENTRIES", "ALWAYS", "PACKAGES", "SHADER_DIRS", "METRIC_ENTRIES", "METRIC_PACKAGES", "method_fingerprint",
           "method_modules", "method_shaders", "metrics_fingerprint", "package_versions"]

#: Each method's entry points: the modules that render it and state its results.
ENTRIES = {
    "sslpv": ("sslpv_gl.renderer", "harness.methods.sslpv"),
    "dipole": ("dipole_gl.renderer", "harness.methods.dipole"),
    "dirpole": ("dipole_gl.renderer", "harness.methods.dipole"),
}
#: Modules in every method's fingerprint, without their imports (those are the metrics, which key
#: the entry's metric rows separately: :func:`metrics_fingerprint`).
ALWAYS = ("harness.runs.worker",)
#: Shader folders, searched in this order for a name (dipole_gl's own first, as ``dipole_gl.glsl.DIRS``).
SHADER_DIRS = (paths.REPO / "dipole_gl" / "shaders", paths.REPO / "sslpv_gl" / "shaders")
#: Packages whose version can change an image or how it is read.
PACKAGES = ("numpy", "scipy", "moderngl", "glcontext", "pymeshlab", "OpenEXR", "pydantic")
#: What a configuration's metric rows are computed by: the metrics package (with its imports) and the
#: worker module whose ``measure`` and ``reference_floors`` call it (without its imports: those are the methods).
METRIC_ENTRIES = ("harness.metrics",)
#: Packages whose version can change a metric's value.
METRIC_PACKAGES = ("numpy", "scipy", "flip-evaluator", "colour-science", "scikit-image", "OpenEXR")
_SHADER_NAME = re.compile(r"^[A-Za-z0-9_]+\.(?:vert|frag|comp|glsl)$")
_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"', re.M)


def method_modules(method):
    """The project's modules ``method``'s results depend on (its entries' import closure and :data:`ALWAYS`)."""
    return sorted(set(import_closure(ENTRIES[method])) | set(ALWAYS))


def _find_shader(name):
    for d in SHADER_DIRS:
        if (d / name).is_file():
            return d / name
    return None


def method_shaders(method):
    """Shader files of ``method``: stage names in its modules' string constants and their ``#include``s."""
    names = set()
    for mod in method_modules(method):
        if mod in ALWAYS:
            continue
        for node in ast.walk(parsed(str(module_path(mod)))):
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and _SHADER_NAME.match(node.value):
                names.add(node.value)
    found, todo = {}, sorted(names)
    while todo:
        name = todo.pop()
        path = _find_shader(name)
        if path is None or name in found:
            continue
        found[name] = path
        todo += [n for n in _INCLUDE.findall(path.read_text()) if n not in found]
    return sorted(found.values())


@functools.lru_cache(maxsize=None)
def package_versions(packages=PACKAGES):
    """``{package: version}`` of ``packages`` (default :data:`PACKAGES`; absent ones omitted) and Python's."""
    out = {"python": platform.python_version()}
    for name in packages:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            continue
    return out


def method_fingerprint(method):
    """``{"code": sha256, "modules": {module: sha}, "shaders": {file: sha}}`` of ``method``'s code as it is now."""
    modules = {m: python_source_hash(module_path(m)) for m in method_modules(method)}
    shaders = {str(p.relative_to(paths.REPO)): glsl_source_hash(p.read_text()) for p in method_shaders(method)}
    blob = repr((sorted(modules.items()), sorted(shaders.items()))).encode()
    return {"code": hashlib.sha256(blob).hexdigest(), "modules": modules, "shaders": shaders}


@functools.lru_cache(maxsize=1)
def metrics_fingerprint():
    """sha256 of the code and packages that turn a render and its reference into metric rows.

    The result cache keeps a configuration's metric rows beside its images under this hash
    (:mod:`harness.runs.cache`): the images and the reference are in the entry's key already, so
    the rows are reused exactly while this hash is unchanged, and measured again otherwise.
    Computed once per process (the files do not change while a sweep runs).
    """
    modules = {m: python_source_hash(module_path(m)) for m in sorted(set(import_closure(METRIC_ENTRIES)) | set(ALWAYS))}
    blob = repr((sorted(modules.items()), sorted(package_versions(METRIC_PACKAGES).items()))).encode()
    return hashlib.sha256(blob).hexdigest()
