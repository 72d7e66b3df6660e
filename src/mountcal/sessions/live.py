"""A calibration session on a live CAN bus: record, detect stops as they end, refit, suggest, stop at the target.

Every frame is received one by one (unavoidable on a bus) and written at once to a BLF recording
(python-can's ``BLFWriter``); the frames are kept as arrays, and at each evaluation the whole
session so far is decoded with the readers' vectorised DBC decoding
(:func:`mountcal.io.can.read.samples_from_frames`) and the *batch* stop detection runs on it. So
the session's answer is, by construction, what ``calibrate`` gives on the recording: the
timestamps are kept exactly as the BLF file will return them (ms start, ns ticks).

Headings β come from the log's heading channel with ``uphill_azimuth_deg``; otherwise each stop
takes the next heading of a plan, or the heading suggested before it. Then a protocol sheet on the
log's clock is written beside the recording, so that ``calibrate REC.blf --protocol SHEET``
reproduces the result offline.

A refit after each stop is the stops' fit alone (fast, for the suggestions and the target); the final
evaluation is ``calibrate``'s own pipeline (:func:`mountcal.calibration.pipeline.calibrate_samples`) on the
whole session and its sheet: the drive's yaw, the cross-checks, the conventions and the notes included.
"""

from __future__ import annotations

import contextlib
import json
import signal
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import IO, Any, Literal

import numpy as np
import pandas as pd

from mountcal.calibration.fit import WITH_OFFSET, calibrate
from mountcal.calibration.options import Options
from mountcal.calibration.pipeline import LogJob, calibrate_samples
from mountcal.core.angles import ANGLE_NAMES, AngleName, Angles
from mountcal.core.atomic import atomic_path
from mountcal.core.conventions import specific_force_v
from mountcal.core.errors import InputError, MountcalError, NotEnoughInformation
from mountcal.core.option_names import option
from mountcal.core.result import Calibration
from mountcal.estimate import effects as registry
from mountcal.estimate.bound import crb_deg, true_state
from mountcal.io.can.bus import BusFrames, Recording
from mountcal.io.can.read import samples_from_frames
from mountcal.io.input_conventions import parse_axes
from mountcal.io.logs import stated
from mountcal.io.reader import LogOptions
from mountcal.io.samples import Samples
from mountcal.stops.detect import StillPeriod, StopDetection, detect_stops
from mountcal.stops.headings import protocol_sheet, tabulate
from mountcal.stops.table import StopTable, write_stop_table

CANDIDATES_DEG = tuple(float(b) for b in range(0, 360, 5))
BASE_TERMS = WITH_OFFSET  # the terms a bound for a suggestion may use


@dataclass(frozen=True)
class LiveOptions:
    """What a session needs besides the bus."""

    dbc: str
    mapping: str | None = None
    can_channel: int | None = None
    target_deg: dict[str, float] = field(default_factory=lambda: {"roll": 0.1, "pitch": 0.1, "yaw": 0.5})
    options: Options = field(default_factory=Options)
    detection: StopDetection = field(default_factory=StopDetection)
    uphill_azimuth_deg: float | None = None
    plan_beta_deg: tuple[float, ...] | None = None  # headings in driving order (a plan's sheet)
    silence_s: float = 10.0  # a bus silent this long ends the session
    axes: str | None = None  # the device's axes onto the sensor frame (--axes), after the mapping's
    heading_unit: Literal["deg", "rad"] | None = None  # the bus's heading signal (--heading-unit; unstated: checked)
    evaluate_every_s: float = 2.0  # bus time between evaluations


@dataclass
class Session:
    """What a session produced (also when it was interrupted)."""

    reason: str  # why it ended: "target met", "bus silent", "interrupted"
    recording: Path
    frames: int = 0
    samples: Samples | None = None
    table: StopTable | None = None
    calibration: Calibration | None = None
    protocol: pd.DataFrame | None = None
    suggestion_deg: float | None = None
    dropped: dict[str, int] = field(default_factory=dict)
    ignored_frames: int = 0  # error and remote frames (recorded, carry no signal)
    still_not_kept: tuple[StillPeriod, ...] = ()  # still periods stop detection did not keep (for the report)


