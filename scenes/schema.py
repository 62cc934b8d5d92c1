"""One typed schema per structure: a frozen dataclass is both the data and its validator.

Every user-facing input of the suite (scene spec sections, family ranges, `compare` settings,
planner settings, dataset manifests) is a dataclass; `load(cls, data, where=...)` checks plain data
(parsed YAML or JSON, CLI values) against the dataclass's annotations with pydantic and returns
the dataclass itself, as Drake's `yaml_load_typed` does. The rules are the same everywhere:

- scalars are strict: no "3" for 3, no `true` for 1, no 1.5 for an int; floats are finite;
- lists are read as tuples; unknown fields are refused; a field without a default is required;
- bounds go in the annotation (`Annotated[float, Field(gt=0)]`, or the aliases below);
- a check that spans fields goes in the dataclass's `__post_init__`, raising `FieldError`.

A bad value is one `SuiteError` line: `WHERE field 'a.b' = VALUE (item I): what is allowed`, or
`WHERE field 'a.b' is missing`, or `WHERE field 'a.b' is unknown; allowed: [...]`.
"""

from __future__ import annotations

import dataclasses
import functools
import re
import types
import typing
from typing import Annotated, Any, Literal, Union

import pydantic
from pydantic import AfterValidator, AllowInfNan, Field, Strict

from scenes.errors import SuiteError

Pos = Annotated[float, Field(gt=0)]
NonNeg = Annotated[float, Field(ge=0)]
Unit = Annotated[float, Field(ge=0, le=1)]
Vec2 = tuple[float, float]
Vec3 = tuple[float, float, float]
PosVec3 = tuple[Pos, Pos, Pos]
Rgba = tuple[Unit, Unit, Unit, Unit]
PosInt = Annotated[int, Field(gt=0)]
NonNegInt = Annotated[int, Field(ge=0)]


class FieldError(ValueError):
    """A value refused by a check across fields (`__post_init__`): `field` names the bad one."""

    def __init__(self, field: str, message: str):
        super().__init__(message)
        self.field = field


_SCALARS = {float: (Strict(), AllowInfNan(False)), int: (Strict(),), bool: (Strict(),), str: (Strict(),)}


def _strict(tp: Any) -> Any:
    """The annotation `tp` with strict scalars, and every dataclass in it replaced by its model."""
    origin = typing.get_origin(tp)
    if origin is Annotated:
        base, *meta = typing.get_args(tp)
        return Annotated[(_strict(base), *meta)]
    if tp in _SCALARS:
        return Annotated[(tp, *_SCALARS[tp])]
    if dataclasses.is_dataclass(tp):
        return Annotated[_model(tp), AfterValidator(functools.partial(_instance, tp))]
    if origin is Literal or origin is None:
        return tp
    args = tuple(a if a is Ellipsis else _strict(a) for a in typing.get_args(tp))
    if origin is types.UnionType or origin is Union:
        return Union[args]
    return origin[args]


@functools.cache
def _model(cls: type) -> type[pydantic.BaseModel]:
    """A pydantic model of the dataclass's init fields (defaults kept; nothing else allowed)."""
    hints = typing.get_type_hints(cls, include_extras=True)
    fields: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        if f.default is not dataclasses.MISSING:
            default = Field(default=f.default)
        elif f.default_factory is not dataclasses.MISSING:
            default = Field(default_factory=f.default_factory)
        else:
            default = ...
        fields[f.name] = (_strict(hints[f.name]), default)
    return pydantic.create_model(f"{cls.__name__}Schema", __config__=pydantic.ConfigDict(extra="forbid",
                                 arbitrary_types_allowed=True), **fields)


def _instance(cls: type, model: pydantic.BaseModel) -> Any:
    values = {name: getattr(model, name) for name in type(model).model_fields}
    try:
        return cls(**values)
    except SuiteError as exc:  # a planner's own check in __post_init__
        raise ValueError(str(exc)) from None


@functools.cache
def _adapter(tp: Any) -> pydantic.TypeAdapter:
    return pydantic.TypeAdapter(_strict(tp))


def load(tp: Any, data: Any, *, where: str = "", at: str = "", ignore_unknown: bool = False) -> Any:
    """`data` checked against the annotation `tp` (usually a dataclass) and returned as a `tp`.

    Args:
        where: the start of an error line (e.g. "scene spec FILE: ").
        at: where `data` sits in a larger document ("table"), named before its fields in errors.
        ignore_unknown: top-level fields the dataclass does not name are left out instead of
            refused (for records whose other fields are kept as they are).

    Raises:
        SuiteError: one line naming the first bad field, its value and what is allowed.
    """
    if ignore_unknown and dataclasses.is_dataclass(tp) and isinstance(data, dict):
        names = set(fields_of(tp))
        data = {k: v for k, v in data.items() if k in names}
    try:
        return _adapter(tp).validate_python(data)
    except pydantic.ValidationError as exc:
        raise SuiteError(error_line(exc, data, tp, where=where, at=at)) from None


