"""The base of the suite's typed records: a dataclass whose fields are named as the keys of the JSON
object it is read from and written as.

A record read from JSON (`from_json`) and written back (`to_json`) is the object it was, key order
included: a key the record's class does not name is kept in `extra`, and a field the object did not
have keeps its default and is written only once it is set. So a reader of an older file gets the
defaults of the fields added since, and a file read and rewritten (rescore) keeps what it held.
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar, TypeVar

R = TypeVar("R", bound="JsonRecord")


@dataclasses.dataclass(eq=False)
class JsonRecord:
    """Fields named as JSON keys, plus the keys this class does not name (`extra`) and the object's
    key order (`keys`). Records compare by their JSON."""

    #: keys of the object this class does not name (kept for the round trip)
    extra: dict[str, Any] = dataclasses.field(default_factory=dict, repr=False, kw_only=True)
    #: the object's keys in its order (empty for a record made in memory)
    keys: tuple[str, ...] = dataclasses.field(default=(), repr=False, kw_only=True)

    #: fields always written, even at their default (a subclass's required keys)
    ALWAYS_WRITTEN: ClassVar[tuple[str, ...]] = ()

    @classmethod
    def json_fields(cls) -> tuple[dataclasses.Field, ...]:
        return tuple(f for f in dataclasses.fields(cls) if f.name not in ("extra", "keys"))

    @classmethod
    def from_json(cls: type[R], obj: dict[str, Any]) -> R:
        """A record from one parsed JSON object (the caller checks the keys it requires)."""
        names = {f.name for f in cls.json_fields()}
        return cls(**{k: v for k, v in obj.items() if k in names},
                   extra={k: v for k, v in obj.items() if k not in names}, keys=tuple(obj))

    def to_json(self) -> dict[str, Any]:
        """The JSON object: the keys it was read with, in their order, then every field set since."""
        fields = self.json_fields()
        names = {f.name for f in fields}
        out: dict[str, Any] = {}
        for key in self.keys:
            out[key] = _plain(getattr(self, key)) if key in names else self.extra[key]
        for f in fields:
            if f.name in out:
                continue
            value = getattr(self, f.name)
            default = f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default
            if f.name in self.ALWAYS_WRITTEN or default is dataclasses.MISSING or value != default:
                out[f.name] = _plain(value)
        out.update((k, v) for k, v in self.extra.items() if k not in out)
        return out

    def with_(self: R, **changes: Any) -> R:
        """A copy with some fields changed (its dict fields copied, not shared)."""
        copied = {f.name: dict(v) for f in self.json_fields() if isinstance(v := getattr(self, f.name), dict)}
        return dataclasses.replace(self, **{**copied, **changes})

    def __eq__(self, other: object) -> bool:
        return type(other) is type(self) and self.to_json() == other.to_json()

    __hash__ = None  # type: ignore[assignment]  # mutable, compared by value


def _plain(value: Any) -> Any:
    """A field's JSON value: nested records as their JSON, tuples as lists."""
    if isinstance(value, JsonRecord):
        return value.to_json()
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value] if any(isinstance(v, JsonRecord) for v in value) else value
    return value