def next_heading(
    table: StopTable, cal: Calibration, target_deg: dict[str, float], candidates: tuple[float, ...] = CANDIDATES_DEG
) -> float | None:
    """The candidate heading whose added stop most reduces the largest σ/target (Cramér–Rao bound).

    The added stop carries the mean covariance of the stops so far and sits where the current fit
    predicts it; the bound is evaluated at the current fit. None when no candidate gives a bound.
    """
    if cal.slope_deg is None or table.beta_rad is None or table.cov_s is None:
        return None
    terms = tuple(t for t in cal.model if t in BASE_TERMS)
    off = registry.offset_of(cal)
    bias = np.zeros(3) if off is None else np.array(off.value)
    state = true_state(cal.rot_vs, cal.slope_deg, cal.gravity_mps2, {registry.offset().name: bias})
    cov = table.cov_s.mean(axis=0)
    best: tuple[float, float] | None = None
    for beta in candidates:
        acc = cal.rot_vs.inv().apply(specific_force_v(np.radians(cal.slope_deg), np.radians([beta]), cal.gravity_mps2))
        grown = replace(
            table,
            acc_s=np.vstack([table.acc_s, acc + bias]),
            beta_rad=np.append(table.beta_rad, np.radians(beta)),
            cov_s=np.concatenate([table.cov_s, cov[None]]),
            temperature_c=None,
            t_s=None,
            site=None,
            lat_deg=None,
            alt_m=None,
            lon_deg=None,
        )
        crb = crb_deg(grown, state, terms, cal.gravity_mps2)
        if crb is None:
            continue
        worst = max((np.inf if (bound := crb[a]) is None else bound / t) for a, t in target_deg.items())
        if best is None or worst < best[0]:
            best = (worst, beta)
    return None if best is None else best[1]


def sigma_of(cal: Calibration, angle: str) -> float | None:
    return cal.angles.sigmas[angle]


def target_met(cal: Calibration, target_deg: dict[str, float]) -> bool:
    return all((s := sigma_of(cal, a)) is not None and s <= t for a, t in target_deg.items())


def unreachable(cal: Calibration, target_deg: dict[str, float]) -> dict[str, float]:
    """Targets below the systematic part of their σ (mountcal.loop.systematic): more stops cannot reach them."""
    part = cal.systematic
    if part is None:
        return {}
    sys = part.systematic_angles
    return {a: s for a, t in target_deg.items() if (s := sys[a]) is not None and s > t}


