"""Method parameters on the command line: ``--method dipole --gather dense,vertex --spacing 1,0.5`` -> configurations.

Every method declares its command-line names (:attr:`Method.cli`); a flag is given as a
comma-separated list (one value for ``render``) and converted to the field's type, and the
method's own dataclass validates each combination. A flag that belongs to none of the
selected methods is refused with one line naming the method it belongs to. A sweep *product*
is ``{"method": NAME, field: [values], ...}`` (``method`` absent means ``sslpv``, as in a
``sweep.json`` written before methods); :func:`expand` turns one into validated parameters,
cartesian, input order kept.
"""

from __future__ import annotations

import itertools

from harness.errors import InputError

from . import DEFAULT_METHOD, METHOD_NAMES, get_method

__all__ = ["convert", "flag", "all_cli_names", "owners", "parse_lists", "products", "expand", "params_from_cli",
           "product_method"]


def flag(cli_name):
    return "--" + cli_name.replace("_", "-")


def convert(cli_name, text, type_name):
    """One command-line value -> the field's type (an InputError names the flag)."""
    if type_name in ("bool", bool, "bool | None"):
        if text.lower() in ("true", "1", "yes", "on"):
            return True
        if text.lower() in ("false", "0", "no", "off"):
            return False
        raise InputError(flag(cli_name), cli_name, f"{text!r} is not true or false", "write true or false")
    if type_name == "int | str":                     # steps: a count, or a mode ('auto', 'steady')
        try:
            return int(text)
        except ValueError:
            return text
    kind = type_name.split(" | ")[0] if isinstance(type_name, str) else type_name
    try:
        if kind in ("int", int):
            return int(text)
        if kind in ("float", float):
            return float(text)
    except ValueError:
        integer = kind in ("int", int)
        raise InputError(flag(cli_name), cli_name, f"{text!r} is not a{'n integer' if integer else ' number'}",
                         f"write {'an integer, e.g. 32' if integer else 'a number, e.g. 0.5'}") from None
    return text


def all_cli_names():
    """Every command-line parameter name of every method, first seen first."""
    out = []
    for name in METHOD_NAMES:
        for c in get_method(name).cli:
            if c not in out:
                out.append(c)
    return out


def owners(cli_name):
    return [n for n in METHOD_NAMES if cli_name in get_method(n).cli]


def _items(cli_name, raw):
    items = [str(x) for x in raw] if isinstance(raw, (list, tuple)) else [x.strip() for x in str(raw).split(",")]
    if not items or any(x == "" for x in items):
        raise InputError(flag(cli_name), cli_name, f"empty value in {raw!r}", "give at least one value, separated by commas")
    return items


def parse_lists(method, values):
    """``{'grid': '16,32', ...}`` -> ``{'N': [16, 32]}``: the given flags of ``method``, typed."""
    m = get_method(method)
    types = m.field_types()
    out = {}
    for cli_name, field in m.cli.items():
        raw = values.get(cli_name)
        if raw is None:
            continue
        out[field] = [convert(cli_name, x, types[field]) for x in _items(cli_name, raw)]
    return out


def products(methods, values):
    """Sweep products for ``methods`` from command-line ``values`` (every method's flags; None when not given).

    Each method takes the flags that belong to it; a given flag that belongs to none of
    ``methods`` is an InputError naming its method. A method may split its lists into
    several products (the dipole rivals: one per gather, each with its own parameters).
    """
    given = [c for c, v in values.items() if v is not None and c in all_cli_names()]
    for c in given:
        if not any(c in get_method(m).cli for m in methods):
            own = owners(c)
            raise InputError(flag(c), c, f"is a parameter of {' and '.join(own)}, not of {', '.join(methods)}",
                             f"drop {flag(c)} or add {own[0]} to --method")
    out = []
    for m in methods:
        lists = parse_lists(m, values)
        for prod in get_method(m).split_products(lists):
            out.append({"method": m, **prod})
    return out


def product_method(product):
    """A product's method (``sslpv`` when it names none) and its field lists."""
    name = product.get("method", DEFAULT_METHOD)
    get_method(name)
    return name, {k: v for k, v in product.items() if k != "method"}


def expand(method, lists, base=None):
    """Cartesian product of parameter lists -> list of validated parameters (input order kept)."""
    m = get_method(method)
    base = dict(base or {})
    keys = list(lists)
    combos = itertools.product(*(lists[k] for k in keys)) if keys else [()]
    return [m.make_params(**dict(base, **dict(zip(keys, combo)))) for combo in combos]


def params_from_cli(method, values):
    """One validated parameters object of ``method`` from single command-line values (``render``)."""
    prods = products([method], values)
    for prod in prods:
        for field, vals in prod.items():
            if field != "method" and len(vals) != 1:
                cli = get_method(method).field_to_cli(field)
                raise InputError(flag(cli), cli, f"takes one value here, got {len(vals)}", "use 'sweep' for lists")
    if len(prods) != 1:
        raise InputError("--gather", "gather", "takes one value here", "use 'sweep' for lists")
    _, lists = product_method(prods[0])
    return get_method(method).make_params(**{k: v[0] for k, v in lists.items()})
