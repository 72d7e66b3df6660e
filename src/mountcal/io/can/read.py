"""Accelerometer (and gyro) samples from a CAN log and a DBC: the signal mapping and the readers.

A *mapping* says which DBC signals hold the accelerometer axes, the optional gyro axes and the
auxiliary channels, in which units, on which channel, and how the device's axes map to the
right-handed sensor frame. It is a small TOML file (or the equivalent dict)::

    channel = 2                    # optional: CAN channel, python-can numbering
    axes = "x,y,z"                 # optional: sensor axis i = signed device axis, e.g. "-y,x,z";
                                   # a reflection ("x,-y,z") states a left-handed device (--axes alike)
    allow_left_handed = "reason"   # optional: why the device is left-handed (recorded with the map)
    valid = ["gnss_imu.ImuValid"]  # optional: frames whose validity signal is 0 are dropped

    [signals]                      # message.signal; the message by name or by id ("0x9")
    ax = "gnss_imu.AccelerationX"
    ay = "gnss_imu.AccelerationY"
    az = "gnss_imu.AccelerationZ"
    gx = "gnss_imu.AngularRateX"   # optional gx, gy, gz
    gy = "gnss_imu.AngularRateY"
    gz = "gnss_imu.AngularRateZ"
    speed = "gnss_speed.Speed"     # optional: temperature, speed, heading, latitude, longitude, altitude
    heading = "gnss_attitude.Heading"

    [units]                        # optional: overrides the DBC's units
    accel = "m/s^2"                # m/s^2 or g
    gyro = "deg/s"                 # deg/s or rad/s

An optional ``[messages]`` table places a DBC message at another id and/or channel, e.g.
``MM5_10_TX1 = { id = 0x174, channel = 1 }`` (``extended = true`` for a 29-bit id <= 0x7FF).
The DBC may be several files (their messages together; a name or id defined twice is refused). A
message of a J1939 DBC (``VFrameFormat`` ``J1939PG``) is matched by its PGN, from any source
address; one PGN from several source addresses is refused until ``[messages]`` picks one id.

Without a mapping (or without its ``[signals]`` table) the signals are detected from their names
when the DBC and the log make the choice unambiguous: one message with AccelerationX/Y/Z, AccX..,
AX/AY/AZ or Accel_Longitudinal/Lateral/Vertical, or one such signal per axis across messages. A
message name the DBC defines twice (CANedge's gnss.dbc) resolves to the one present in the log.
Gyro axes and the auxiliary channels (Speed, Heading, Latitude, ...; a temperature only from the
accelerometer's own message) are added when they are as unambiguous; the log is read an extra time
only when the DBC alone leaves a choice. Without ``valid``, 1-bit signals whose name contains
"valid" in a used message are the validity flags.

Axes in different messages (Bosch MM5.10: AY1 in 0x70, AX1 in 0x80, AZ in 0x576) are aligned on
the clock of the message carrying ``ax``: each of its frames takes, from every other message, the
frame nearest in time (the earlier one on a tie) if it lies within one period of that message (the
median interval of its first 1000 frames); rows without such a partner are dropped and counted.

Output is float64 SI in the sensor frame, as :class:`~mountcal.io.samples.Samples` states; the
auxiliary channels are ``temperature_c``, ``speed_mps``, ``heading_deg`` (compass, as the DBC
gives it), ``lat_deg``, ``lon_deg``, ``alt_m``, each on its own message's clock. ``dropped`` counts
frames of the selected messages that were unusable: too short, flagged invalid, non-finite, with a
multiplexer value the DBC does not define (cantools refuses such a frame whole), or without a partner in
time. Frames of other messages or channels are simply not selected.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterator, Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mountcal.core.errors import InputError
from mountcal.io.can.dbc import decode, frame_id_text, payload_bytes, raw_values, undefined_multiplexer
from mountcal.io.can.files import iter_frames, log_format
from mountcal.io.can.frames import CanFrames
from mountcal.io.can.gravity_check import check_magnitude, noted
from mountcal.io.can.mapping import (
    AUX_KEYS,
    Plan,
    Presence,
    Source,
    build_plan,
    database,
    dbc_name,
    detect,
    make_plan,
    resolve,
    setup_plan,
)
from mountcal.io.can.mismatch import SHOWN, Want, id_stats, log_mismatch
from mountcal.io.inputs import hold
from mountcal.io.reader import CHUNK_SAMPLES
from mountcal.io.samples import (
    Channel,
    FloatArray,
    LogSummary,
    Samples,
    Stream,
)

_PERIOD_FRAMES = 1000  # frames used to measure a message's period
_FRAMES_PER_CHUNK = CHUNK_SAMPLES  # frames decoded at a time by read_can (≈ 9 MB)


# ---------------------------------------------------------------------------------------------
# Public API


def read_can(
    path: str | Path,
    dbc: str | Path | Any,
    *,
    mapping: str | Path | Mapping[str, Any] | None = None,
    channel: int | None = None,
) -> Samples:
    """Read the accelerometer (and gyro) samples of a CAN log.

    Parameters
    ----------
    path : str or Path
        A BLF, ASC, candump ``.log``, TRC, CSV or MF4 log. It is only read.
    dbc : str, Path or cantools Database
        The DBC describing the bus.
    mapping : str, Path or dict, optional
        A mapping TOML file, or its content as a dict (see the module docstring). Signals are
        auto-detected when it is omitted or has no ``[signals]``.
    channel : int, optional
        The CAN channel (python-can numbering); overrides the mapping's.

    Returns
    -------
    Samples
        ``acc_s`` (n, 3) in m/s², ``gyro_s`` (n, 3) in rad/s when mapped, auxiliary channels,
        ``axis_map`` and ``dropped`` counts.

    Raises
    ------
    InputError
        Unreadable or empty log, wrong DBC, missing message or signal, bad mapping or unit.
    """
    path = Path(path)
    plan = make_plan(path, dbc, mapping, channel)
    samples = _concat(hold(_pieces(path, plan, _FRAMES_PER_CHUNK), str(path), "samples"), plan, str(path))
    return noted(check_magnitude(samples, plan), plan)


def iter_can(
    path: str | Path,
    dbc: str | Path | Any,
    *,
    mapping: str | Path | Mapping[str, Any] | None = None,
    channel: int | None = None,
    max_samples: int = CHUNK_SAMPLES,
) -> Iterator[Samples]:
    """Stream the samples of a CAN log in chunks of at most ``max_samples`` rows.

    Memory is bounded by the chunk size. Concatenating the chunks (times, vectors, auxiliary
    channels, summed ``dropped``) gives exactly what :func:`read_can` returns. Parameters as there.

    Yields
    ------
    Samples
        Consecutive chunks; each carries the auxiliary samples and drop counts of its stretch.
    """
    if max_samples < 1:
        raise ValueError(f"max_samples must be >= 1; got {max_samples}")
    path = Path(path)
    plan = make_plan(path, dbc, mapping, channel)
    held: list[Samples] = []  # pieces without rows but with auxiliary samples or drop counts
    verdict: str | None = None  # the first rows' magnitude checked (check_magnitude); "" or why gravity-free
    for piece in _pieces(path, plan, max(2 * max_samples, 1000)):
        if not len(piece):
            if piece.channels or piece.dropped:
                held.append(piece)
            continue
        if held:
            piece, held = _concat([*held, piece], plan, str(path)), []
        if verdict is None:
            piece = noted(check_magnitude(piece, plan), plan)
            verdict = piece.gravity_free
        elif verdict:
            piece = replace(piece, gravity_free=verdict)
        # pieces go out as they come (views when split): joining them to exact sizes only copies
        while len(piece) > max_samples:
            head, piece = _split(piece, max_samples)
            yield head
        yield piece
    if held:
        yield _concat(held, plan, str(path))


def inspect_can(path: str | Path, dbc: str | Path | Any | None = None) -> LogSummary:
    """What a CAN log holds: one stream per (channel, message) with count, rate and signals.

    Parameters
    ----------
    path : str or Path
        A CAN log in any supported format.
    dbc : str, Path, sequence of them, or cantools Database, optional
        Names the messages and lists their signals; without it messages are named by hex id.

    Returns
    -------
    LogSummary
        Streams sorted by channel and id; ``kind`` is ``"can<channel>"`` (``"can"`` without one);
        ``dlcs`` the data lengths each id was seen with.
    """
    path = Path(path)
    fmt = log_format(path)
    db = database(dbc) if dbc is not None else None
    stats = id_stats(path)
    wants = [(Want.of(m, None), m) for m in db.messages] if db is not None else []
    streams = []
    for (chan, ident, ext), entry in sorted(stats.items()):
        message = next((m for w, m in wants if w.matches(ident, ext)), None)
        name = message.name if message is not None else frame_id_text(ident, ext)
        fields = tuple(s.name for s in message.signals) if message is not None else ()
        span = entry.last - entry.first
        rate = (entry.count - 1) / span if span > 0 else 0.0
        kind = "can" if chan < 0 else f"can{chan}"
        streams.append(Stream(name, kind, entry.count, rate, fields, tuple(sorted(entry.dlcs))))
    if stats:
        duration = max(v.last for v in stats.values()) - min(v.first for v in stats.values())
    else:
        duration = 0.0
    return LogSummary(str(path), fmt, float(duration), tuple(streams))


# ---------------------------------------------------------------------------------------------
# Streaming: frames → decoded, validated source samples → aligned rows


def _pieces(path: Path, plan: Plan, frames_per_chunk: int) -> Iterator[Samples]:
    """Samples pieces, one per chunk of frames, then the final flush; raises on missing data."""
    decoder = _Decoder(plan, str(path))
    for frames in iter_frames(path, ids=plan.ids(), channel=plan.read_channel(), max_frames=frames_per_chunk):
        yield decoder.piece(frames)
    last = decoder.final()
    _check_found(path, plan, decoder.seen, decoder.rows_total, decoder.dropped_total)
    yield last


class _Decoder:
    """Chunks of frames → aligned Samples pieces, with the counts of what was seen and dropped."""

    def __init__(self, plan: Plan, source: str) -> None:
        self.plan, self.source = plan, source
        self.aligner = _Aligner([len(s.signals) for s in plan.imu], [s.name for s in plan.imu])
        self.seen = Counter[str]()  # frames selected per source, before validation
        self.dropped_total = Counter[str]()
        self.rows_total = 0

    def piece(self, frames: CanFrames) -> Samples:
        dropped = Counter[str]()
        for k, source in enumerate(self.plan.imu):
            t_s, values = _take(frames, source, self.plan, dropped, self.seen)
            self.aligner.add(k, t_s, values)
        channels = _aux_piece(frames, self.plan, dropped, self.seen)
        t_s, rows = self.aligner.emit(final=False, dropped=dropped)
        self.rows_total += t_s.shape[0]
        self.dropped_total.update(dropped)
        return _to_samples(t_s, rows, channels, dropped, self.plan, self.source)

    def final(self) -> Samples:
        dropped = Counter[str]()
        t_s, rows = self.aligner.emit(final=True, dropped=dropped)
        self.rows_total += t_s.shape[0]
        self.dropped_total.update(dropped)
        return _to_samples(t_s, rows, {}, dropped, self.plan, self.source)


def samples_from_frames(
    frames: CanFrames,
    dbc: str | Path | Any,
    *,
    mapping: str | Path | Mapping[str, Any] | None = None,
    channel: int | None = None,
    source: str = "<bus>",
    complete: bool = False,
) -> Samples:
    """The samples of frames held in memory (a live bus), decoded exactly as :func:`read_can` decodes a log.

    Signals are resolved against the frames present, as against a log's. With ``complete`` (the
    whole session) a mapped message without frames is an error, as it is for a log; otherwise a bus
    still waiting for it gives what it has.
    """
    db, spec, channel = setup_plan(dbc, mapping, channel)
    where = f"{source} with {dbc_name(dbc)}"
    present = Presence(None, channel, db)
    on_channel = frames if channel is None else frames.take(frames.channel == channel)
    pairs = np.unique(on_channel.arbitration_id.astype(np.int64) * 2 + on_channel.is_extended)
    present.keys = {(int(p) // 2, bool(p % 2)) for p in pairs}
    signals = spec.get("signals") or detect(db, present, where)
    refs = {role: resolve(db, text, role, present, where) for role, text in signals.items()}
    explicit = "signals" in spec and bool(spec["signals"])
    plan = build_plan(where, db, refs, spec.get("units", {}), spec, channel, explicit, present)
    ids, read_channel = plan.ids(), plan.read_channel()  # ids None: a J1939 PGN matches a range of ids
    keep = np.ones(len(frames), bool) if ids is None else np.isin(frames.arbitration_id, np.asarray(ids, np.uint32))
    if read_channel is not None:
        keep &= frames.channel == read_channel
    decoder = _Decoder(plan, source)
    samples = _concat([decoder.piece(frames.take(keep)), decoder.final()], plan, source)
    missing = [s.name for s in plan.imu if not decoder.seen[s.name]]
    missing += [plan.aux[k][0].name for k in sorted(plan.aux_required) if not decoder.seen[plan.aux[k][0].name]]
    if complete and missing:
        raise InputError(
            where,
            "frames of every mapped message (" + ", ".join(missing) + ")",
            "none of them on the bus",
            "Check the mapping, the channel and that the device sends these messages.",
        )
    return noted(check_magnitude(samples, plan), plan)  # as a log's: the units checked by gravity, and stated


def _select(frames: CanFrames, source: Source, plan: Plan) -> CanFrames:
    ids = frames.arbitration_id if source.mask == 0x1FFFFFFF else frames.arbitration_id & np.uint32(source.mask)
    wanted = (ids == source.value) & (frames.is_extended == source.extended)
    if source.channel is not None:
        wanted &= frames.channel == source.channel
    chosen = frames.take(wanted)
    if len(chosen):
        low, high = int(chosen.channel.min()), int(chosen.channel.max())
        source.channels.update((low, high) if low == high or high - low == 1 else np.unique(chosen.channel).tolist())
        if source.channel is None and len(source.channels) > 1:
            found = ", ".join(map(str, sorted(source.channels)))
            raise InputError(
                plan.where,
                f"message {source.message.name} on one CAN channel",
                f"it on channels {found}",
                "Choose one with `channel=` (or `channel = N` in the mapping).",
            )
        if source.mask != 0x1FFFFFFF:  # matched by J1939 PGN: one sender, or two streams would mix
            source.ids.update(np.unique(chosen.arbitration_id).tolist())
            if len(source.ids) > 1:
                found = ", ".join(frame_id_text(i, True) for i in sorted(source.ids)[:SHOWN])
                raise InputError(
                    plan.where,
                    f"message {source.message.name} (J1939 PGN 0x{source.value >> 8:05X}) from one sender",
                    f"it from {len(source.ids)} ids: {found}",
                    f"Pick one in the mapping: [messages] {source.message.name} = {{ id = 0x... }}.",
                )
    return chosen


def _take(
    frames: CanFrames, source: Source, plan: Plan, dropped: Counter[str], seen: Counter[str]
) -> tuple[FloatArray, NDArray[np.float64]]:
    """Times (m,) and values (m, k) of one source's usable frames; the unusable ones counted."""
    chosen = _select(frames, source, plan)
    name = source.message.name
    if source.mux is not None:
        # its multiplexer values, and frames too short to carry the multiplexer (any branch's: counted short)
        signal = source.message.get_signal_by_name(source.signals[0])
        mux = source.message.get_signal_by_name(signal.multiplexer_signal)
        cut = chosen.dlc < payload_bytes(source.message, [mux.name])
        page = raw_values(chosen.data, mux)
        if len(source.mux_found) < SHOWN:
            source.mux_found.update(np.unique(page[~cut]).tolist()[:SHOWN])
        chosen = chosen.take(np.isin(page, np.asarray(source.mux, np.uint64)) | cut)
    seen[source.name] += len(chosen)
    refused = undefined_multiplexer(chosen, source.message)  # what cantools refuses: no signal of it is read
    _count(dropped, f"{name}: multiplexer value the DBC does not define", refused)
    if refused.any():
        chosen = chosen.take(~refused)
    short = chosen.dlc < payload_bytes(source.message, source.signals + source.valid)
    _count(dropped, f"{name}: frame shorter than the DBC layout", short)
    if short.any():
        chosen = chosen.take(~short)
    decoded = decode(chosen, source.message, source.signals + source.valid)
    keep = np.ones(len(chosen), np.bool_)
    if source.valid:
        invalid = (np.stack([decoded[v] for v in source.valid]) == 0).any(axis=0)
        _count(dropped, f"{name}: {' or '.join(source.valid)} == 0", invalid)
        keep &= ~invalid
    values = np.stack([decoded[s] for s in source.signals], axis=1)
    finite = np.logical_and.reduce([np.isfinite(decoded[s]) for s in source.signals])
    _count(dropped, f"{name}: non-finite value", keep & ~finite)
    keep &= finite
    if keep.all():
        return chosen.t_s, values
    return chosen.t_s[keep], values[keep]