class Live:
    """One session: feed it a bus; it calls ``emit`` with each event (a dict)."""

    def __init__(self, opts: LiveOptions, recording: Path, emit: Callable[[dict[str, Any]], None]) -> None:
        self.axes = None if opts.axes is None else parse_axes(opts.axes, option("axes"))  # refused before the bus
        self.opts, self.recording, self.emit = opts, recording, emit
        self.frames = BusFrames()
        self.ignored = 0
        self.beta: list[float] = []  # β of each closed stop (protocol mode)
        self.suggestion: float | None = None
        self.n_closed = 0
        self.why = ""
        self.last: Session = Session("not started", recording)
        self.told_unreachable = False

    def run(self, bus: Any) -> Session:
        """Listen until the target is met, the bus is silent or Ctrl-C (SIGTERM likewise); the recording is
        closed however the session ends.

        Raises
        ------
        SystemFailure
            The recording could not be written (no space, ...): it is kept up to its last whole
            container, and the message says so.
        """
        recording = Recording(self.recording)
        try:
            reason = self._listen(bus, recording)
        finally:
            recording.close()
        try:
            self._evaluate(final=True)
        except KeyboardInterrupt:  # a second Ctrl-C: the recording is closed already
            pass
        self.last.reason = reason
        self.last.frames = self.frames.count
        self.last.ignored_frames = self.ignored
        self.last.dropped = {**self.last.dropped, **recording.refused}
        self.emit({"event": "ended", "reason": reason, "frames": self.last.frames, "recording": str(self.recording)})
        return self.last

    def _listen(self, bus: Any, recording: Recording) -> str:
        """Receive, record and evaluate until the session ends; why it ended."""
        reason = "interrupted"
        last_eval = -np.inf
        last_rx = time.monotonic()
        self.emit({"event": "started", "recording": str(self.recording)})
        self._suggest(None, None)
        stop_asked = threading.Event()
        try:
            with _ctrl_c_sets(stop_asked):
                while True:
                    if stop_asked.is_set():
                        raise KeyboardInterrupt  # here, between two steps
                    msg = bus.recv(timeout=min(0.5, self.opts.silence_s))
                    if msg is None:
                        if time.monotonic() - last_rx >= self.opts.silence_s:
                            reason = "bus silent"
                            self.emit({"event": "silent", "after_s": self.opts.silence_s})
                            break
                        continue
                    last_rx = time.monotonic()
                    if not recording.add(msg):  # a stamp the recording cannot hold: counted there
                        continue
                    if msg.is_error_frame or msg.is_remote_frame:
                        self.ignored += 1
                        continue
                    self.frames.add(msg, recording.writer.start_timestamp)
                    if self.frames.last_t - last_eval >= self.opts.evaluate_every_s:
                        last_eval = self.frames.last_t
                        if self._evaluate(final=False):
                            reason = "target met"
                            break
        except KeyboardInterrupt:
            reason = "interrupted"
            self.emit({"event": "interrupted"})
        return reason

    # --- evaluation -------------------------------------------------------------------------

    def _evaluate(self, final: bool) -> bool:
        """Decode the session so far; on a newly ended stop refit and suggest. True when the target is met."""
        if not self.frames.count:
            return False
        try:
            samples = samples_from_frames(
                self.frames.table(), self.opts.dbc, mapping=self.opts.mapping, channel=self.opts.can_channel,
                source=str(self.recording), complete=final,
            )  # fmt: skip
            # the heading channel's unit is inferred from the whole session only (a part cannot tell)
            samples = stated(samples, self._job().log, self.axes, check=final)
        except InputError as err:  # e.g. no accelerometer frame yet: say so, keep listening
            if final:  # the whole session cannot be decoded: no result that the recording would not give
                self.last.calibration = None
            self._waiting(str(err))
            return False
        self.last.samples, self.last.dropped = samples, dict(samples.dropped)
        cfg = self.opts.detection
        if len(samples) < 3 or samples.t_s[-1] - samples.t_s[0] < cfg.min_duration_s + 2 * cfg.trim_s:
            return False  # shorter than a stop: nothing to detect yet
        stops = detect_stops(samples, cfg)
        if not final:  # a stop has ended when its still run closed a window before the newest sample
            stops = [s for s in stops if s.t_end_s + cfg.trim_s + cfg.window_s < samples.t_s[-1]]
        if len(stops) <= self.n_closed and not final:
            return False
        beta = list(self.beta[: len(stops)])  # built aside: a Ctrl-C here leaves the session consistent
        plan = self.opts.plan_beta_deg
        for _ in stops[len(beta) :]:
            if plan is not None:
                beta.append(plan[len(beta)] if len(beta) < len(plan) else np.nan)
            else:
                beta.append(np.nan if self.suggestion is None else self.suggestion)
        old, self.beta, self.n_closed = len(self.beta), beta, len(stops)
        for i, s in enumerate(stops[old:], start=old + 1):
            self.emit({"event": "stop", "index": i, "t_start_s": s.t_start_s, "t_end_s": s.t_end_s, "n": s.n,
                       "beta_deg": None if np.isnan(beta[i - 1]) else beta[i - 1]})  # fmt: skip
        if not stops:
            return False
        protocol = None
        if self.opts.uphill_azimuth_deg is None:
            known = [(s, b) for s, b in zip(stops, self.beta, strict=True) if np.isfinite(b)]
            # the whole still run (the stop plus its trimmed ends) and a margin lies in the window
            pad = cfg.trim_s + 0.5 * cfg.window_s
            protocol = pd.DataFrame(
                {
                    "t_start_s": [s.t_start_s - pad for s, _ in known],
                    "t_end_s": [s.t_end_s + pad for s, _ in known],
                    "beta_deg": [b for _, b in known],
                }
            )
            self.last.protocol = protocol
            if protocol.empty:
                return False
        try:
            sheet = None if protocol is None else protocol_sheet(protocol, self._sheet_where(), stated_by=self._by())
            if final:  # calibrate's pipeline on the session: what it gives on the recording and sheet
                done = calibrate_samples(self._job(), samples, sheet)
                table, cal = done.table, done.calibration
                dropped = () if done.stops is None else done.stops.dropped
            else:
                found = tabulate(samples, cfg, sheet, self.opts.uphill_azimuth_deg)
                table = found.table if protocol is not None else found.table.subset(np.arange(len(stops)))
                table, dropped = replace(table, source=str(self.recording)), found.dropped
                cal = calibrate(table, self.opts.options)
        except MountcalError as err:  # too few stops yet, one heading, ...; at the end, calibrate's refusal
            if final:  # no result that the recording would not give
                self.last.table = self.last.calibration = None
            self._waiting(str(err))
            self._suggest(None, None)
            return False
        self.last.table, self.last.calibration, self.last.still_not_kept = table, cal, dropped
        n = 0 if table is None else len(table)  # none: the drive alone (the stops refused), as calibrate gives
        event: dict[str, Any] = {"event": "fit", "stops": n, "model": list(cal.model)}
        event |= cal.angles.columns(slope=False)  # the message's flat columns, spelled by the type
        self.emit(event)
        met = target_met(cal, self.opts.target_deg)
        if met:
            self.emit({"event": "target_met", "target_deg": self.opts.target_deg})
            return True
        beyond = unreachable(cal, self.opts.target_deg)
        if beyond and not self.told_unreachable:  # said once: the sensor's part does not change with stops
            self.told_unreachable = True
            source = cal.systematic.source if cal.systematic is not None else None
            self.emit({"event": "target_unreachable", "systematic_deg": beyond, "source": source})
        if table is not None:
            self._suggest(table, cal)
        return False

    def _job(self) -> LogJob:
        """What ``calibrate`` is given for the session's recording (its sheet aside)."""
        o = self.opts
        log = LogOptions(dbc=o.dbc, mapping=o.mapping, channel=o.can_channel, axes=o.axes, heading_unit=o.heading_unit)
        return LogJob(
            paths=(str(self.recording),),
            log=log,
            detection=o.detection,
            uphill_azimuth_deg=o.uphill_azimuth_deg,
            options=o.options,
        )  # use "auto" and the default driving gates, as `calibrate REC.blf` without those options

    def _sheet_where(self) -> str:
        return f"the session's protocol sheet (beside {self.recording})"

    def _by(self) -> str:
        """Who states the sheet's β from uphill: the plan driven, or the headings the session asked for."""
        if self.opts.plan_beta_deg is not None:
            return "the session's protocol sheet (the headings of its plan, from uphill)"
        return "the session's protocol sheet (the headings it asked the driver for, from uphill)"

    def _waiting(self, why: str) -> None:
        if why != self.why:  # once per reason, not at every evaluation
            self.why = why
            self.emit({"event": "waiting", "why": why})

    def _suggest(self, table: StopTable | None, cal: Calibration | None) -> None:
        if self.opts.plan_beta_deg is not None:
            plan = self.opts.plan_beta_deg
            nxt = plan[len(self.beta)] if len(self.beta) < len(plan) else None
        elif table is not None and cal is not None:
            nxt = next_heading(table, cal, self.opts.target_deg)
        else:  # no fit yet: spread the first stops around the circle
            nxt = float((len(self.beta) * 120.0) % 360.0)
        self.suggestion = nxt
        self.last.suggestion_deg = nxt
        if nxt is not None:
            self.emit({"event": "next", "beta_deg": nxt})


