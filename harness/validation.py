"""Typed input files: one base model, shared constrained types, and the ONE translation of
pydantic's validation errors into the project's one-line :class:`~harness.errors.InputError`.

Every input format of the harness (``scene.toml``, a sweep's ``sweep.json``, the nightly
matrix, the accuracy matrix) is a pydantic v2 model derived from :class:`InputModel`:
``extra="forbid"`` refuses unknown keys, ``strict=True`` refuses a string where a number
belongs (an integer is still a valid number), and ``allow_inf_nan=False`` refuses NaN and
infinities. Rules that a type cannot express are ``model_validator``\\ s that raise
:class:`FieldProblem` with the path of the field they blame.

:func:`validate` runs a model and turns the first problem into one line::

    <file>: <field path>: <problem>; <fix>

The field path comes from pydantic's ``loc`` with the tags of discriminated unions
dropped (``mesh.radius``, not ``mesh.sphere.radius``) and list indices in brackets
(``lights[0].intensity``). The fix comes from the field's ``examples`` (which also
reach the JSON Schema, for editors) or from what the type expects.
"""

from __future__ import annotations

import dataclasses
import json
import math
import tomllib
import types
import typing
from pathlib import Path
from typing import Annotated, Literal

import annotated_types
from pydantic import BaseModel, ConfigDict, Field, Tag, ValidationError, WrapValidator

from harness.errors import InputError

__all__ = ["InputModel", "FieldProblem", "Vec3", "Positive", "NonNegative", "ImageSize", "SweepSize", "MAX_IMAGE_SIZE",
           "read_toml", "read_json", "validate", "input_error", "field_names", "INPUT_CONFIG"]

#: Largest image width or height anywhere (scene cameras, ``--size``, matrices).
MAX_IMAGE_SIZE = 8192