def _count(dropped: Counter[str], reason: str, rows: NDArray[np.bool_]) -> None:
    """Add the rows flagged in ``rows`` to the drop counts (no entry for none)."""
    n = int(rows.sum())
    if n:
        dropped[reason] += n


def _aux_piece(frames: CanFrames, plan: Plan, dropped: Counter[str], seen: Counter[str]) -> dict[str, Channel]:
    channels = {}
    for key, (source, signal, scale, offset) in plan.aux.items():
        t_s, values = _take(frames, source, plan, dropped, seen)
        if t_s.shape[0]:
            channels[key] = Channel(t_s, values[:, source.signals.index(signal)] * scale + offset)
    return channels


class _Aligner:
    """Nearest-in-time alignment of several sources onto the clock of source 0, streamed.

    A row of source 0 at time t is emitted once every other source k holds a sample later than
    t + period_k (or the stream has ended), so the chunking never changes the result.
    """

    def __init__(self, widths: list[int], names: list[str]) -> None:
        self.names = names
        self.t: list[FloatArray] = [np.empty(0) for _ in widths]
        self.v: list[NDArray[np.float64]] = [np.empty((0, w)) for w in widths]
        self.period: list[float | None] = [None] * len(widths)

    def add(self, k: int, t_s: FloatArray, values: NDArray[np.float64]) -> None:
        if not t_s.shape[0]:
            return
        t, v = np.concatenate([self.t[k], t_s]), np.concatenate([self.v[k], values])
        if (np.diff(t) < 0).any():  # keep each source in time order
            order = np.argsort(t, kind="stable")
            t, v = t[order], v[order]
        self.t[k], self.v[k] = t, v

    def emit(self, *, final: bool, dropped: Counter[str]) -> tuple[FloatArray, list[NDArray[np.float64]]]:
        """Rows of source 0 whose partners are settled: times (n,) and per-source values (n, w_k)."""
        if len(self.t) == 1:
            n = self.t[0].shape[0]
        elif self._periods_known(final):
            n = self._settled(final)
        else:  # partners' periods not measured yet: hold everything
            return np.empty(0), [np.empty((0, v.shape[1])) for v in self.v]
        t_out, values, keep = self.t[0][:n], [self.v[0][:n]], np.ones(n, np.bool_)
        periods = [p or 0.0 for p in self.period]
        for k in range(1, len(self.t)):
            index, ok = _nearest(self.t[k], t_out, periods[k])
            keep &= ok
            values.append(self.v[k][index] if ok.any() else np.zeros((n, self.v[k].shape[1])))
        _count(dropped, f"{self.names[0]}: no frame of {', '.join(self.names[1:])} within one period", ~keep)
        self._trim(n, periods)
        if keep.all():
            return t_out, values
        return t_out[keep], [v[keep] for v in values]

    def _periods_known(self, final: bool) -> bool:
        """Measure each partner's period from its first frames, once there are enough of them."""
        for k in range(1, len(self.t)):
            if self.period[k] is None and (final or self.t[k].shape[0] >= _PERIOD_FRAMES):
                dt = np.diff(self.t[k][:_PERIOD_FRAMES])
                self.period[k] = float(np.median(dt)) if dt.shape[0] else 0.0
        return all(p is not None for p in self.period[1:])

    def _settled(self, final: bool) -> int:
        """How many rows of source 0 have all their candidate partners in hand."""
        if final:
            return int(self.t[0].shape[0])
        limits = [
            float(self.t[k][-1]) - (self.period[k] or 0.0) if self.t[k].shape[0] else -np.inf
            for k in range(1, len(self.t))
        ]
        return int(np.searchsorted(self.t[0], min(limits), side="left"))

    def _trim(self, n: int, periods: list[float]) -> None:
        """Forget emitted rows, and partner samples too early for any row still to come."""
        ref_t = self.t[0]
        lower = ref_t[n] if n < ref_t.shape[0] else (ref_t[n - 1] if n else -np.inf)
        self.t[0], self.v[0] = ref_t[n:], self.v[0][n:]
        for k in range(1, len(self.t)):
            first = int(np.searchsorted(self.t[k], lower - periods[k], side="left"))
            self.t[k], self.v[k] = self.t[k][first:], self.v[k][first:]