def line_of(event: dict[str, Any]) -> str:
    """A line a person in a vehicle reads at a glance."""
    kind = event["event"]
    if kind == "started":
        return f"recording to {event['recording']}; waiting for the first stop"
    if kind == "stop":
        beta = "β unknown" if event["beta_deg"] is None else f"β {event['beta_deg']:g}°"
        return f"STOP {event['index']} ended ({event['t_end_s'] - event['t_start_s']:.0f} s, {beta})"
    if kind == "fit":
        angles = Angles.from_columns(event)

        def pm(a: AngleName) -> str:
            v, s = angles.value(a), angles.sigma(a)
            return f"{a} not determined" if v is None or s is None else f"{a} {v:+.3f}° ± {s:.3f}°"

        return f"{event['stops']} stops: " + "   ".join(pm(a) for a in ANGLE_NAMES[:3])
    if kind == "next":
        return f">>> DRIVE TO β = {event['beta_deg']:g}° (from uphill) and park"
    if kind == "target_met":
        return "TARGET MET: you can stop"
    if kind == "target_unreachable":
        parts = ", ".join(f"{a} {s:.3g}°" for a, s in event["systematic_deg"].items())
        return (
            f"TARGET NOT REACHABLE BY MORE STOPS: the sensor's systematic part ({parts}; {event['source']}) exceeds "
            "it; give the sensor's spec or a triad calibration, or accept a looser target"
        )
    if kind == "waiting":
        return f"  (not yet: {event['why']})"
    if kind == "silent":
        return f"bus silent for {event['after_s']:g} s: ending the session (the recording is kept)"
    if kind == "interrupted":
        return "interrupted: keeping what was measured"
    if kind == "ended":
        return f"session ended ({event['reason']}): {event['frames']} frames recorded in {event['recording']}"
    return json.dumps(event)