class InputModel(BaseModel):
    """Base of every input-file model: unknown keys, wrong types, NaN and infinity are refused."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)


#: The same settings for the ``pydantic.dataclasses`` of inputs (a sweep's configuration).
INPUT_CONFIG = InputModel.model_config


class FieldProblem(ValueError):
    """A rule a type cannot express failed; raised inside a validator.

    ``path`` is relative to the model whose validator raises it: a dotted string
    (``"camera.origin"``), or a tuple of keys and list indices (``("lights", 0, "position")``);
    ``()`` blames the model itself.
    """

    def __init__(self, path, problem, fix=None):
        if isinstance(path, str):
            path = tuple(p for p in path.split(".") if p)
        self.path, self.problem, self.fix = tuple(path), str(problem), fix
        super().__init__(self.problem)


# --------------------------------------------------------------------------- shared types

Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]
Positive = Annotated[float, Field(gt=0)]
NonNegative = Annotated[float, Field(ge=0)]
ImageSize = Annotated[int, Field(ge=1, le=MAX_IMAGE_SIZE)]


def _small_or_size(value, handler):
    # "small" passes as it is; anything else must be a [W, H] size, and its errors are the list's own
    return "small" if value == "small" else handler(value)


#: The image size of a sweep or a matrix: ``[W, H]``, or ``"small"`` (each scene at its committed
#: small size, :func:`harness.reference.committed.small_size`).
SweepSize = Annotated[list[ImageSize], Field(min_length=2, max_length=2), WrapValidator(_small_or_size)]


# --------------------------------------------------------------------------- reading files

def _check_file(path, what, fix):
    path = Path(path)
    if path.is_dir():
        raise InputError(path, "file", f"is a folder, not {what}", fix)
    if not path.is_file():
        raise InputError(path, "file", "does not exist", fix)
    return path


def _text(path, what, fix):
    path = _check_file(path, what, fix)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise InputError(path, "file", f"cannot be read ({exc.strerror})", "check its permissions") from exc
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(path, "file", f"is not UTF-8 text (byte 0x{raw[exc.start]:02x} at offset {exc.start})",
                         "save it as UTF-8") from exc


def _parsed(path, what, fix, loads, error, syntax):
    text = _text(path, what, fix)
    try:
        return loads(text)
    except error as exc:
        raise InputError(path, syntax.lower(), f"is not valid {syntax} ({exc})", "fix the syntax") from exc


def read_toml(path, what="a TOML file", fix="give the right file"):
    """The table of a UTF-8 TOML file, or an InputError naming what is wrong with the file."""
    return _parsed(path, what, fix, tomllib.loads, tomllib.TOMLDecodeError, "TOML")


def read_json(path, what="a JSON file", fix="give the right file"):
    """The object of a UTF-8 JSON file, or an InputError naming what is wrong with the file."""
    return _parsed(path, what, fix, json.loads, json.JSONDecodeError, "JSON")


# --------------------------------------------------------------------------- validation

def validate(model, data, where, context=None, syntax="toml"):
    """``model`` validated from ``data`` (a dict read from ``where``); an InputError if it is not valid.

    ``model`` is an :class:`InputModel` subclass or a pydantic dataclass; ``context`` reaches
    validators as ``info.context`` (the scene folder, for files named in a scene);
    ``syntax`` (``toml`` or ``json``) is how the fix writes an example value.
    """
    try:
        if isinstance(model, type) and issubclass(model, BaseModel):
            return model.model_validate(data, context=context)
        if not isinstance(data, dict):
            raise InputError(where, "file", f"must hold a table of settings, got {_show(data)}",
                             "give the file a sweep wrote")
        return model(**data)
    except ValidationError as exc:
        raise input_error(where, exc, model, syntax) from None


def input_error(where, exc, model, syntax="toml"):
    """The first problem of a pydantic ``ValidationError`` as one :class:`InputError` line."""
    groups = {}
    for err in exc.errors(include_url=False):
        problem = err.get("ctx", {}).get("error") if err["type"] == "value_error" else None
        loc = tuple(err["loc"]) + (problem.path if isinstance(problem, FieldProblem) else ())
        place = _walk(model, loc)
        if err["type"] in ("union_tag_invalid", "union_tag_not_found"):
            key = err["ctx"]["discriminator"].strip("'")
            place = dataclasses.replace(place, path=f"{place.path}.{key}" if place.path else key)
        groups.setdefault(place.path, []).append((err, problem, place))
    # Within the first field that failed, the deepest path is the most specific (a union's
    # branches all fail, and the branch that got furthest says what was meant).
    first = next(iter(groups))
    top = _top(first)
    path = max((p for p in groups if _top(p) == top), key=lambda p: p.count(".") + p.count("["))
    items = groups[path]
    problem, fix = _describe(path, items, syntax)
    more = sum(len(v) > 0 for v in groups.values()) - 1
    if more:
        fix = f"{fix} ({more} more problem{'s' if more > 1 else ''} in this file)"
    return InputError(where, path or "file", problem, fix)


def _top(path):
    return path.split(".")[0].split("[")[0]


# --------------------------------------------------------------------------- the loc walker

def _strip(ann):
    """``Annotated[T, ...]`` -> (T, metadata); ``Optional[T]`` -> T."""
    meta = []
    while True:
        origin = typing.get_origin(ann)
        if origin is Annotated:
            args = typing.get_args(ann)
            ann, meta = args[0], meta + list(args[1:])
            continue
        if origin in (typing.Union, types.UnionType):
            args = [a for a in typing.get_args(ann) if a is not type(None)]
            if len(args) == 1:
                ann = args[0]
                continue
        return ann, meta


def _fields(cls):
    if isinstance(cls, type) and issubclass(cls, BaseModel):
        return cls.model_fields
    return getattr(cls, "__pydantic_fields__", None)


def _tag(cls):
    """The ``Literal`` value of a union member's ``kind`` (its discriminator), or of its ``method``
    (the parameter products of ``harness.runs.params``, optional for SSLPV's), if any."""
    fields = _fields(cls) or {}
    for name in ("kind", "method"):
        if name in fields:
            ann, _ = _strip(fields[name].annotation)
            args = typing.get_args(ann)
            if typing.get_origin(ann) is Literal and args:
                return args[0]
    return None


@dataclasses.dataclass(frozen=True)
class _Place:
    """Where a pydantic ``loc`` points: the printable path and what the model says about it."""

    path: str
    parent: object = None        # the model class that holds the last named key
    info: object = None          # its FieldInfo (None for an unknown key or a list item)
    ann: object = None           # the annotation of what the loc points at
    example: object = None       # FieldInfo of the last named field (examples for the fix)
    key: str = ""                # that field's name


def _annotation(info):
    return Annotated[(info.annotation, *info.metadata)] if info.metadata else info.annotation


def _walk(model, loc):
    """pydantic ``loc`` -> :class:`_Place`: union tags dropped, list indices in brackets."""
    parts, parent, info, ann, example, key = [], None, None, model, None, ""

    def named(name, owner, field):
        nonlocal parent, info, ann, example, key
        parent, info, key = owner, field, str(name)
        example = field
        ann = _annotation(field) if field is not None else None
        parts.append(("." if parts else "") + str(name))

    for item in loc:
        ann, _ = _strip(ann)
        if isinstance(item, int):
            parts.append(f"[{item}]")
            args, origin = typing.get_args(ann), typing.get_origin(ann)
            ann = args[-1] if origin in (list, tuple, set, dict) and args else None
            info = None
            continue
        fields = _fields(ann) if isinstance(ann, type) else None
        if fields is not None:
            named(item, ann, fields.get(item))      # None: an unknown key
            continue
        origin = typing.get_origin(ann)
        if origin in (typing.Union, types.UnionType):
            tagged = [base for base, meta in map(_strip, typing.get_args(ann))
                      if any(isinstance(m, Tag) and m.tag == item for m in meta)]
            if tagged:                              # a callable discriminator's Tag: that member
                ann = tagged[0]
                continue
            members = [_strip(a)[0] for a in typing.get_args(ann)]
            match = [m for m in members if isinstance(m, type) and (getattr(m, "__name__", None) == item
                                                                      or _tag(m) == item)]
            if match:
                ann = match[0]
                continue
            owners = [m for m in members if item in (_fields(m) or {})]
            if owners:                              # a validator's path without the tag: a member's field
                named(item, owners[0], _fields(owners[0])[item])
            continue                                # a member's label ('int', "literal[...]"): no part
        if origin is dict:
            parts.append(("." if parts else "") + str(item))
            ann, info = (typing.get_args(ann)[1] if typing.get_args(ann) else None), None
            continue
        if not any(ch in str(item) for ch in "[]()"):   # not a label of pydantic's ('function-after[...]')
            parts.append(("." if parts else "") + str(item))
            ann, info = None, None
    return _Place("".join(parts), parent, info, ann, example, key)


# --------------------------------------------------------------------------- wording

_EXPECTED = {
    "float_type": "a number", "float_parsing": "a number", "int_type": "an integer", "int_parsing": "an integer",
    "int_from_float": "an integer", "string_type": "a string", "bool_type": "true or false",
    "bool_parsing": "true or false", "list_type": "a list", "tuple_type": "a list", "set_type": "a list",
    "dict_type": "a table", "model_type": "a table", "model_attributes_type": "a table",
    "dataclass_type": "a table", "literal_error": None, "finite_number": "a finite number",
}


def _show(value):
    if isinstance(value, dict):
        return "a table" if value else "an empty table"
    text = json.dumps(value) if isinstance(value, (list, str, bool, int, float)) and not (
        isinstance(value, float) and not math.isfinite(value)) else repr(value)
    if isinstance(value, float) and not math.isfinite(value):
        text = str(value)
    return text if len(text) <= 48 else text[:45] + "..."


def _bounds(meta):
    """``(0, 180)``-style interval of annotated_types constraints, or None."""
    lo = hi = None
    lo_open = hi_open = False
    for m in meta:
        if isinstance(m, annotated_types.Gt):
            lo, lo_open = m.gt, True
        elif isinstance(m, annotated_types.Ge):
            lo, lo_open = m.ge, False
        elif isinstance(m, annotated_types.Lt):
            hi, hi_open = m.lt, True
        elif isinstance(m, annotated_types.Le):
            hi, hi_open = m.le, False
        elif hasattr(m, "metadata"):                 # a FieldInfo inside Annotated
            inner = _bounds(m.metadata)
            if inner:
                return inner
    if lo is None and hi is None:
        return None
    lo, hi = _num(lo), _num(hi)
    if hi is None:
        return f"{'>' if lo_open else '>='} {lo}"
    if lo is None:
        return f"{'<' if hi_open else '<='} {hi}"
    return f"in {'(' if lo_open else '['}{lo}, {hi}{')' if hi_open else ']'}"


def _num(x):
    return None if x is None else str(x) if isinstance(x, int) else f"{x:g}"


def _lengths(meta):
    lo = hi = None
    for m in meta:
        if isinstance(m, annotated_types.MinLen):
            lo = m.min_length
        elif isinstance(m, annotated_types.MaxLen):
            hi = m.max_length
        elif hasattr(m, "metadata"):
            a, b = _lengths(m.metadata)
            lo, hi = lo if a is None else a, hi if b is None else b
    return lo, hi


def _format(value, syntax):
    """A value as it is written in a TOML file (inline tables) or a JSON one."""
    if syntax == "json":
        return json.dumps(value)
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {_format(v, syntax)}" for k, v in value.items()) + "}"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_format(v, syntax) for v in value) + "]"
    return json.dumps(value)


