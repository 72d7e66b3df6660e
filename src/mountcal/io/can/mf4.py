"""MF4 (ASAM MDF 4 bus logging) read with asammdf into :class:`~mountcal.io.can.frames.CanFrames`, after
checking the blocks asammdf would trust (channel groups, variable-length signal data) and that the
file is whole (:mod:`mountcal.io.whole`).

Whole means: every block the file links to lies inside it (a finalised file states every block's
length), and an unfinalised file (``UnFinMF``: CANedge loggers, which write no length for the
last data block, so it runs to the end of the file) ends on a whole record — its data block holds
exactly the bytes of the records asammdf reads from it, and every frame's variable-length payload
follows it. A copy cut exactly between two records of an unfinalised file cannot be told from a
file the logger closed there: its samples say so (:func:`mountcal.io.whole.found_unverified`).
"""

from __future__ import annotations

import contextlib
import gc
import io
import logging
import math
import mmap
import struct
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import UTC
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mountcal.core import budget
from mountcal.core.errors import InputError
from mountcal.io.can.blf import DLC2LEN, le_field
from mountcal.io.can.frames import DATA_WIDTH, CanFrames, Filter, FloatArray, pad_payload
from mountcal.io.inputs import block_too_large, max_block_bytes
from mountcal.io.whole import Cut, found_cut, found_unverified, unreadable_part

# ---------------------------------------------------------------------------------------------
# MF4 (ASAM MDF 4 bus logging), read with asammdf


def _mf4_error(path: Path, found: str) -> InputError:
    return InputError(
        str(path),
        "a readable MDF4 bus log with a CAN_DataFrame channel group",
        found,
        "Check that the file is a finalised MF4 (CANedge: run mdf2finalized) and was copied completely.",
    )


@dataclass(frozen=True)
class _Layout:
    """What the block walk found: the file's size, whether it is unfinalised, its last block."""

    size: int
    unfinalised: bool  # "UnFinMF" with flags: the last data block's length was never written
    last_block: int  # address of the block that starts last (an unfinalised file's open data block)
    cut: Cut | None  # where a block the file links to runs past its end


def _open_mdf(path: Path) -> tuple[Any, _Layout]:
    from asammdf import MDF

    with path.open("rb") as f:
        ident = f.read(64)
    magic = ident[:8]
    if not magic.startswith((b"MDF", b"UnFinMF")):  # CANedge writes unfinalised files
        raise _mf4_error(path, f"no MDF file identification (the file starts {magic!r})")
    layout = _mf4_layout(path, ident)
    _check_mf4_channel_groups(path)
    try:
        with _asammdf_quiet():
            return MDF(path), layout
    except Exception as err:  # asammdf raises bare Exception, struct.error, ValueError, ... on bad files
        cause = err
    _release_quietly(cause)
    found = f"a file asammdf cannot open ({type(cause).__name__}: {cause})"
    if layout.cut is not None:  # allowed to read in part, but what is left cannot be opened
        raise unreadable_part(layout.cut, found) from cause
    raise _mf4_error(path, found) from cause


_ID_UNFINALISED_FLAGS = 60  # the identification block's standard flags of an unfinalised file (u16)
_MAX_WALKED_BLOCKS = 1 << 22


