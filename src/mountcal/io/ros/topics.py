"""Which topics of a recording to read: the IMU (named, or the only one), and the optional temperature,
GNSS fix, odometry and GNSS velocity; refusals name the option that would read the file.

The rules, the same for every ROS container (ROS 1 bag, ROS 2 bag folder, MCAP read with ``--field``);
each container lists its topics as :class:`Topic` (:func:`mountcal.io.bag.read.ros1_topics`,
:func:`mountcal.io.mcap.topics.mcap_topics`):

- **IMU**: ``--topic`` names it; without it, the only ``sensor_msgs/msg/Imu`` topic. ``--field``
  reads an Imu or a Vector3 carried inside another message (a driver's own message type); without
  ``--topic``, the only topic with such a field. A recording without an Imu topic but with a
  message carrying one is refused with the ``--topic … --field …`` that reads it.
- **Temperature, fix, odometry**: the only topic of that type; several of a type are left unread
  and the notes say so (no option chooses among them).
- **Speed** from one source, in order: odometry; a GNSS velocity (``TwistStamped``,
  ``TwistWithCovarianceStamped``; only with a GNSS fix in the recording, and not a command topic,
  ``cmd``); NMEA sentences (``nmea_msgs/msg/Sentence``, RMC and VTG, with their course as heading).
  The others are left unread and the notes say so.
"""

from __future__ import annotations

from dataclasses import dataclass

from mountcal.core.errors import InputError
from mountcal.core.option_names import option
from mountcal.io.ros.kinds import TYPES, Target, target
from mountcal.io.ros.types import (
    IMU,
    VECTOR3,
    VECTOR3_STAMPED,
    DefinitionError,
    Types,
    carriers,
)

AUX = ("temperature", "fix", "odom", "velocity", "nmea")
SPEED = ("odom", "velocity", "nmea")  # speed sources, in order of preference: one is read


@dataclass(frozen=True)
class Topic:
    """A topic of a recording: its type, its definitions (or why there are none) and its ids in the file."""

    name: str
    type_name: str
    ids: tuple[int, ...]
    types: Types | None
    problem: str = ""  # why there are no definitions
    count: int | None = None  # messages recorded (None: not known without reading them)

    def definitions(self, where: str) -> Types:
        if self.types is None:
            raise InputError(
                where,
                f"the definition of {self.type_name} (topic {self.name!r})",
                self.problem or "none stored in the recording",
                "Record with a ROS 2 release that stores message definitions (Iron or later), or read another topic.",
            )
        return self.types


@dataclass(frozen=True)
class Selection:
    """A topic to read, and what from it."""

    topic: Topic
    target: Target

    @property
    def kind(self) -> str:
        return self.target.kind


def listing(topics: dict[str, Topic]) -> str:
    items = [f"{t.name!r} ({t.type_name})" for t in topics.values()]
    return ", ".join(items) if items else "no topics at all"


def _carried(topics: dict[str, Topic]) -> list[tuple[Topic, str]]:
    """Fields carrying an Imu, or a Vector3 named as an acceleration: (topic, dotted field path)."""
    out = []
    for t in topics.values():
        if t.types is not None and t.type_name not in TYPES:
            out += [(t, ".".join(p)) for p in _candidates(t.types, t.type_name)]
    return out


def _candidates(types: Types, type_name: str) -> list[tuple[str, ...]]:
    imus = carriers(types, type_name, (IMU,))
    vectors = [
        p
        for p in carriers(types, type_name, (VECTOR3, VECTOR3_STAMPED))
        if "acc" in ".".join(p).lower() and not any(p[: len(i)] == i for i in imus)  # not inside an Imu listed
    ]
    return imus + vectors


def _read_with(carried: list[tuple[Topic, str]]) -> str:
    return "; ".join(f"{option('topic', t.name)} {option('field', f)}" for t, f in carried[:4])


def carried_hint(topics: dict[str, Topic]) -> str:
    """ " Read the Imu … a message carries: --topic … --field …" when some topic carries one, else ""."""
    carried = _carried(topics)
    return f" Read the Imu or Vector3 a message carries: {_read_with(carried)}." if carried else ""