def _example(place, syntax):
    """``write e.g. key = value`` from the field's ``examples``, or None."""
    examples = getattr(place.example, "examples", None) if place.example is not None else None
    if not examples or not place.key:
        return None
    if syntax == "json":
        return f'write e.g. "{place.key}": {_format(examples[0], syntax)}'
    return f"write e.g. {place.key} = {_format(examples[0], syntax)}"


def _table_fix(place, syntax):
    """How to write a table that is missing or of the wrong type."""
    if syntax == "json" or not place.key:
        return None
    if place.path.endswith("]"):
        return f"write each entry as a [[{place.key}]] table"
    return f"write it as a [{place.path}] table" if "." not in place.path else None


def _describe(path, items, syntax="toml"):
    """(problem, fix) for the errors that pydantic gave at one path (several: union branches)."""
    err, problem, place = items[0]
    kind, value, ann, info = err["type"], err.get("input"), place.ann, place.info
    example = _example(place, syntax)
    if isinstance(problem, FieldProblem):
        return problem.problem, problem.fix or example or "change the value"
    if kind in ("value_error", "assertion_error"):
        return str(err.get("ctx", {}).get("error", err["msg"])), example or "change the value"
    words = _words(ann, meta_extra=list(info.metadata) if info is not None else [])
    is_table = words in ("a table", "tables")
    if kind in ("missing", "missing_argument"):
        return "is missing", (_table_fix(place, syntax) if is_table else None) or example or "add it"
    if kind in ("extra_forbidden", "unexpected_keyword_argument"):
        allowed = sorted(_fields(place.parent) or {}) if place.parent is not None else []
        return "is not a known field", (f"use only: {', '.join(allowed)}" if allowed else "remove it")
    if kind == "union_tag_invalid":
        tags = err["ctx"]["expected_tags"].replace("'", "")
        return f"unknown kind {err['ctx']['tag']!r}", f"use one of: {tags}"
    if kind == "union_tag_not_found":
        tags = _union_tags(ann)
        return "is missing", f"add kind = one of: {tags}" if tags else "add kind"
    if kind == "finite_number":                     # NaN or an infinity where a number belongs
        return f"must be a finite number, got {_show(value)}", example or "give a finite number"
    if kind in _EXPECTED or kind in ("greater_than", "greater_than_equal", "less_than", "less_than_equal"):
        if len(items) > 1 and typing.get_origin(_strip(ann)[0]) in (typing.Union, types.UnionType):
            words = " or ".join(dict.fromkeys(_words(a) for a in typing.get_args(_strip(ann)[0])))
        if kind == "literal_error" and not words:
            words = "one of " + err["ctx"]["expected"].replace("'", '"')
        fix = (_table_fix(place, syntax) if is_table else None) or example or _type_fix(_EXPECTED.get(kind) or "")
        return f"must be {words or _EXPECTED.get(kind) or 'in range'}, got {_show(value)}", fix
    if kind in ("too_short", "too_long"):
        lo, hi = _lengths((list(info.metadata) if info is not None else []) + _strip(ann)[1])
        n = err["ctx"].get("actual_length")
        return (f"must be {words or 'a list of ' + str(lo or hi) + ' items'}, got {n} item{'s' if n != 1 else ''}",
                example or "change the list")
    if kind == "string_too_short":
        return "must not be empty", example or "give a value"
    return err["msg"][0].lower() + err["msg"][1:], example or "change the value"


