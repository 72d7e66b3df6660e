"""An MCAP log's topics with their message definitions (:class:`~mountcal.io.ros.topics.Topic`), and its
messages located a chunk at a time for the path every ROS container is read through
(:mod:`mountcal.io.ros.batches`): an MCAP log read with ``--field``, and the MCAP storage of a ROS 2 bag
folder (:mod:`mountcal.io.bag.ros2`)."""

from __future__ import annotations

from collections.abc import Generator, Sequence
from contextlib import closing
from dataclasses import replace
from pathlib import Path

import numpy as np

from mountcal.core.errors import InputError
from mountcal.io.frame import channel_rotated
from mountcal.io.mcap.chunks import chunk_units, open_log
from mountcal.io.mcap.records import MESSAGE_HEAD, RECORD_HEAD, Corrupt, Log, damaged, record_field
from mountcal.io.ros.batches import Batch, samples_of
from mountcal.io.ros.topics import Selection, Topic, choose_imu
from mountcal.io.ros.types import DefinitionError, Types, from_definition, standard
from mountcal.io.ros2.cdr import CdrError, cdr_rows
from mountcal.io.samples import Samples


def mcap_topics(log: Log) -> dict[str, Topic]:
    """An MCAP log's topics with the definitions of their schemas (``ros2msg`` or ``ros2idl``)."""
    out = {}
    for name, channels in log.topics().items():
        schema = log.schemas.get(channels[0].schema_id)
        type_name = log.type_name(channels[0])
        types: Types | None = None
        problem = "no schema"
        if schema is not None:
            try:
                if schema.encoding in ("ros2msg", "ros2idl") and schema.data:
                    types = from_definition(schema.data.decode(errors="replace"), schema.name, schema.encoding[4:])
                else:
                    types = standard(schema.name)
            except DefinitionError as err:
                problem = str(err)
        if any(c.message_encoding != "cdr" for c in channels):
            types, problem = None, f"messages encoded as {channels[0].message_encoding!r}, not CDR"
        counts = log.statistics.channel_counts if log.statistics is not None else None
        count = None if counts is None else sum(counts.get(c.id, 0) for c in channels)
        out[name] = Topic(name, type_name, tuple(c.id for c in channels), types, problem, count)
    return out


def read_mcap_topics(path: str | Path, *, topic: str | None, field: str | None) -> Samples:
    """An MCAP log read through message definitions (for ``--field``)."""
    log = open_log(path)
    try:
        topics = mcap_topics(log)
        samples = samples_of(
            log.where, topics, lambda sels: mcap_batches(log, sels), cdr=True, topic=topic, field=field
        )
        chosen = choose_imu(topics, log.where, topic, field).topic  # the topic samples_of read (metadata only)
        said = (channel_rotated(log.channels[i].metadata, chosen.name) for i in chosen.ids if i in log.channels)
        rotated = next((r for r in said if r is not None), None)
        return samples if rotated is None else replace(samples, rotated=rotated)
    except Corrupt as err:
        raise damaged(log.where, str(err)) from err
    finally:
        log.file.close()


def mcap_batches(
    log: Log, selections: Sequence[Selection], ids: dict[str, tuple[int, ...]] | None = None
) -> Generator[Batch, None, None]:
    """Blocks (MCAP chunks) of the selections' messages; ``ids`` gives each topic's channel ids in this
    file when they are not those of the selection (the files of a ROS 2 bag number channels apart)."""
    channel_ids = {s.topic.name: s.topic.ids if ids is None else ids.get(s.topic.name, ()) for s in selections}
    wanted = frozenset(i for v in channel_ids.values() for i in v)
    with closing(chunk_units(log, wanted)) as units:
        for unit in units:
            channel = record_field(unit.data, unit.messages, RECORD_HEAD.size, "<u2")
            for sel in selections:
                mine = np.isin(channel, channel_ids[sel.topic.name])
                if not mine.any():
                    continue
                at, size = unit.messages[mine], unit.lengths[mine] - MESSAGE_HEAD
                record = record_field(unit.data, at, RECORD_HEAD.size + 6, "<u8").astype(np.int64)
                try:
                    rows = cdr_rows(unit.data, at + RECORD_HEAD.size + MESSAGE_HEAD, size)
                except CdrError as err:
                    raise InputError(
                        log.where,
                        f"CDR messages on {sel.topic.name!r}",
                        f"{err}, in the {unit.what}",
                        err.fix or "Check the file.",
                    ) from err
                yield Batch(sel, rows, record, unit.what)
            del unit


__all__ = ["mcap_batches", "mcap_topics", "read_mcap_topics"]
