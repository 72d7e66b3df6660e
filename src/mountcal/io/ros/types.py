"""ROS message definitions as field trees, parsed by ``rosbags.typesys`` (ROS 1 ``.msg`` text, ROS 2
``ros2msg`` and ``ros2idl``), and the questions mountcal asks of them: what type sits at a field path,
and where in a message an Imu or a Vector3 is carried (for the message that names ``--field``).

A tree is ``rosbags``' *fielddefs*: type name → (constants, fields), each field ``(name, desc)`` with
``desc`` one of ``(BASE, (primitive, bound))``, ``(NAME, type)``, ``(ARRAY, (desc, length))`` or
``(SEQUENCE, (desc, bound))``. Type names are ROS 2 style (``sensor_msgs/msg/Imu``).
"""

from __future__ import annotations

from collections.abc import Iterator
from functools import cache
from typing import Any

from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, TypesysError, get_types_from_idl, get_types_from_msg, get_typestore
from rosbags.typesys.msg import normalize_msgtype

Types = dict[str, tuple[Any, list[tuple[str, Any]]]]
BASE, NAME, ARRAY, SEQUENCE = Nodetype.BASE, Nodetype.NAME, Nodetype.ARRAY, Nodetype.SEQUENCE
IMU = "sensor_msgs/msg/Imu"
VECTOR3 = "geometry_msgs/msg/Vector3"
VECTOR3_STAMPED = "geometry_msgs/msg/Vector3Stamped"


class DefinitionError(ValueError):
    """A message definition that does not parse, or lacks a type it uses; the text says which."""


def normalize(type_name: str) -> str:
    """``sensor_msgs/Imu`` (ROS 1) → ``sensor_msgs/msg/Imu``; ROS 2 names are kept."""
    return normalize_msgtype(type_name)


def _builtins() -> Types:
    return dict(get_typestore(Stores.EMPTY).fielddefs)  # builtin_interfaces Time and Duration (ROS 1 time)


def from_definition(text: str, type_name: str, encoding: str = "msg") -> Types:
    """The tree of ``type_name`` and every type it uses, from a definition as a bag or MCAP schema stores it.

    ``encoding`` is ``"msg"`` (ROS 1 ``message_definition``, ROS 2 ``ros2msg``: the message, then each
    dependency after a line of ``=``) or ``"idl"`` (``ros2idl``).

    Raises
    ------
    DefinitionError
        The text does not parse, or a type it uses is defined nowhere in it.
    """
    name = normalize(type_name)
    try:
        if encoding == "idl":
            parsed = _idl(text)
        else:
            parsed = get_types_from_msg(text, name)
    except (TypesysError, ValueError, KeyError, IndexError) as err:
        raise DefinitionError(f"a {encoding} definition of {name} that does not parse ({err})") from err
    types = {**_builtins(), **{k: (v[0], list(v[1])) for k, v in parsed.items()}}
    missing = sorted(set(used_types(types, name)) - set(types))
    if name not in types or missing:
        raise DefinitionError(f"a definition of {name} without {', '.join(missing) or name}")
    return types


def _idl(text: str) -> Any:
    separator = "=" * 80 + "\n"
    if text.startswith(f"{separator}IDL: "):
        out: dict[str, Any] = {}
        for part in text.split(separator)[1:]:
            out.update(get_types_from_idl(part.split("\n", 1)[1]))
        return out
    return get_types_from_idl(text)


@cache
def standard(type_name: str) -> Types:
    """The standard ROS 2 definition of a ``type_name`` (for a ROS 2 bag that stores no definitions).

    Raises
    ------
    DefinitionError
        ``type_name`` is not a standard ROS 2 message.
    """
    store = get_typestore(Stores.LATEST).fielddefs
    name = normalize(type_name)
    if name not in store:
        raise DefinitionError(f"no stored definition of {name}, and it is not a standard ROS 2 message")
    return {k: store[k] for k in {name, *used_types(store, name)} | set(_builtins())}


def used_types(types: Types, name: str) -> Iterator[str]:
    """Every message type ``name`` uses, depth first (missing ones included, so that callers see them)."""
    seen: set[str] = set()

    def walk(typ: str) -> Iterator[str]:
        for _, desc in types.get(typ, ((), []))[1]:
            for sub in _named(desc):
                if sub not in seen:
                    seen.add(sub)
                    yield sub
                    yield from walk(sub)

    yield from walk(name)


def _named(desc: Any) -> Iterator[str]:
    kind, detail = desc
    if kind == NAME:
        yield detail
    elif kind in (ARRAY, SEQUENCE):
        yield from _named(detail[0])


def type_at(types: Types, type_name: str, path: tuple[str, ...]) -> Any | None:
    """The field description at ``path`` inside ``type_name`` (None when there is no such field).

    A path crosses nested messages only (not arrays or sequences): ``("imu", "linear_acceleration")``.
    """
    desc: Any = (NAME, type_name)
    for name in path:
        if desc[0] != NAME:
            return None
        fields = dict(types[desc[1]][1])
        if name not in fields:
            return None
        desc = fields[name]
    return desc


def carriers(types: Types, type_name: str, wanted: tuple[str, ...], depth: int = 4) -> list[tuple[str, ...]]:
    """Paths (through nested messages, up to ``depth`` deep) of fields whose type is one of ``wanted``."""
    out: list[tuple[str, ...]] = []

    def walk(typ: str, prefix: tuple[str, ...]) -> None:
        if len(prefix) >= depth:
            return
        for name, desc in types.get(typ, ((), []))[1]:
            if desc[0] != NAME:
                continue
            path = (*prefix, name)
            if desc[1] in wanted:
                out.append(path)
            else:
                walk(desc[1], path)

    walk(type_name, ())
    return out


def has_stamp(types: Types, type_name: str, prefix: tuple[str, ...]) -> bool:
    """Whether the message at ``prefix`` has a ``header.stamp`` with ``sec`` and ``nanosec``."""
    return all(type_at(types, type_name, (*prefix, "header", "stamp", f)) is not None for f in ("sec", "nanosec"))


__all__ = [
    "IMU",
    "VECTOR3",
    "VECTOR3_STAMPED",
    "DefinitionError",
    "Types",
    "carriers",
    "from_definition",
    "has_stamp",
    "normalize",
    "standard",
    "type_at",
    "used_types",
]