def choose_imu(topics: dict[str, Topic], where: str, name: str | None, field: str | None) -> Selection:
    """The IMU selection (see the module doc), or an :class:`InputError` naming the option that reads it."""
    if name is not None:
        if name not in topics:
            raise InputError(
                where,
                f"a topic named {name!r}",
                f"topics {listing(topics)}",
                f"Pass one of them with {option('topic')}.",
            )
        return _imu_of(topics[name], where, field, topics)
    if field is not None:
        fitting = [t for t in topics.values() if t.types is not None and target(t.types, t.type_name, field)]
        if len(fitting) != 1:
            raise InputError(
                where,
                f"exactly one topic whose field {field!r} is an Imu or a Vector3",
                f"{len(fitting)}: " + ", ".join(repr(t.name) for t in fitting)
                if fitting
                else f"none; {listing(topics)}",
                f"Name the topic with {option('topic')}.",
            )
        return _imu_of(fitting[0], where, field, topics)
    imus = [t for t in topics.values() if t.type_name == "sensor_msgs/msg/Imu"]
    if len(imus) == 1:
        return _imu_of(imus[0], where, None, topics)
    carried = _carried(topics)
    if imus:
        found = f"{len(imus)}: " + ", ".join(repr(t.name) for t in imus)
        todo = f"Name the topic to read with {option('topic')}."
    else:
        found = f"none; the topics are {listing(topics)}"
        todo = (
            f"Read the Imu or Vector3 a message carries: {_read_with(carried)}."
            if carried
            else "Record an IMU topic, or export the accelerometer to CSV."
        )
    raise InputError(where, "exactly one sensor_msgs/msg/Imu topic", found, todo)


def _imu_of(topic: Topic, where: str, field: str | None, topics: dict[str, Topic]) -> Selection:
    types = topic.definitions(where)
    try:
        t = target(types, topic.type_name, field)
    except DefinitionError as err:
        raise InputError(where, f"a readable definition of {topic.type_name}", str(err), "Read another topic.") from err
    if t is not None and t.kind in ("imu", "acc"):
        return Selection(topic, t)
    carried = [(topic, ".".join(p)) for p in _candidates(types, topic.type_name)]
    if field is None:
        expected = f"topic {topic.name!r} of type sensor_msgs/msg/Imu"
        found = f"type {topic.type_name}"
    else:
        expected = (
            f"a field {field!r} of topic {topic.name!r} holding a sensor_msgs/msg/Imu or geometry_msgs/msg/Vector3"
        )
        found = f"no such Imu or Vector3 field in {topic.type_name}"
    if carried:
        todo = f"Read what it carries: {_read_with(carried)}."
    else:
        imus = [t.name for t in topics.values() if t.type_name == "sensor_msgs/msg/Imu"]
        todo = f"Pass an Imu topic with {option('topic')}" + (
            f": {', '.join(map(repr, imus))}." if imus else "; the recording has none."
        )
    raise InputError(where, expected, found, todo)


def choose_aux(topics: dict[str, Topic], where: str, notes: list[str]) -> list[Selection]:
    """The temperature, fix, odometry and velocity selections (each optional; see the module doc)."""
    by_kind: dict[str, list[Topic]] = {k: [] for k in AUX}
    for topic in topics.values():
        kind = TYPES.get(topic.type_name)
        if kind in by_kind and topic.count != 0:  # a topic that recorded nothing is no source
            by_kind[kind].append(topic)
    by_kind["velocity"] = [t for t in by_kind["velocity"] if "cmd" not in t.name.lower()] if by_kind["fix"] else []
    speed = next((k for k in SPEED if by_kind[k]), None)
    for kind in SPEED:
        if kind != speed and by_kind[kind]:
            notes.append(f"speed not taken from {', '.join(t.name for t in by_kind[kind])}: {speed} is read")
            by_kind[kind] = []
    out = []
    for kind, found in by_kind.items():
        if len(found) > 1:
            notes.append(f"{len(found)} {kind} topics ({', '.join(t.name for t in found)}): none read, none is chosen")
            continue
        if not found:
            continue
        topic = found[0]
        try:
            chosen = target(topic.definitions(where), topic.type_name)
        except (InputError, DefinitionError) as err:
            notes.append(f"{kind} topic {topic.name} not read: {err}")
            continue
        if chosen is not None:
            out.append(Selection(topic, chosen))
            if kind == "velocity":
                notes.append(f"speed from the GNSS velocity {topic.name} (horizontal magnitude, never negative)")
            if kind == "nmea":
                notes.append(f"speed and course from the NMEA sentences of {topic.name} (RMC, VTG)")
    return out


__all__ = [
    "AUX",
    "Selection",
    "Topic",
    "carried_hint",
    "choose_aux",
    "choose_imu",
    "listing",
]