def _mf4_layout(path: Path, ident: bytes) -> _Layout:
    """Walk every block the file links to, from the header, reading block heads only; a block that
    runs past the end of the file is a cut (:func:`~mountcal.io.whole.found_cut`).

    A link is the address of a block (or 0): following all of them reaches every block of a sound
    file, metadata and data alike, without reading any data.
    """
    size = path.stat().st_size
    unfinalised = ident[:7] == b"UnFinMF" and len(ident) >= 64 and struct.unpack_from("<H", ident, 60)[0] != 0
    if size < 64 + 24:
        return _Layout(size, unfinalised, 0, None)  # asammdf says what is wrong with a file this short
    with path.open("rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as data:
        seen, todo, last = {64}, [(64, 0)], 64
        crossing: list[tuple[int, int, bytes, int]] = []  # (address, end, id, linked from)
        while todo:
            at, parent = todo.pop()
            if at + 24 > size:
                end, kind = at + 24, b"a block"
            else:
                kind = bytes(data[at : at + 4])
                length, n_links = struct.unpack_from("<QQ", data, at + 8)
                end = at + max(length, 24)
                if kind[:2] != b"##" or n_links > (1 << 20):
                    continue  # not a block head: damage, left to asammdf's checks
                last = max(last, at)
                links = struct.unpack_from(f"<{n_links}Q", data, at + 24) if at + 24 + 8 * n_links <= size else ()
                for link in links:
                    if link and link not in seen and link % 8 == 0:
                        if len(seen) >= _MAX_WALKED_BLOCKS:
                            raise _mf4_error(path, f"more than {_MAX_WALKED_BLOCKS} linked blocks")
                        seen.add(link)
                        todo.append((link, at))
            if end > size:
                crossing.append((at, end, kind, parent))
    # Past a cut, every block is gone: a block running past the end with whole blocks after it
    # states a damaged length (left to asammdf), it is not where the file was cut.
    intact = max((a for a in seen if a < size and a not in {c[0] for c in crossing}), default=0)
    crossing = [c for c in crossing if c[0] > intact or c[0] + 24 > size]
    cut = None
    if crossing:
        at, end, kind, parent = min(crossing)
        name = kind.decode("ascii", "replace").strip("#") + " block" if kind.startswith(b"##") else "block"
        if at < size:
            cut = found_cut(path, size, f"the rest of its {name} at byte {at} (which runs to byte {end})")
        else:
            cut = found_cut(path, size, f"its {name} at byte {at} (linked from the block at byte {parent})")
    return _Layout(size, unfinalised, last, cut)


_CG_DATA_BYTES = 32  # an MDF 4.x channel group's data section: record id, cycles, flags, sizes
_MAX_MF4_BLOCKS = 1 << 16


def _check_mf4_channel_groups(path: Path) -> None:
    """Refuse channel-group blocks that asammdf would misread into a huge allocation while opening.

    asammdf sizes its buffers from each channel group's record size, read at offsets that depend on
    the block's stated length: a damaged length (or record size) makes it allocate gigabytes before
    any of our checks run. A 4.x channel group is 24 + 8·links + 32 bytes; its record must fit the
    block limit. Walked from the header through the data-group and channel-group chains (small reads).
    """
    if path.stat().st_size < 64 + 24:
        return  # asammdf says what is wrong with a file this short
    seen: set[int] = set()

    def block(offset: int, kind: bytes) -> tuple[list[int], bytes] | None:
        if offset in seen or len(seen) > _MAX_MF4_BLOCKS:
            raise _mf4_error(path, f"a block chain that loops or never ends (at byte {offset})")
        seen.add(offset)
        f.seek(offset)
        head = f.read(24)
        if len(head) < 24 or head[:4] != kind:
            return None  # not this file's layout: left to asammdf's own checks
        length, n_links = struct.unpack_from("<QQ", head, 8)
        if kind == b"##CG" and length != 24 + 8 * n_links + _CG_DATA_BYTES:
            raise _mf4_error(
                path,
                f"a channel group stating {length} bytes at byte {offset} (with {n_links} links a "
                f"channel group is {24 + 8 * n_links + _CG_DATA_BYTES})",
            )
        rest = f.read(min(length, 4096) - 24) if length >= 24 else b""
        if len(rest) < 8 * n_links:
            raise _mf4_error(path, f"a {kind.decode()} block at byte {offset} cut short")
        return list(struct.unpack_from(f"<{n_links}Q", rest)), rest[8 * n_links :]

    with path.open("rb") as f:
        header = block(64, b"##HD")
        dg = header[0][0] if header and header[0] else 0
        while dg:
            data_group = block(dg, b"##DG")
            if data_group is None or len(data_group[0]) < 2:
                return
            cg = data_group[0][1]
            while cg:
                group = block(cg, b"##CG")
                if group is None or len(group[1]) < _CG_DATA_BYTES:
                    return
                data_bytes, inval_bytes = struct.unpack_from("<II", group[1], 24)
                if data_bytes + inval_bytes > max_block_bytes():
                    raise block_too_large(
                        str(path),
                        f"an MF4 record (channel group at byte {cg})",
                        f"{data_bytes + inval_bytes} bytes per record",
                    )
                cg = group[0][0] if group[0] else 0
            dg = data_group[0][0]


@contextmanager
def _asammdf_quiet() -> Iterator[None]:
    """asammdf's logger silenced: on a damaged file it logs tracebacks of errors it recovers
    from (its own bus-logging decoding, which these raw frames do not use), and finalising an
    unfinalised file prints the traceback of an error before raising it (to stdout, which is
    mountcal's answer's): what cannot be read raises, and becomes an InputError here."""
    logger = logging.getLogger("asammdf")
    level = logger.level
    logger.setLevel(logging.CRITICAL + 1)
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            yield
    finally:
        logger.setLevel(level)


def _release_quietly(err: BaseException) -> None:
    """Free the half-built MDF object a failed ``MDF()`` leaves in the traceback, now.

    Its ``__del__`` fails (no ``_file`` attribute yet) and Python would print that as an ignored
    exception at some later garbage collection; here it happens under a hook that drops just that.
    """
    previous = sys.unraisablehook

    def hook(unraisable: Any) -> None:
        if not (isinstance(unraisable.exc_value, AttributeError) and "MDF" in repr(unraisable.object)):
            previous(unraisable)

    sys.unraisablehook = hook
    try:
        err.__traceback__ = None
        gc.collect()
    finally:
        sys.unraisablehook = previous


def _mf4_can_groups(mdf: Any) -> list[int]:
    """Indices of the channel groups holding CAN data frames."""
    return [
        i
        for i, group in enumerate(mdf.groups)
        if group.channel_group.cycles_nr and any(ch.name == "CAN_DataFrame" for ch in group.channels)
    ]


def _mf4_records(
    path: Path, mdf: Any, group: int, start: float, keep: Filter, max_frames: int, total: int
) -> Iterator[CanFrames]:
    """One group's first ``total`` frames (its whole ones), a record range at a time."""
    conversions = _mf4_conversions(mdf, group)
    for offset in range(0, total, max_frames):
        count = min(max_frames, total - offset)
        try:
            with _asammdf_quiet():
                sig = mdf.get("CAN_DataFrame", group=group, record_offset=offset, record_count=count, raw=True)
            table = _mf4_table(sig.samples, np.asarray(sig.timestamps, np.float64) + start, keep, conversions, path)
        except Exception as err:  # asammdf reports damaged data blocks with assorted exceptions
            raise _mf4_error(path, f"unreadable records from {offset} ({type(err).__name__}: {err})") from err
        yield table


# the CAN_DataFrame fields whose value is a number we use (not DataBytes, read as bytes)
_MF4_NUMERIC = ("BusChannel", "ID", "IDE", "DLC", "DataLength")


def _mf4_conversions(mdf: Any, group: int) -> dict[str, Any]:
    """The conversions of a group's numeric CAN_DataFrame fields, by field name.

    A field's value is its raw value through its conversion. CANedge firmware 01.07 and later
    relies on it: one channel group per bus and id kind, with ``BusChannel`` and ``IDE`` stored as
    0-bit channels whose value is the constant of a linear conversion (the raw "value" of a 0-bit
    channel is only the record index). Raw values without a conversion are the values.
    """
    out = {}
    for channel in mdf.groups[group].channels:
        field = str(channel.name).removeprefix("CAN_DataFrame.")
        if field in _MF4_NUMERIC and channel.conversion is not None:
            out[field] = channel.conversion
    return out


def _mf4_converted(values: NDArray[Any], conversion: Any, field: str, path: Path) -> NDArray[Any]:
    """``values`` through an asammdf conversion; a conversion to text is refused."""
    if conversion is None:
        return values
    out = np.asarray(conversion.convert(values))
    if out.dtype.kind not in "biuf":
        raise _mf4_error(path, f"CAN_DataFrame.{field} converted to {out.dtype} values, not numbers")
    return out


def _mf4_table(rec: NDArray[Any], t_s: FloatArray, keep: Filter, conversions: dict[str, Any], path: Path) -> CanFrames:
    """A CAN_DataFrame record array (raw values) as CanFrames: numeric fields through their
    conversions, as python-can's MF4Reader reads them; fields missing from the file take defaults."""
    names = set(rec.dtype.names or ())
    n = rec.shape[0]

    def column(name: str, default: int) -> NDArray[Any]:
        key = f"CAN_DataFrame.{name}"
        if key not in names:
            return np.full(n, default)
        return _mf4_converted(np.asarray(rec[key]), conversions.get(name), name, path)

    raw_id = column("ID", 0).astype(np.uint32)
    channel = column("BusChannel", -1).astype(np.int64)
    mask = keep.mask(raw_id & 0x1FFFFFFF, channel)
    index = np.arange(n) if mask is None else np.flatnonzero(mask)
    payload = _mf4_payload(rec["CAN_DataFrame.DataBytes"][index])
    length = column("DataLength", -1)[index].astype(np.int64)
    length = np.where(length < 0, DLC2LEN[column("DLC", 8)[index].astype(np.int64) & 0x0F], length)
    ide = column("IDE", -1)[index]
    ident = raw_id[index] & 0x1FFFFFFF
    return CanFrames(
        t_s[index],
        channel[index],
        ident.astype(np.uint32),
        np.where(ide < 0, ident > 0x7FF, ide != 0),
        length.astype(np.uint8),
        pad_payload(payload, length),
    )


def _mf4_payload(data: NDArray[Any]) -> NDArray[np.uint8]:
    """DataBytes as a 2-D uint8 array (variable-length records come as an object array)."""
    if data.dtype != object:
        return np.asarray(data, np.uint8).reshape(data.shape[0], math.prod(data.shape[1:]))
    out = np.zeros((data.shape[0], DATA_WIDTH), np.uint8)
    for row, value in enumerate(data):
        raw = np.frombuffer(bytes(value), np.uint8)[:DATA_WIDTH]
        out[row, : raw.shape[0]] = raw
    return out


HD_LOCAL_TIME = 1  # MDF 4 hd_time_flags bit 0: the start time is the recorder's local time, its zone not recorded
HD_FLAGS_AT = 64 + 24 + 6 * 8 + 8 + 2 + 2  # the HD block (at 64): header, six links, start ns, tz and DST minutes


def start_s(header: Any) -> float:
    """The measurement's start in s since the Unix epoch, as asammdf dates it (to the microsecond, as python-can's
    MF4Reader reads it): a UTC header's start, or where the header is flagged local time, the recorder's wall
    clock read as UTC (:func:`local_time_header`).

    Not ``header.start_time.timestamp()`` alone: asammdf returns a local-time start as a naive datetime, whose
    ``timestamp()`` takes the zone of the machine reading it — the same file would start hours apart on two
    machines.
    """
    start = header.start_time
    return float((start if start.tzinfo is not None else start.replace(tzinfo=UTC)).timestamp())


def local_time_header(path: Path) -> bool:
    """Whether an MDF 4 file's header says its start time is local time of an unrecorded zone (read from the
    HD block's flags, without opening the file with asammdf; False for MDF 3 or a file too short to say)."""
    with path.open("rb") as f:
        head = f.read(HD_FLAGS_AT + 1)
    if len(head) <= HD_FLAGS_AT or head[64:68] != b"##HD":
        return False
    return bool(head[HD_FLAGS_AT] & HD_LOCAL_TIME)


def iter_mf4(path: Path, keep: Filter, max_frames: int) -> Iterator[CanFrames]:
    mdf, layout = _open_mdf(path)
    try:
        groups = _mf4_can_groups(mdf)
        if not groups and not any(any(c.name == "CAN_DataFrame" for c in g.channels) for g in mdf.groups):
            raise _mf4_error(path, "no CAN_DataFrame channel group (not a bus log)")
        whole, values = {}, {}
        for g in groups:
            _check_mf4_blocks(path, mdf.groups[g])
            whole[g], values[g] = _check_mf4_vlsd(path, mdf, g, layout)
        if layout.unfinalised and all(whole[g] == mdf.groups[g].channel_group.cycles_nr for g in groups):
            _check_unfinalised_end(path, mdf, layout, values)
        start = start_s(mdf.header)
        sources = [_mf4_records(path, mdf, g, start, keep, max_frames, whole[g]) for g in groups]
        if len(sources) == 1:
            yield from sources[0]
        elif sources:  # CAN frames split over several channel groups: merge them in time
            yield from _merge_by_time([(c for c in s if len(c)) for s in sources])
    finally:
        mdf.close()


def _check_mf4_blocks(path: Path, group: Any) -> None:
    """Refuse a data block stating more than the block limit before asammdf inflates it, and a
    channel group stating more record bytes than its data blocks hold (a damaged record size or
    count: asammdf would allocate what it states)."""
    total = 0
    for block in group.get_data_blocks():
        if block.original_size > max_block_bytes():
            what = f"an MF4 data block (at byte {block.address})"
            raise block_too_large(str(path), what, f"one stating {block.original_size} bytes")
        if block.compressed_size and block.compressed_size != block.original_size:  # a DZ block
            budget.inflate(int(block.compressed_size), int(block.original_size), str(path), "the MF4 data blocks")
        total += int(block.original_size)
    cg = group.channel_group
    record = int(cg.samples_byte_nr) + int(cg.invalidation_bytes_nr)
    if int(cg.cycles_nr) * record > total:
        found = f"a channel group stating {cg.cycles_nr} records of {record} bytes, with {total} bytes of record data"
        raise _mf4_error(path, found)


_VLSD = 1  # cn_type of a variable-length signal data channel (CANedge: DataBytes)
_VlsdStats = list[tuple[int, int] | None]  # bytes and values of each variable-length channel of a group


def _check_mf4_vlsd(path: Path, mdf: Any, index: int, layout: _Layout) -> tuple[int, _VlsdStats]:
    """Refuse variable-length data whose records point outside it, before asammdf reads it; return
    how many of the group's records are whole (all of them, but in a cut unfinalised file), and the
    bytes and values of each variable-length channel (None where its values do not follow each other).

    asammdf's C ``extract`` copies each value at the offset its record states without a bounds
    check: a damaged offset or length would make it read past its buffer (a segfault). A sound
    file has each record's offset, ascending, at a 4-byte length and that many bytes inside the
    channel's signal data. In an unfinalised file the last records may point past it: the file
    was cut between a frame and its payload, or inside the payload (a cut, not damage); only the
    records before them are read.
    """
    group = mdf.groups[index]
    whole = int(group.channel_group.cycles_nr)
    stats: _VlsdStats = []
    for ch_nr, channel in enumerate(group.channels):
        if channel.channel_type != _VLSD:
            continue
        for block in group.get_signal_data_blocks(ch_nr):
            if block.original_size > max_block_bytes():
                what = f"an MF4 signal data block (at byte {block.address})"
                raise block_too_large(str(path), what, f"one stating {block.original_size} bytes")
            if block.compressed_size and block.compressed_size != block.original_size:
                budget.inflate(int(block.compressed_size), int(block.original_size), str(path), "the MF4 data blocks")
        try:
            with _asammdf_quiet():
                data, offsets = _mf4_vlsd_arrays(mdf._mdf, group, ch_nr)  # the MDF4 object under MDF
        except Exception as err:  # asammdf reports damaged data blocks with assorted exceptions
            raise _mf4_error(path, f"unreadable {channel.name} ({type(err).__name__}: {err})") from err
        ends = _value_ends(data, offsets)
        stats.append((data.shape[0], offsets.shape[0]) if int(ends.max(initial=0)) == data.shape[0] else None)
        if not offsets.shape[0]:
            continue
        name = f"{channel.name} (channel group {index})"
        size = data.shape[0]
        if layout.unfinalised:
            offsets = offsets[: _whole_values(path, data, offsets, name, layout)]
            whole = min(whole, offsets.shape[0])
        outside = np.flatnonzero(offsets > size - 4) if size >= 4 else np.arange(offsets.shape[0])
        if outside.shape[0]:
            k = int(outside[0])
            raise _mf4_error(path, f"{name}: record {k} points to byte {offsets[k]} of {size} bytes of signal data")
        starts = offsets.astype(np.int64)
        ends = starts + 4 + le_field(data, starts, "<u4").astype(np.int64)
        beyond = np.flatnonzero(ends > size)
        if beyond.shape[0]:
            k = int(beyond[0])
            raise _mf4_error(path, f"{name}: record {k}'s value ends at byte {ends[k]} of {size} bytes of signal data")
        # asammdf reads a record range's values from the data between its first and last offsets
        descending = np.flatnonzero(starts[1:] < starts[:-1])
        if descending.shape[0]:
            k = int(descending[0]) + 1
            raise _mf4_error(path, f"{name}: record {k} points back, to byte {starts[k]} after {starts[k - 1]}")
    return whole, stats


def _value_ends(data: NDArray[np.uint8], offsets: NDArray[np.uint64]) -> NDArray[np.int64]:
    """Where each variable-length value ends (its 4-byte length and bytes); past the data where its
    length is not there to read."""
    size = data.shape[0]
    starts = offsets.astype(np.int64)  # an offset beyond 2⁶³ (a corrupt file) turns negative: outside too
    inside = (starts >= 0) & (starts <= size - 4)
    lengths = le_field(data, np.where(inside, starts, 0), "<u4").astype(np.int64)
    return np.where(inside, starts + 4 + lengths, size + 1)


def _whole_values(path: Path, data: NDArray[np.uint8], offsets: NDArray[np.uint64], name: str, layout: _Layout) -> int:
    """How many leading records of an unfinalised file have their value in the signal data; the
    records after them (a trailing run only) are the cut (:func:`~mountcal.io.whole.found_cut`)."""
    beyond = _value_ends(data, offsets) > data.shape[0]
    if not beyond[-1]:
        return int(offsets.shape[0])
    first = int(offsets.shape[0]) - int(np.argmin(beyond[::-1])) if not beyond.all() else 0
    if beyond[first:].all() and not beyond[:first].any():
        found_cut(path, layout.size, f"the payload of its last frame record ({name}, record {first})")
        return first
    return int(offsets.shape[0])  # not a trailing run: damage, refused by the checks that follow


def _check_unfinalised_end(path: Path, mdf: Any, layout: _Layout, values: dict[int, _VlsdStats]) -> None:
    """An unfinalised file's open data block (its last block, running to the end of the file) must
    hold exactly the bytes of the records asammdf found in it: record ids, fixed records, and the
    variable-length values with their lengths. More bytes are a record cut off at the end.

    ``values`` holds the variable-length channels' bytes and values of the CAN groups, measured
    already; those of other groups with records (LIN, error frames with payloads) are read here.
    Only a data group whose data link is that one DT block is checked (CANedge's layout); a
    file that ends on a whole record is recorded as unverifiable (:func:`~mountcal.io.whole.found_unverified`).
    """
    by_group: dict[int, list[tuple[int, Any]]] = {}
    for index, group in enumerate(mdf.groups):
        by_group.setdefault(int(group.data_group.address), []).append((index, group))
    for groups in by_group.values():
        data_group = groups[0][1].data_group
        at = int(data_group.data_block_addr or 0)
        if at != layout.last_block or _block_id(path, at) != b"##DT":
            continue
        held = layout.size - (at + 24)
        rid = int(data_group.record_id_len)
        used = 0
        for index, group in groups:
            cg = group.channel_group
            if cg.flags & _CG_VLSD or not cg.cycles_nr:
                continue
            used += int(cg.cycles_nr) * (rid + int(cg.samples_byte_nr) + int(cg.invalidation_bytes_nr))
            for stat in values[index] if index in values else _vlsd_stats(mdf, group):
                if stat is None:
                    found_unverified(path, _UNVERIFIED + " (its payloads are not stored one after the other)")
                    return
                used += rid * stat[1] + stat[0]
        if held > used:
            found_cut(path, layout.size, f"the end of its last record ({held - used} bytes of one are there)")
            return
    found_unverified(path, _UNVERIFIED)


_CG_VLSD = 1  # cg_flags bit: the channel group holds variable-length signal data
_UNVERIFIED = (
    "an unfinalised MF4 (its logger writes no length for the last data block): it ends on a whole "
    "record, but a copy cut exactly between two records cannot be told from the whole file"
)


def _vlsd_stats(mdf: Any, group: Any) -> _VlsdStats:
    """The bytes and values of each variable-length channel of a group (None: not one after the other)."""
    out: _VlsdStats = []
    for ch_nr, channel in enumerate(group.channels):
        if channel.channel_type == _VLSD:
            with _asammdf_quiet():
                data, offsets = _mf4_vlsd_arrays(mdf._mdf, group, ch_nr)
            ends = _value_ends(data, offsets)
            out.append((data.shape[0], offsets.shape[0]) if int(ends.max(initial=0)) == data.shape[0] else None)
    return out


def _block_id(path: Path, at: int) -> bytes:
    with path.open("rb") as f:
        f.seek(at)
        return f.read(4)


def _mf4_vlsd_arrays(mdf4: Any, group: Any, ch_nr: int) -> tuple[NDArray[np.uint8], NDArray[np.uint64]]:
    """A VLSD channel's signal data, and the offset into it stated by each record (read a data
    fragment at a time, 8 bytes per record kept)."""
    data = np.frombuffer(mdf4._load_signal_data(group, ch_nr), np.uint8)
    record = int(group.channel_group.samples_byte_nr) + int(group.channel_group.invalidation_bytes_nr)
    at = int(group.channels[ch_nr].byte_offset)
    parts = [np.empty(0, "<u8")]
    for fragment in mdf4._load_data(group):
        rows = np.frombuffer(fragment.data, np.uint8)
        rows = rows[: rows.shape[0] // record * record].reshape(-1, record)
        parts.append(np.ascontiguousarray(rows[:, at : at + 8]).view("<u8").ravel())
    return data, np.concatenate(parts)


def _merge_by_time(sources: list[Iterator[CanFrames]]) -> Iterator[CanFrames]:
    """Merge time-ordered chunk streams into one time-ordered stream, holding one chunk per source."""
    heads: list[CanFrames | None] = [next(s, None) for s in sources]
    while any(h is not None for h in heads):
        # everything up to the earliest last-time of the held chunks is complete
        held = [k for k, h in enumerate(heads) if h is not None]
        first = held[int(np.argmin([float(heads[k].t_s[-1]) for k in held]))]  # type: ignore[union-attr]
        horizon = float(heads[first].t_s[-1])  # type: ignore[union-attr]
        out = []
        for k, head in enumerate(heads):
            if head is None:
                continue
            # the chunk that sets the horizon goes whole: progress even where damaged times are unsorted
            cut = len(head) if k == first else int(np.searchsorted(head.t_s, horizon, side="right"))
            out.append(head.take(slice(0, cut)))
            rest = head.take(slice(cut, None))
            heads[k] = rest if len(rest) else next(sources[k], None)
        merged = CanFrames.concat(out)
        yield merged.take(np.argsort(merged.t_s, kind="stable"))