def _nearest(t_k: FloatArray, t_ref: FloatArray, tolerance: float) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """Index of the sample of ``t_k`` nearest each ``t_ref`` (earlier on ties) and whether it is
    within ``tolerance``."""
    if not t_k.shape[0]:
        return np.zeros(t_ref.shape[0], np.int64), np.zeros(t_ref.shape[0], np.bool_)
    after = np.clip(np.searchsorted(t_k, t_ref, side="left"), 0, t_k.shape[0] - 1)
    before = np.clip(after - 1, 0, None)
    use_before = np.abs(t_ref - t_k[before]) <= np.abs(t_k[after] - t_ref)
    index = np.where(use_before, before, after)
    return index, np.abs(t_k[index] - t_ref) <= tolerance


def _to_samples(
    t_s: FloatArray,
    rows: list[NDArray[np.float64]],
    channels: dict[str, Channel],
    dropped: Counter[str],
    plan: Plan,
    source: str,
) -> Samples:
    """Scaled device-axis columns, permuted by the axis map, as one Samples piece."""
    n = t_s.shape[0]
    acc_s = np.empty((n, 3))
    gyro_s = np.empty((n, 3)) if plan.has_gyro else None
    # the axis map is a signed permutation: sensor axis i is ±(device axis j), a scaled column copy
    for i, j in enumerate(np.argmax(np.abs(plan.axes), axis=1)):
        sign = plan.axes[i, j]
        for out, column in ((acc_s, j), (gyro_s, 3 + j)):
            if out is not None:
                k, signal, scale = plan.columns[column]
                out[:, i] = rows[k][:, plan.imu[k].signals.index(signal)] * (sign * scale)
    return Samples(np.asarray(t_s, np.float64), acc_s, gyro_s, channels, source, plan.axis_map, dict(dropped))