def event_line(event: dict[str, Any]) -> str:
    """An event as a JSON line, stamped with the wall-clock time."""
    return json.dumps({"time_utc": datetime.now(UTC).isoformat(timespec="milliseconds"), **event}) + "\n"


def json_sink(stream: IO[str]) -> Callable[[dict[str, Any]], None]:
    def write(event: dict[str, Any]) -> None:
        stream.write(event_line(event))
        stream.flush()

    return write


def session_files(prefix: Path) -> dict[str, Path]:
    """The files a session writes beside ``prefix``: its recording, stop table, protocol sheet and result."""
    names = {"recording": ".blf", "stops": "_stops.csv", "protocol": "_protocol.csv", "result": ".json"}
    return {key: prefix.with_name(prefix.name + end) for key, end in names.items()}


def write_outputs(session: Session, prefix: Path) -> list[Path]:
    """The session's stop table, protocol sheet (log clock) and result, as ``calibrate`` writes them."""
    written = []
    files = session_files(prefix)
    if session.table is not None:
        write_stop_table(session.table, files["stops"])
        written.append(files["stops"])
    if session.protocol is not None and not session.protocol.empty:
        with atomic_path(files["protocol"]) as tmp:
            session.protocol.to_csv(tmp, index=False, float_format="%.17g")
        written.append(files["protocol"])
    if session.calibration is not None:
        session.calibration.save(files["result"])
        written.append(files["result"])
    return written


def no_result_reason(session: Session) -> str:
    if session.samples is None or not len(session.samples):
        return "no accelerometer samples were decoded from the bus"
    return "the stops so far do not determine the mounting (see the messages above)"


def fail_if_empty(session: Session) -> None:
    if session.calibration is None:
        raise NotEnoughInformation(
            f"{session.recording}: no result ({no_result_reason(session)}); the recording is kept: "
            f"`mountcal calibrate {session.recording} --dbc …` re-runs it offline."
        )


@contextlib.contextmanager
def _ctrl_c_sets(flag: threading.Event) -> Iterator[None]:
    """Ctrl-C (SIGINT), SIGTERM and SIGHUP set ``flag`` instead of raising wherever the main thread happens to be.

    The session loop checks the flag between two steps, so an interrupt never lands between a
    stop being counted and its event being sent (the events would then miss a stop the result has).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    asked = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)  # a session ended by the system keeps its data too
    previous = {sig: signal.signal(sig, lambda *_: flag.set()) for sig in asked}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
