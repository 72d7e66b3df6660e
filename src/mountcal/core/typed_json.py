"""Frozen dataclasses to JSON and back, and their JSON Schema, all derived from the fields.

One converter for every typed part of a result: :func:`to_plain` writes a dataclass as an object
with one key per field; :func:`from_plain` rebuilds it from the field types, refusing a value of
the wrong type, a missing required field or an unknown key (a tampered or foreign document);
:func:`schema_of` states the same rules as JSON Schema. The supported field types are what the
result uses: ``bool``, ``int``, ``float``, ``str``, ``None`` unions, ``tuple[X, ...]``, fixed
tuples, ``dict[str, X]``, ``Literal``, ``Any`` and nested dataclasses.
"""

from __future__ import annotations

import dataclasses
import math
import types
from typing import Any, Literal, Union, get_args, get_origin, get_type_hints

from mountcal.core.ranges import QUANTITIES

MAX_NUMBER = QUANTITIES["result_value"].hi  # a square (a variance, a χ²) of it stays finite
_SCALARS: dict[type, str] = {bool: "boolean", int: "integer", float: "number", str: "string", type(None): "null"}


def to_plain(value: Any) -> Any:
    """A dataclass (or a tuple, dict, number of them) as plain JSON types; a non-finite float as None."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: to_plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, tuple | list):
        return [to_plain(v) for v in value]
    if isinstance(value, dict):
        return {str(k): to_plain(v) for k, v in value.items()}
    if hasattr(value, "item") and callable(value.item):  # a numpy scalar
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def from_plain(tp: Any, data: Any, path: str = "") -> Any:
    """The value of type ``tp`` that :func:`to_plain` wrote as ``data``.

    Raises
    ------
    ValueError
        Naming the dotted path of the first value that does not fit its type.
    """
    if tp is Any:
        return data
    origin, args = get_origin(tp), get_args(tp)
    if origin is Literal:
        if data not in args or isinstance(data, bool):
            raise ValueError(f"{path} = {_short(data)} (expected one of {', '.join(map(repr, args))})")
        return data
    if origin in (Union, types.UnionType):
        if data is None and type(None) in args:
            return None
        options = [a for a in args if a is not type(None)]
        for option in options[:-1]:
            try:
                return from_plain(option, data, path)
            except ValueError:
                continue
        return from_plain(options[-1], data, path)
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        return _dataclass(tp, data, path)
    if origin is tuple:
        if not isinstance(data, list):
            raise ValueError(f"{path or 'value'} = {_short(data)} (expected a list)")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(from_plain(args[0], v, f"{path}.{i}") for i, v in enumerate(data))
        if len(data) != len(args):
            raise ValueError(f"{path} has {len(data)} items (expected {len(args)})")
        return tuple(from_plain(a, v, f"{path}.{i}") for i, (a, v) in enumerate(zip(args, data, strict=True)))
    if origin is dict:
        if not isinstance(data, dict):
            raise ValueError(f"{path or 'value'} = {_short(data)} (expected an object)")
        return {str(k): from_plain(args[1], v, f"{path}.{k}") for k, v in data.items()}
    if tp is float and isinstance(data, int | float) and not isinstance(data, bool):
        if not (math.isfinite(data) and abs(data) <= MAX_NUMBER):
            raise ValueError(f"{path} = {data!r} (expected a finite number within ±{MAX_NUMBER:g})")
        return float(data)
    if tp in _SCALARS and tp is not float and isinstance(data, tp) and (tp is bool or not isinstance(data, bool)):
        return data
    raise ValueError(f"{path or 'value'} = {_short(data)} (expected {_SCALARS.get(tp, str(tp))})")


def _dataclass(tp: type, data: Any, path: str) -> Any:
    if not isinstance(data, dict):
        raise ValueError(f"{path or 'value'} = {_short(data)} (expected an object)")
    hints = get_type_hints(tp)
    names = {f.name for f in dataclasses.fields(tp)}
    unknown = sorted(set(data) - names)
    if unknown:
        raise ValueError(f"{path or 'object'} has unknown keys {', '.join(unknown)}")
    kwargs: dict[str, Any] = {}
    for f in dataclasses.fields(tp):
        if f.name in data:
            kwargs[f.name] = from_plain(hints[f.name], data[f.name], f"{path}.{f.name}".lstrip("."))
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ValueError(f"{path or 'object'} lacks the key {f.name}")
    return tp(**kwargs)


def schema_of(tp: Any, defs: dict[str, Any]) -> dict[str, Any]:
    """The JSON Schema of values of type ``tp``; dataclasses go to ``defs`` (referenced by name)."""
    if tp is Any:
        return {}
    origin, args = get_origin(tp), get_args(tp)
    if origin is Literal:
        return {"enum": list(args)}
    if origin in (Union, types.UnionType):
        parts = [schema_of(a, defs) for a in args]
        if all(set(p) == {"type"} for p in parts):
            return {"type": [p["type"] for p in parts]}
        return {"anyOf": parts}
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        if tp.__name__ not in defs:
            defs[tp.__name__] = {}  # a placeholder: a recursive type refers to itself
            hints = get_type_hints(tp)
            fields = dataclasses.fields(tp)
            defs[tp.__name__] = {
                "type": "object",
                "description": (tp.__doc__ or "").strip().split("\n")[0],
                "properties": {f.name: schema_of(hints[f.name], defs) for f in fields},
                "required": [
                    f.name
                    for f in fields
                    if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
                ],
                "additionalProperties": False,
            }
        return {"$ref": f"#/$defs/{tp.__name__}"}
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return {"type": "array", "items": schema_of(args[0], defs)}
        items = [schema_of(a, defs) for a in args]
        return {"type": "array", "prefixItems": items, "minItems": len(items), "maxItems": len(items)}
    if origin is dict:
        return {"type": "object", "additionalProperties": schema_of(args[1], defs)}
    if tp in _SCALARS:
        return {"type": _SCALARS[tp]}
    raise TypeError(f"no JSON Schema for {tp!r}")


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


__all__ = ["from_plain", "schema_of", "to_plain"]