def refusal(tp: Any, value: Any) -> str | None:
    """Why `value` is not a `tp` ("input should be greater than 0"), or None if it is one (for a
    value that comes without a field name, such as a command-line flag's)."""
    try:
        _adapter(tp).validate_python(value)
    except pydantic.ValidationError as exc:
        return _words(exc.errors(include_url=False)[0]["msg"])
    return None


def json_schema(tp: Any) -> dict[str, Any]:
    """The JSON Schema (2020-12) of what `load(tp, ...)` accepts, with the fields' descriptions."""
    return _adapter(tp).json_schema()


def fields_of(tp: Any) -> list[str]:
    """The names `load` accepts for the dataclass `tp`."""
    return [f.name for f in dataclasses.fields(tp) if f.init]


def error_line(exc: pydantic.ValidationError, data: Any, tp: Any, *, where: str, at: str = "") -> str:
    """The first validation error as one line: the field, its value and what is allowed."""
    err = exc.errors(include_url=False)[0]
    loc = list(err["loc"])
    cause = (err.get("ctx") or {}).get("error")
    if isinstance(cause, FieldError):
        loc.append(cause.field)
    loc = [x for x in loc if not (isinstance(x, str) and x.startswith(("function-after[", "tagged-union[")))]
    items = []
    while loc and isinstance(loc[-1], int):  # an element of a list: name the list, show it whole
        items.insert(0, str(loc.pop()))
    field = ".".join([at] * bool(at) + [str(x) for x in loc]) or "(top level)"
    if err["type"] in ("extra_forbidden", "unexpected_keyword_argument"):
        return f"{where}field '{field}' is unknown; allowed: {_allowed_at(tp, loc[:-1])}"
    if err["type"] in ("missing", "missing_keyword_argument") and not items:
        return f"{where}field '{field}' is missing"
    value = _lookup(data, loc)
    shown = repr(value)
    if len(shown) > 100:  # a long list (a path): its start names it well enough
        shown = shown[:96] + " ..."
    if err["type"] == "missing":
        msg = f"item {'.'.join(items)} is missing: the list is too short"
    else:
        msg = _words(err["msg"])
    item = f" (item {'.'.join(items)})" if items and err["type"] != "missing" else ""
    return f"{where}field '{field}' = {shown}{item}: {msg}"


def _words(msg: str) -> str:
    """pydantic's message in the suite's words: a list is a list, a check's own text as written,
    lower case first."""
    msg = re.sub(r" or instance of \w+", "", msg).removeprefix("Value error, ")
    msg = msg.replace("a valid tuple", "a list").replace("Tuple should", "the list should")
    return msg[0].lower() + msg[1:]


def _lookup(data: Any, loc: list) -> Any:
    for key in loc:
        if isinstance(data, dict):
            data = data.get(key)
        elif isinstance(data, (list, tuple)) and isinstance(key, int) and key < len(data):
            data = data[key]
        else:
            return None
    return data


def _allowed_at(tp: Any, loc: list) -> list[str]:
    """The field names allowed in the dataclass at `loc` below `tp` (the names of a mapping's
    entries, such as cameras.poses.top, are skipped over)."""
    keys = list(loc)
    cls = _dataclass_in(tp)
    while keys and cls is not None:
        key = keys.pop(0)
        hint = typing.get_type_hints(cls, include_extras=True).get(key)
        if hint is None:
            return []
        hint = _unwrap(hint)
        if typing.get_origin(hint) is dict:
            hint = typing.get_args(hint)[1]
            if keys:
                keys.pop(0)  # the entry's name
        cls = _dataclass_in(hint)
    return sorted(fields_of(cls)) if cls is not None and not keys else []


def _unwrap(tp: Any) -> Any:
    while typing.get_origin(tp) is Annotated:
        tp = typing.get_args(tp)[0]
    return tp


def _dataclass_in(tp: Any) -> type | None:
    tp = _unwrap(tp)
    if dataclasses.is_dataclass(tp):
        return tp
    return next((a for a in typing.get_args(tp) if dataclasses.is_dataclass(_unwrap(a))), None)
