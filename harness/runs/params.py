"""Renderer parameters on the command line and in files: ``--grid 16,32`` -> typed lists.

The command-line names are the ones users know from the paper (``--grid`` for
the LPV resolution N); each maps onto one field of
:class:`sslpv_gl.params.SSLPVParams`, whose own validation decides what is
allowed.

In files a product of parameter lists is a typed model made from
:class:`~sslpv_gl.params.SSLPVParams` itself (:func:`param_lists_model`): keyed by the
command-line names in the TOML matrices (``grid = [16, 32]``), by the field names in a
sweep's ``sweep.json`` (``"N": [16, 32]``). A new renderer parameter appears in both
without a change here; :func:`check_products` then lets ``SSLPVParams`` judge every value
and names the file and the key of a bad one.
"""

import dataclasses
import functools
import itertools
from typing import Annotated, Optional, Union

from pydantic import Field, create_model

from harness.errors import InputError
from harness.validation import InputModel

# command-line name -> SSLPVParams field
CLI_TO_FIELD = {
    "grid": "N", "steps": "steps", "mapping": "mapping", "resample": "resample", "outside": "outside",
    "lookup": "lookup", "skip": "skip", "inject_offset": "inject_offset", "precision": "precision",
    "rsm_size": "rsm_size", "inject_size": "inject_size", "eta2": "eta2",
    "sigma_scale": "sigma_scale", "radiance_scale": "radiance_scale", "converge_tol": "converge_tol",
    "max_steps": "max_steps",
}
FIELD_TO_CLI = {v: k for k, v in CLI_TO_FIELD.items()}


def _field_types():
    from sslpv_gl.params import SSLPVParams

    return {f.name: f.type for f in dataclasses.fields(SSLPVParams)}


#: SSLPVParams field type (as written in the dataclass) -> the type of one value in a file.
_ITEM_TYPES = {"int": int, "float": float, "bool": bool, "str": str, "int | str": Union[int, str]}


@functools.cache
def param_lists_model(keys="cli"):
    """The model of one product of parameter lists: every SSLPVParams field as an optional,
    non-empty list, keyed by its command-line name (``keys="cli"``) or its field name (``"field"``)."""
    from sslpv_gl.params import SSLPVParams

    fields = {}
    for f in dataclasses.fields(SSLPVParams):
        item = _ITEM_TYPES.get(str(f.type), Union[int, float, str, bool])
        key = FIELD_TO_CLI.get(f.name, f.name) if keys == "cli" else f.name
        fields[key] = (Optional[Annotated[list[item], Field(min_length=1)]],
                       Field(None, description=SSLPVParams.doc(f.name), examples=[[f.default]]))
    return create_model(f"ParamLists_{keys}", __base__=InputModel, **fields)


def product_dict(model):
    """A validated product model -> ``{SSLPVParams field: [values]}`` (only the given ones)."""
    out = {}
    for key, values in model.model_dump(exclude_none=True).items():
        out[CLI_TO_FIELD.get(key, key)] = values
    return out


def check_products(products, where, prefix="params", keys="cli"):
    """Let SSLPVParams judge every combination of each product; a bad value names ``where`` and
    ``<prefix>.<key>`` (or ``<prefix>[i].<key>`` for a list of products) instead of the flag.

    Errors that name their own file (a calibrated mapping's) are raised as they are.
    """
    many = isinstance(products, list)
    for i, lists in enumerate(products if many else [products]):
        try:
            expand(lists)
        except InputError as exc:
            if not exc.where.startswith("--"):
                raise
            key = FIELD_TO_CLI.get(exc.field, exc.field) if keys == "cli" else exc.field
            at = f"{prefix}[{i}]" if many else prefix
            raise InputError(where, f"{at}.{key}", exc.problem, exc.fix) from None


def _convert(cli_name, text, type_name):
    flag = "--" + cli_name.replace("_", "-")
    if type_name in ("bool", bool):
        if text.lower() in ("true", "1", "yes", "on"):
            return True
        if text.lower() in ("false", "0", "no", "off"):
            return False
        raise InputError(flag, cli_name, f"{text!r} is not true or false", "write true or false")
    if type_name == "int | str":                     # steps: a count, or a mode ('auto', 'steady')
        try:
            return int(text)
        except ValueError:
            return text
    try:
        if type_name in ("int", int):
            return int(text)
        if type_name in ("float", float):
            return float(text)
    except ValueError:
        raise InputError(flag, cli_name, f"{text!r} is not a{'n integer' if type_name in ('int', int) else ' number'}",
                         "give numbers separated by commas, e.g. 16,32") from None
    return text


def parse_lists(values):
    """``{'grid': '16,32', 'steps': None, ...}`` -> ``{'N': [16, 32]}`` (only the given ones)."""
    types = _field_types()
    out = {}
    for cli_name, field in CLI_TO_FIELD.items():
        raw = values.get(cli_name)
        if raw is None:
            continue
        if isinstance(raw, (list, tuple)):
            items = [str(x) for x in raw]
        else:
            items = [x.strip() for x in str(raw).split(",")]
        if not items or any(x == "" for x in items):
            raise InputError("--" + cli_name.replace("_", "-"), cli_name, f"empty value in {raw!r}",
                             "give at least one value, separated by commas")
        out[field] = [_convert(cli_name, x, types[field]) for x in items]
    return out


def params_from_cli(values):
    """One :class:`SSLPVParams` from single command-line values (``render``)."""
    from sslpv_gl.params import SSLPVParams

    lists = parse_lists(values)
    for field, vals in lists.items():
        if len(vals) != 1:
            raise InputError("--" + FIELD_TO_CLI[field].replace("_", "-"), FIELD_TO_CLI[field],
                             f"takes one value here, got {len(vals)}", "use 'sweep' for lists")
    return SSLPVParams(**{k: v[0] for k, v in lists.items()})


def expand(lists, base=None):
    """Cartesian product of parameter lists -> list of validated SSLPVParams (input order kept)."""
    from sslpv_gl.params import SSLPVParams

    base = dict(base or {})
    keys = list(lists)
    combos = itertools.product(*(lists[k] for k in keys)) if keys else [()]
    out = []
    for combo in combos:
        kw = dict(base, **dict(zip(keys, combo)))
        out.append(SSLPVParams(**kw))
    return out


def config_label(params):
    """A short stable name for a configuration: the paper's three axes, then any non-default setting."""
    from sslpv_gl.params import SSLPVParams

    p = params if isinstance(params, dict) else params.as_dict()
    label = f"N{p['N']}-K{p['steps']}-{p['mapping']}"
    defaults = SSLPVParams().as_dict()
    extra = [f"{FIELD_TO_CLI.get(k, k)}={v}" for k, v in sorted(p.items())
             if k not in ("N", "steps", "mapping") and v != defaults.get(k)]
    return label + ("-" + "-".join(extra) if extra else "")
