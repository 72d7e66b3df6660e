"""What :func:`mountcal.apply.rotate_log.rotate_log` read, wrote, dropped and checked."""

from __future__ import annotations

from dataclasses import dataclass

from mountcal.core.result import VEHICLE_FRAME


@dataclass(frozen=True)
class RotateReport:
    """What :func:`rotate_log` read, wrote and dropped.

    ``samples_in`` are the IMU samples the readers delivered and ``samples_out`` those written
    (always equal); ``dropped`` counts what the readers discarded, by reason. For an MCAP copied
    through, ``copied_messages`` counts the input's messages (every channel, the original IMU one
    included) and ``nonfinite`` the IMU messages with NaN or infinite values (rotated, so still
    NaN, and kept so the new channel has one message per original).
    """

    output: str
    format: str
    inputs: tuple[str, ...]
    samples_in: int
    samples_out: int
    dropped: dict[str, int]
    chunks: int
    largest_chunk: int
    gyro: bool
    topic: str | None = None
    copied_messages: int = 0
    copied_channels: int = 0
    nonfinite: int = 0
    frame: str = VEHICLE_FRAME
    warnings: tuple[str, ...] = ()  # what check_applicable found: not confident, levelled only
    incomplete: tuple[str, ...] = ()  # inputs cut short, read in part (--allow-truncated): where each ends
    turns: tuple[str, ...] = ()  # the gyro's scale and the turns' handedness against this log (TurnWatch)

    def lines(self) -> list[str]:
        """Lines for the user."""
        dropped = ", ".join(f"{k}: {v}" for k, v in self.dropped.items())
        out = [
            f"read {self.samples_in} IMU samples from {len(self.inputs)} file(s)"
            + (f"; the readers dropped {dropped}" if dropped else "; nothing dropped"),
            f"wrote {self.samples_out} {'vehicle' if self.frame == VEHICLE_FRAME else 'levelled'}-frame samples "
            "(accelerometer"
            + (" and gyro" if self.gyro else "")
            + f") to {self.output} ({self.format}, {self.chunks} chunk(s) of at most {self.largest_chunk})",
        ]
        if self.topic is not None and self.copied_channels:
            out.append(
                f"copied {self.copied_messages} messages on {self.copied_channels} channel(s) unchanged; "
                f"added {self.topic}"
            )
        if self.nonfinite:
            out.append(f"{self.nonfinite} IMU messages hold NaN or infinite values: kept, rotated to NaN")
        out += [f"input file: {line}" for line in self.incomplete]
        return out + list(self.turns)
