"""The plan of a sweep: its typed configuration (``sweep.json``), the configurations it expands to, and their step groups.

:class:`SweepConfig` is the resolved configuration of a sweep, read from the command line
(:func:`config_from_args`) or from the ``sweep.json`` a sweep wrote; :func:`expand_all`
turns its parameter products into configurations (each product may name its method,
:mod:`harness.runs.rivals`); :func:`group_configs` puts the configurations of one scene
that differ only in an integer ``steps`` into one step group (one propagation), largest
estimated cost (N^3 x largest step count) first. :func:`parse_size` and
:func:`resolve_scenes` read the ``--size`` and ``--scenes`` of every command.
"""

import dataclasses
import json
from typing import Annotated, Optional, Union

from pydantic import Discriminator, Field, Tag
from pydantic.dataclasses import dataclass as pydantic_dataclass

from harness.errors import InputError
from harness.runs.params import CLI_TO_FIELD, any_product_model, check_methods, check_products, parse_lists, \
    product_dict
from harness.validation import INPUT_CONFIG, MAX_IMAGE_SIZE, SweepSize, read_json, validate

from harness.scene import list_scenes, scene_path, unknown_scene_fix


def expand_all(params):
    """One product (dict of lists) or several (a list of them) -> their configurations, first seen first.

    A product may name its method (``{"method": "dipole", ...}``, :mod:`harness.runs.rivals`);
    SSLPV's configurations are SSLPVParams, another method's :class:`~harness.runs.rivals.MethodConfig`.
    """
    from harness.runs.rivals import expand_product, method_of

    products = params if isinstance(params, list) else [params]
    out, seen = [], set()
    for product in products:
        for p in expand_product(product):
            key = (method_of(p), tuple(sorted(p.as_dict().items())))
            if key not in seen:
                seen.add(key)
                out.append(p)
    return out

_PRODUCT = any_product_model("field")
# One product or a list of them, chosen by the value's shape, so that a bad value is reported
# from the one branch that was meant (a plain union reports both, and loses the field's path).
_PRODUCTS = Annotated[Union[Annotated[_PRODUCT, Tag("product")], Annotated[list[_PRODUCT], Tag("products")]],
                      Discriminator(lambda v: "products" if isinstance(v, list) else "product")]


@pydantic_dataclass(config=INPUT_CONFIG)
class SweepConfig:
    """The resolved configuration of a sweep; written beside its results as ``sweep.json``.

    A typed input (a pydantic dataclass): a ``sweep.json`` given to ``--config`` is checked
    field by field (unknown keys, wrong types, sizes beyond 8192 are refused with one line).
    """

    scenes: Annotated[list[Annotated[str, Field(min_length=1)]], Field(min_length=1)]  # names or folders
    params: _PRODUCTS                        # field -> list of values (or a list of such products; "method")
    out: str                                 # output folder
    store: str = ""                          # results store (default OUT/store.sqlite)
    size: Optional[SweepSize] = None         # [W, H]; "small": each scene's committed size; None: the scene's own
    kind: str = "sweep"                      # run kind in the store
    reference_target: Optional[Annotated[float, Field(gt=0, lt=1)]] = None  # median rel. SE asked of references

    def __post_init__(self):
        # Plain dicts again: sweep.json and the store's run config stay what they always were.
        self.params = ([product_dict(p) for p in self.params] if isinstance(self.params, list)
                       else product_dict(self.params))

    def to_json(self):
        return json.dumps(dataclasses.asdict(self), indent=2)

    @classmethod
    def from_file(cls, path):
        """A ``sweep.json``, validated: types by the dataclass, values by SSLPVParams, scenes by the suite."""
        data = read_json(path, "a sweep.json", "give the sweep.json a sweep wrote")
        if isinstance(data, dict):
            check_methods(data.get("params", {}), path, "params")
        cfg = validate(cls, data, path, syntax="json")
        check_products(cfg.params, path, "params", keys="field")
        resolve_scenes(cfg.scenes, where=path)
        return cfg


