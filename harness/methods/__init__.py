"""The method registry: every renderer the harness compares, by name, and their parameters.

.. list-table::
   :header-rows: 1

   * - ``--method``
     - what
     - adapter
   * - ``sslpv``
     - SSLPV (Borlum et al., HPG 2011), ``sslpv_gl``; the default
     - :mod:`harness.methods.sslpv`
   * - ``dipole``
     - standard dipole (Jensen et al. 2001), dense or per-vertex gather (Hao & Varshney 2004), ``dipole_gl``
     - :mod:`harness.methods.dipole`
   * - ``dirpole``
     - directional dipole (Frisvad et al. 2014), dense or per-vertex gather, ``dipole_gl``
     - :mod:`harness.methods.dipole`

This package sits above every renderer (``sslpv_gl``, ``dipole_gl``) and below the runs, the
regression machinery and the command line (``docs/architecture.md``); the report never
imports it (it reads a configuration's method and parameters from the store). The interface
is :mod:`harness.methods.base`; command-line lists become configurations in
:mod:`harness.methods.params`.
"""

from __future__ import annotations

from harness.errors import InputError

from .base import Method, MethodResult, unknown_method

__all__ = ["Method", "MethodResult", "METHOD_NAMES", "DEFAULT_METHOD", "get_method", "parse_methods", "config_label",
           "release_all"]

METHOD_NAMES = ("sslpv", "dipole", "dirpole")
DEFAULT_METHOD = "sslpv"
_INSTANCES = {}
_SHARED = {}                                           # state shared by the two dipole kernels (one renderer)


def get_method(name):
    """The :class:`Method` called ``name`` (one instance per process), or an InputError."""
    if name not in METHOD_NAMES:
        raise unknown_method(name, METHOD_NAMES)
    m = _INSTANCES.get(name)
    if m is None:
        if name == "sslpv":
            from .sslpv import SSLPVMethod

            m = SSLPVMethod()
        else:
            from .dipole import DipoleMethod

            m = DipoleMethod(name, _SHARED)
        _INSTANCES[name] = m
    return m


def parse_methods(spec):
    """``"sslpv,dipole"`` (or a list) -> validated names, first seen first; None -> the default."""
    if spec is None:
        return [DEFAULT_METHOD]
    names = [s.strip() for s in spec.split(",")] if isinstance(spec, str) else [str(s) for s in spec]
    if not names or any(not n for n in names):
        raise InputError("--method", "method", f"empty method name in {spec!r}", "list methods separated by commas")
    out = []
    for n in names:
        get_method(n)
        if n not in out:
            out.append(n)
    return out


def config_label(method, params):
    """The stable label of one configuration of ``method`` (``params`` a dict or a params object)."""
    return get_method(method or DEFAULT_METHOD).label(params)


def release_all():
    """Release every renderer this process made (their GL contexts)."""
    for m in list(_INSTANCES.values()):
        m.release()
