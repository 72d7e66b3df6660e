"""What an MCAP log holds (``mountcal inspect``): topics, types, counts, rates — from the message
indexes when the file has them, else by one scan of the records."""

from __future__ import annotations

import os
from contextlib import closing

import numpy as np
from numpy.typing import NDArray

from mountcal.core import budget
from mountcal.io.mcap.chunks import chunk_units, open_log, read_message_index
from mountcal.io.mcap.read import schema_fields
from mountcal.io.mcap.records import (
    OP_CHUNK,
    OP_MESSAGE,
    OP_MESSAGE_INDEX,
    RECORD_HEAD,
    Corrupt,
    Log,
    McapChannel,
    damaged,
    record_field,
    walk_file,
)
from mountcal.io.samples import LogSummary, Stream


@budget.scoped
def inspect_mcap(path: str | os.PathLike[str]) -> LogSummary:
    """What an MCAP log holds: topics, types, message counts, rates and duration.

    Counts and duration come from the summary's statistics record, per-topic rates from the
    chunks' message indexes: no chunk is decompressed, so damage inside a chunk goes unnoticed
    here (:func:`read_mcap` finds it). Only a log without indexes is scanned in full.

    Returns
    -------
    LogSummary
        One :class:`~mountcal.io.samples.Stream` per topic: ``kind`` is the schema name,
        ``rate_hz`` = (count − 1) / (last − first log time), ``fields`` the top-level fields of a
        ``ros2msg`` schema. ``duration_s`` spans the first to the last message's log time.
    """
    log = open_log(path)
    try:
        spans = _spans_from_indexes(log) or _spans_from_scan(log)
    except Corrupt as err:
        raise damaged(log.where, str(err)) from err
    finally:
        log.file.close()
    streams = tuple(_stream(log, topic, channels, spans) for topic, channels in log.topics().items())
    stats = log.statistics
    if stats is not None and stats.message_count:
        duration = (stats.end_ns - stats.start_ns) * 1e-9
    else:
        seen = [s for s in spans.values() if s[0]]
        duration = (max(s[2] for s in seen) - min(s[1] for s in seen)) * 1e-9 if seen else 0.0
    return LogSummary(source=log.where, format="mcap", duration_s=duration, streams=streams)


def _stream(log: Log, topic: str, channels: list[McapChannel], spans: _Spans) -> Stream:
    """One topic's line of :func:`inspect_mcap` (its channels merged)."""
    ids = [ch.id for ch in channels if ch.id in spans]
    if log.statistics is not None:
        count = sum(log.statistics.channel_counts.get(ch.id, 0) for ch in channels)
    else:
        count = sum(spans[i][0] for i in ids)
    first = min((spans[i][1] for i in ids), default=0)
    last = max((spans[i][2] for i in ids), default=0)
    rate = (count - 1) / ((last - first) * 1e-9) if count > 1 and last > first else 0.0
    schema = log.schemas.get(channels[0].schema_id)
    fields: tuple[str, ...] = ()
    if schema is not None and schema.encoding == "ros2msg":
        fields = tuple(name for _, name in schema_fields(schema.data.decode(errors="replace")))
    return Stream(topic, log.type_name(channels[0]), count, rate, fields)


_Spans = dict[int, tuple[int, int, int]]  # channel id → (count, first, last log time in ns)


def _merge(spans: _Spans, channel_id: int, log_ns: NDArray[np.uint64]) -> None:
    if log_ns.size:
        n, first, last = spans.get(channel_id, (0, 2**64, 0))
        spans[channel_id] = (n + log_ns.size, min(first, int(log_ns.min())), max(last, int(log_ns.max())))


def _spans_from_indexes(log: Log) -> _Spans | None:
    """Per-channel spans from the message index records, or None when a chunk has none."""
    spans: _Spans = {}
    chunk_indexed = True
    for opcode, at, length in walk_file(log):
        if opcode == OP_MESSAGE:
            return None
        if opcode == OP_CHUNK:
            if not chunk_indexed:
                return None
            chunk_indexed = False
        elif opcode == OP_MESSAGE_INDEX:
            chunk_indexed = True
            channel_id, pairs = read_message_index(log, at, length)
            _merge(spans, channel_id, pairs[:, 0])
    return spans if chunk_indexed else None


def _spans_from_scan(log: Log) -> _Spans:
    """Per-channel spans by decompressing and walking every chunk."""
    spans: _Spans = {}
    with closing(chunk_units(log, None)) as units:
        for unit in units:
            channel = record_field(unit.data, unit.messages, RECORD_HEAD.size, "<u2")
            log_ns = record_field(unit.data, unit.messages, RECORD_HEAD.size + 6, "<u8")
            del unit  # not held while the next chunk is read
            for channel_id in np.unique(channel).tolist():
                _merge(spans, channel_id, log_ns[channel == channel_id])
    return spans


def topic_spans(path: str | os.PathLike[str]) -> dict[str, tuple[int, int, int]]:
    """Per topic of an MCAP log: message count, first and last log time (ns), as :func:`inspect_mcap` finds them."""
    log = open_log(path)
    try:
        spans = _spans_from_indexes(log) or _spans_from_scan(log)
    except Corrupt as err:
        raise damaged(log.where, str(err)) from err
    finally:
        log.file.close()
    out = {}
    for topic, channels in log.topics().items():
        seen = [spans[ch.id] for ch in channels if ch.id in spans]
        if seen:
            out[topic] = (sum(s[0] for s in seen), min(s[1] for s in seen), max(s[2] for s in seen))
    return out