def _concat(pieces: list[Samples], plan: Plan, source: str) -> Samples:
    """One Samples from consecutive pieces: rows, auxiliary samples and drop counts joined."""
    t_s = np.concatenate([p.t_s for p in pieces]) if pieces else np.empty(0)
    acc_s = np.concatenate([p.acc_s for p in pieces]) if pieces else np.empty((0, 3))
    gyro_s = np.concatenate([p.gyro_s for p in pieces if p.gyro_s is not None]) if plan.has_gyro else None
    channels = {}
    for key in AUX_KEYS.values():
        parts = [p.channels[key] for p in pieces if key in p.channels]
        if parts:
            channels[key] = Channel(np.concatenate([c.t_s for c in parts]), np.concatenate([c.value for c in parts]))
    dropped = Counter[str]()
    for p in pieces:
        dropped.update(p.dropped)
    return Samples(t_s, acc_s, gyro_s, channels, source, plan.axis_map, dict(dropped))


def _split(samples: Samples, n: int) -> tuple[Samples, Samples]:
    """The first n rows (with every auxiliary sample and drop count so far) and the rest."""
    head = Samples(
        samples.t_s[:n],
        samples.acc_s[:n],
        None if samples.gyro_s is None else samples.gyro_s[:n],
        samples.channels,
        samples.source,
        samples.axis_map,
        samples.dropped,
    )
    rest = Samples(
        samples.t_s[n:],
        samples.acc_s[n:],
        None if samples.gyro_s is None else samples.gyro_s[n:],
        {},
        samples.source,
        samples.axis_map,
        {},
    )
    return head, rest


