"""Why a CAN log lacks what the DBC and mapping expect: per-id statistics of the log, and the message
that names the ids, channels and near matches it does hold (for ``mountcal inspect`` and the reader's refusals).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mountcal.core import budget
from mountcal.core.errors import InputError
from mountcal.io.can.dbc import frame_id_text, id_match
from mountcal.io.can.files import iter_frames


@dataclass(frozen=True)
class Want:
    """A message looked for in the log: its name and where its frames would be."""

    name: str
    value: int
    mask: int
    extended: bool
    channel: int | None

    @classmethod
    def of(cls, message: Any, channel: int | None) -> Want:
        value, mask = id_match(message)
        return cls(message.name, value, mask, bool(message.is_extended_frame), channel)

    def matches(self, ident: int, extended: bool) -> bool:
        return extended == self.extended and ident & self.mask == self.value

    def matches_any(self, keys: Iterable[tuple[int, bool]]) -> bool:
        return any(self.matches(i, e) for i, e in keys)

    @property
    def text(self) -> str:
        pgn = f", J1939 PGN 0x{self.value >> 8:05X}" if self.mask != 0x1FFFFFFF else ""
        return f"{self.name} ({frame_id_text(self.value, self.extended)}{pgn})"


SHOWN = 10  # ids, channels and near matches an error lists: it has to fit on a screen


def log_mismatch(path: Path | None, db: Any, where: str, channel: int | None, wanted: list[Want]) -> InputError | None:
    """The error for an empty log, a log the DBC does not describe, or one lacking ``wanted`` (None for a bus)."""
    if path is None:
        return None
    stats = id_stats(path)
    if not stats:
        return InputError(str(path), "CAN frames", "an empty log (no data frames)", "Check the logger's output.")
    per_id = Counter[tuple[int, bool]]()
    for (_, ident, ext), entry in stats.items():
        per_id[(ident, ext)] += entry.count
    known = [Want.of(m, None) for m in db.messages]
    if not any(w.matches_any(per_id) for w in known):
        examples = ", ".join(w.text for w in known[:SHOWN]) + (", ..." if len(known) > SHOWN else "")
        return InputError(
            where,
            f"frames of messages of the DBC ({len(known)} messages: {examples})",
            "no frame of any of them; the log has " + _seen(stats),
            "Use the DBC that describes this bus (29-bit ids print with 8 hex digits).",
        )
    if not wanted:
        return None
    names = ", ".join(w.text + ("" if w.channel is None else f" on channel {w.channel}") for w in wanted)
    return InputError(
        where,
        f"frames of {names}",
        "none; the log has " + _seen(stats) + "".join(_closest(w, stats) for w in wanted),
        "Check the mapping (its [messages] table places a message at another id or channel), the channel "
        "and that the logger recorded this message.",
    )


def _seen(stats: dict[tuple[int, int, bool], _IdStat]) -> str:
    """The channels and the most frequent ids of a log, with frame counts, in a few lines."""
    per_channel = Counter[int]()
    per_id = Counter[tuple[int, bool]]()
    for (chan, ident, ext), entry in stats.items():
        per_channel[chan] += entry.count
        per_id[(ident, ext)] += entry.count
    channels = ", ".join(f"{c} ({n} frames)" for c, n in per_channel.most_common(SHOWN))
    more = f" and {len(per_channel) - SHOWN} more" if len(per_channel) > SHOWN else ""
    top = ", ".join(f"{frame_id_text(i, e)} ({n})" for (i, e), n in per_id.most_common(SHOWN))
    return f"{len(per_id)} ids on channels {channels}{more}; the most frequent: {top}"


def _closest(want: Want, stats: dict[tuple[int, int, bool], _IdStat]) -> str:
    """Where the log has the wanted id on other channels, else its ids nearest to it."""
    elsewhere = [(c, e.count) for (c, i, x), e in stats.items() if want.matches(i, x)]
    if elsewhere:
        where = ", ".join(f"channel {c} ({n} frames)" for c, n in sorted(elsewhere)[:SHOWN])
        return f". {want.name} is on {where}"
    other_kind = sum(e.count for (_, i, x), e in stats.items() if x != want.extended and i == want.value)
    if other_kind and want.mask == 0x1FFFFFFF:  # the same number as the other id kind: 0x070 sent as 0x00000070
        kind, theirs = ("an 11", "a 29") if want.extended else ("a 29", "an 11")
        return (
            f". {want.name}'s id is in the log as {kind}-bit id, "
            f"{frame_id_text(want.value, not want.extended)} ({other_kind} frames), where the DBC has {theirs}-bit "
            f"{frame_id_text(want.value, want.extended)}: if those are its frames, place it in the mapping, "
            f"[messages] {want.name} = {{ id = 0x{want.value:X}, extended = {str(not want.extended).lower()} }}"
        )
    same_kind = sorted({(i, x) for (_, i, x) in stats if x == want.extended}, key=lambda k: abs(k[0] - want.value))
    if not same_kind:
        return f". No {'29' if want.extended else '11'}-bit id in the log for {want.name}"
    near = ", ".join(frame_id_text(i, x) for i, x in same_kind[:3])
    return f". Nearest ids to {want.name}'s: {near}"


@dataclass
class _IdStat:
    """One (channel, id, extended) of a log: frames, first and last time, the DLCs seen."""

    count: int
    first: float
    last: float
    dlcs: set[int]


def id_stats(path: Path) -> dict[tuple[int, int, bool], _IdStat]:
    """Per (channel, id, extended): frame count, first and last time, DLCs, in one streamed pass."""
    stats: dict[tuple[int, int, bool], _IdStat] = {}
    for frames in iter_frames(path, max_frames=1 << 18):
        known = len(stats)
        key = (frames.channel * (1 << 33)) + frames.arbitration_id.astype(np.int64) * 2 + frames.is_extended
        uniq, first, counts = np.unique(key, return_index=True, return_counts=True)
        last = len(key) - 1 - np.unique(key[::-1], return_index=True)[1]
        pairs = np.unique(key * 128 + frames.dlc)  # the DLCs of each id
        dlcs: dict[int, set[int]] = {}
        for pair in pairs.tolist():
            dlcs.setdefault(pair // 128, set()).add(pair % 128)
        for u, f, c, la in zip(uniq.tolist(), first, counts, last, strict=True):
            chan, rest = u // (1 << 33), u % (1 << 33)
            k = (chan, rest // 2, bool(rest % 2))
            entry = stats.setdefault(k, _IdStat(0, float(frames.t_s[f]), 0.0, set()))
            entry.count += int(c)
            entry.last = float(frames.t_s[la])
            entry.dlcs |= dlcs[u]
        budget.charge("streams", len(stats) - known, str(path), "distinct CAN ids (per channel)")
    return stats