_NOUNS = {int: ("an integer", "integers"), float: ("a number", "numbers"), str: ("a string", "strings"),
          bool: ("true or false", "true/false values")}


def _words(ann, meta_extra=(), plural=False):
    """What a type accepts, in words: ``a list of 2 integers in [3, 1024]``."""
    if ann is None:
        return ""
    base, meta = _strip(ann)
    meta = list(meta_extra) + meta
    origin = typing.get_origin(base)
    bounds = _bounds(meta)
    if base in _NOUNS:
        noun = _NOUNS[base][1 if plural else 0]
        if base is str and _lengths(meta)[0]:
            noun = "non-empty " + noun if plural else "a non-empty string"
        return noun + (f" {bounds}" if bounds and base in (int, float) else "")
    if origin is Literal:
        return "one of " + ", ".join(json.dumps(a) for a in typing.get_args(base))
    if origin in (list, tuple, set):
        args = typing.get_args(base)
        lo, hi = _lengths(meta)
        item = _words(args[0], plural=True) if args else "items"
        if lo == 1 and hi is None:
            return f"a non-empty list of {item}" if item else "a non-empty list"
        count = f"{lo} " if lo is not None and lo == hi else f"at least {lo} " if lo else ""
        return f"a list of {count}{item}" if item else "a list"
    if origin is dict:
        return "a table"
    if origin in (typing.Union, types.UnionType):
        return " or ".join(dict.fromkeys(w for w in (_words(a, plural=plural) for a in typing.get_args(base)) if w))
    if isinstance(base, type) and _fields(base) is not None:
        return "tables" if plural else "a table"
    return ""


def _ctx_bound(err):
    ctx = err.get("ctx", {})
    for key, sym in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<=")):
        if key in ctx:
            return f"{sym} {ctx[key]}"
    return "in range"


def _type_fix(expected):
    return {"a number": "give a number", "an integer": "give an integer", "a string": "give a string in quotes",
            "a list": "give a list in brackets", "a table": "give a table", "true or false": "write true or false",
            "a finite number": "give a finite number"}.get(expected, "change the value")


def _union_tags(ann):
    ann, _ = _strip(ann) if ann is not None else (None, [])
    if typing.get_origin(ann) in (typing.Union, types.UnionType):
        tags = [_tag(_strip(a)[0]) for a in typing.get_args(ann)]
        return ", ".join(t for t in tags if t)
    return ""


def field_names(cls):
    """The field names of a model or pydantic dataclass (for messages and tests)."""
    if dataclasses.is_dataclass(cls):
        return [f.name for f in dataclasses.fields(cls)]
    return list(_fields(cls) or {})