def parse_size(text):
    """``WxH`` -> ``[W, H]``; ``small`` -> ``"small"``; None -> None."""
    if text is None:
        return None
    if str(text).strip().lower() == "small":
        return "small"
    try:
        w, h = (int(x) for x in str(text).lower().split("x"))
        if w <= 0 or h <= 0:
            raise ValueError
    except ValueError:
        raise InputError("--size", "size", f"{text!r} is not WIDTHxHEIGHT", "write e.g. 128x128, or small") from None
    if w > MAX_IMAGE_SIZE or h > MAX_IMAGE_SIZE:
        raise InputError("--size", "size", f"{w}x{h} is larger than {MAX_IMAGE_SIZE}x{MAX_IMAGE_SIZE}",
                         f"give a width and height of at most {MAX_IMAGE_SIZE}, e.g. 128x128")
    return [w, h]


def resolve_scenes(spec, where="--scenes", field="scenes"):
    """Comma-separated names (or a list) -> validated list; unknown or empty gives one line.

    ``where``/``field`` name the source in the message: the flag, or a file and its key.
    """
    listed = not isinstance(spec, str)
    names = list(spec or list_scenes()) if listed else [s.strip() for s in spec.split(",")]
    if not names or any(not n for n in names):
        raise InputError(where, field, f"empty scene name in {spec!r}", "list scene names separated by commas")
    known = list_scenes()
    for i, n in enumerate(names):
        if not scene_path(n).is_file():
            raise InputError(where, f"{field}[{i}]" if listed and where != "--scenes" else field,
                             f"unknown scene {n!r}", unknown_scene_fix(n, known))
    return names


def config_from_args(args):
    if args.config:
        # The file holds the whole configuration: a flag beside it would be silently ignored.
        from harness.methods.params import all_cli_names

        given = [k for k in (*all_cli_names(), "method", "scenes", "size", "store")
                 if getattr(args, k, None) is not None]
        if given:
            flag = "--" + given[0].replace("_", "-")
            raise InputError(flag, given[0], "cannot be combined with --config (the file holds the whole sweep)",
                             "edit the sweep.json, or drop --config")
        cfg = SweepConfig.from_file(args.config)
        if args.out:
            cfg.out = str(args.out)
        return cfg
    if not args.out:
        raise InputError("--out", "out", "is required", "give an output folder, or --config sweep.json")
    lists = _params_from_args(args)
    return SweepConfig(scenes=resolve_scenes(args.scenes) if args.scenes else list_scenes(), params=lists,
                       out=str(args.out), store=str(args.store or ""), size=parse_size(args.size))


def _params_from_args(args):
    """The sweep's products: SSLPV's lists as before methods, or one product per method (``--method``)."""
    from harness.methods import parse_methods
    from harness.methods.params import all_cli_names, products

    methods = parse_methods(getattr(args, "method", None))
    values = {k: getattr(args, k, None) for k in all_cli_names()}
    if methods == ["sslpv"]:
        products(methods, values)                     # a flag of another method is refused here
        return parse_lists({k: values.get(k) for k in CLI_TO_FIELD})
    return products(methods, values)


def group_configs(todo, group=True):
    """``[(scene, params, key)]`` -> ``[(scene, base_params, [(steps, key), ...])]``: step groups.

    Configurations of one scene that share every parameter but an integer ``steps``
    form one group (step counts ascending); ``steps = auto`` and ``steady`` cannot share
    a propagation and each form a group of their own, as does every configuration
    when ``group`` is False (the per-configuration sweep). Groups come out largest
    estimated cost first (N^3 x largest step count), so the longest ones do not
    trail at the end of the sweep.
    """
    groups = {}
    for s, p, key in todo:
        d = p.as_dict()
        if group and isinstance(p.steps, int) and not isinstance(p.steps, bool):
            gkey = (s.name, json.dumps({k: v for k, v in d.items() if k != "steps"}, sort_keys=True, default=str))
        else:
            gkey = (s.name, key)
        groups.setdefault(gkey, (s, p, []))[2].append((p.steps, key))
    out = [(s, p, sorted(members, key=lambda m: (not isinstance(m[0], int), m[0] if isinstance(m[0], int) else 0)))
           for s, p, members in groups.values()]
    out.sort(key=_group_cost, reverse=True)      # stable: input order among equal costs
    return out


def _group_cost(g):
    _, p, members = g
    ks = [k if isinstance(k, int) else 64 for k, _ in members]
    return p.N ** 3 * max(max(ks), 1)