# ---------------------------------------------------------------------------------------------
# Errors that need a look at the whole log


def _check_found(path: Path, plan: Plan, seen: Counter[str], total_rows: int, dropped: Counter[str]) -> None:
    """Raise when the log lacks the mapped messages, or none of their samples survived."""
    missing_aux = sorted(k for k in plan.aux_required if not seen[plan.aux[k][0].name])
    silent = [s for s in plan.imu if not seen[s.name]]
    if not silent and not missing_aux and total_rows:
        return
    sources = silent + [plan.aux[k][0] for k in missing_aux]
    branch = next((s for s in sources if s.mux is not None and s.mux_found), None)
    if branch is not None:  # its message is in the log, on other branches only
        signal = branch.message.get_signal_by_name(branch.signals[0])
        values = "/".join(map(str, branch.mux or ()))
        found = ", ".join(map(str, sorted(branch.mux_found)[:SHOWN]))
        raise InputError(
            plan.where,
            f"frames of {branch.message.name} with {signal.multiplexer_signal} = {values} (the branch of "
            f"{', '.join(branch.signals)})",
            f"frames of {branch.message.name} with {signal.multiplexer_signal} = {found} only",
            "Check the mapped signals' multiplexer branch in the DBC against the device's messages.",
        )
    wanted = [Want(s.message.name, s.value, s.mask, s.extended, s.channel) for s in sources]
    mismatch = log_mismatch(path, plan.db, plan.where, plan.channel, wanted)
    if mismatch is not None:
        raise mismatch
    raise InputError(
        plan.where,
        "usable accelerometer samples",
        "every row dropped (" + ", ".join(f"{k}: {v}" for k, v in dropped.items()) + ")",
        "Check the validity flags and the DBC layout against the log.",
    )


__all__ = ["inspect_can", "iter_can", "read_can", "samples_from_frames"]
