"""Renderer parameters on the command line and in files: ``--grid 16,32`` -> typed lists.

The command-line names are the ones users know from the paper (``--grid`` for
the LPV resolution N); each maps onto one field of
:class:`sslpv_gl.params.SSLPVParams`, whose own validation decides what is
allowed. Every method's parameters (``harness.methods``: SSLPV's and the dipole
rivals') are converted by :mod:`harness.methods.params`; this module keeps the
SSLPV names that existing callers use and the file models.

In files a product of parameter lists is a typed model made from the method's
parameter dataclass itself (:func:`param_lists_model`): keyed by the
command-line names in the TOML matrices (``grid = [16, 32]``), by the field names in a
sweep's ``sweep.json`` (``"N": [16, 32]``). A product of another method than SSLPV names it
(``method = "dipole"``; SSLPV's may). A new renderer parameter appears in both
without a change here; :func:`check_products` then lets the method's dataclass judge every value
and names the file and the key of a bad one.
"""

import dataclasses
import functools
from typing import Annotated, Literal, Optional, Union

from pydantic import Discriminator, Field, Tag, create_model

from harness.errors import InputError
from harness.methods import DEFAULT_METHOD, METHOD_NAMES, get_method
from harness.methods import params as _mp
from harness.methods.sslpv import CLI_TO_FIELD
from harness.validation import InputModel

FIELD_TO_CLI = {v: k for k, v in CLI_TO_FIELD.items()}


#: Parameter field type (as written in the dataclass) -> the type of one value in a file.
_ITEM_TYPES = {"int": int, "float": float, "bool": bool, "str": str, "int | str": Union[int, str],
               "float | None": float, "int | None": int, "str | None": str}


@functools.cache
def param_lists_model(keys="cli", method=DEFAULT_METHOD):
    """The model of one product of parameter lists of ``method``: every field of its parameter
    dataclass as an optional, non-empty list, keyed by its command-line name (``keys="cli"``) or
    its field name (``"field"``), and ``method`` (optional for SSLPV, required for another)."""
    m = get_method(method)
    fields = {}
    for f in dataclasses.fields(m.params_type):
        item = _ITEM_TYPES.get(str(f.type), Union[int, float, str, bool])
        key = m.field_to_cli(f.name) if keys == "cli" else f.name
        fields[key] = (Optional[Annotated[list[item], Field(min_length=1)]],
                       Field(None, description=m.doc(f.name), examples=[[f.default if f.default is not None
                                                                          else 1.0]]))
    if method == DEFAULT_METHOD:
        fields["method"] = (Optional[Literal[method]], Field(None, description="the method (default sslpv)"))
    else:
        fields["method"] = (Literal[method], Field(..., description="the method", examples=[method]))
    return create_model(f"ParamLists_{method}_{keys}", __base__=InputModel, **fields)


def _method_tag(value):
    """The discriminator of :func:`any_product_model`: a product's ``method`` (none: SSLPV)."""
    if isinstance(value, dict):
        return value.get("method", DEFAULT_METHOD)
    return getattr(value, "method", None) or DEFAULT_METHOD


@functools.cache
def any_product_model(keys="cli"):
    """A product of any method: ``method`` picks the model (none: SSLPV's)."""
    return Annotated[Union[tuple(Annotated[param_lists_model(keys, m), Tag(m)] for m in METHOD_NAMES)],
                     Discriminator(_method_tag)]


def check_methods(data, where, prefix):
    """Every product of a raw file table (a dict, or a list of them) names a known method, or one line."""
    items = data if isinstance(data, list) else [data]
    for i, table in enumerate(items):
        if isinstance(table, dict) and "method" in table and table["method"] not in METHOD_NAMES:
            at = f"{prefix}[{i}]" if isinstance(data, list) else prefix
            raise InputError(where, f"{at}.method", f"unknown method {table['method']!r}",
                             "use one of: " + ", ".join(METHOD_NAMES))


def product_dict(model):
    """A validated product model -> ``{field: [values]}`` (only the given ones), with ``method``
    first for another method than SSLPV (an SSLPV product stays what it always was)."""
    name = getattr(model, "method", None) or DEFAULT_METHOD
    m = get_method(name)
    out = {} if name == DEFAULT_METHOD else {"method": name}
    for key, values in model.model_dump(exclude_none=True).items():
        if key != "method":
            out[m.cli.get(key, key)] = values
    return out


def check_products(products, where, prefix="params", keys="cli"):
    """Let each product's method judge every combination; a bad value names ``where`` and
    ``<prefix>.<key>`` (or ``<prefix>[i].<key>`` for a list of products) instead of the flag.

    Errors that name their own file (a calibrated mapping's) are raised as they are.
    """
    many = isinstance(products, list)
    for i, lists in enumerate(products if many else [products]):
        name, fields = _mp.product_method(lists)
        try:
            _mp.expand(name, fields)
        except InputError as exc:
            if not exc.where.startswith("--"):
                raise
            key = get_method(name).field_to_cli(exc.field) if keys == "cli" else exc.field
            at = f"{prefix}[{i}]" if many else prefix
            raise InputError(where, f"{at}.{key}", exc.problem, exc.fix) from None


def parse_lists(values):
    """``{'grid': '16,32', 'steps': None, ...}`` -> ``{'N': [16, 32]}`` (only the given ones)."""
    return _mp.parse_lists("sslpv", values)


def params_from_cli(values):
    """One :class:`SSLPVParams` from single command-line values (``render``)."""
    return _mp.params_from_cli("sslpv", {k: values.get(k) for k in CLI_TO_FIELD})


def expand(lists, base=None):
    """Cartesian product of parameter lists -> list of validated SSLPVParams (input order kept)."""
    return _mp.expand("sslpv", lists, base)


def config_label(params):
    """A short stable name for a configuration: the paper's three axes, then any non-default setting."""
    return get_method("sslpv").label(params)


def file_label(label):
    """``label`` as one file or folder name: a calibrated mapping's path (``calibrated:dir/f.toml``)
    has separators, so every character but letters, digits and ``._=+-`` becomes ``_``."""
    return "".join(ch if ch.isascii() and (ch.isalnum() or ch in "._=+-") else "_" for ch in str(label))
