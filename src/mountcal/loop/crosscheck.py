"""Cross-checks between independent cues: a convention one of them gets wrong shows as a contradiction.

Each cue reads the vehicle's motion through its own conventions; where two measure the same thing,
a sign or reference one of them has wrong makes them disagree — by a sign or by half a turn, far
beyond any noise. The checks here run wherever the data hold two cues, and either pass, are not
tested (with the reason), or refuse with the option that fixes the convention:

- :func:`stops_sense`: the stops' order of headings against their pattern. With headings, the stop
  means go round their circle **counter-clockwise about the up axis** as β grows (docs/conventions.md
  §2) in a right-handed sensor frame; a mirrored sensor (one axis reversed: a left-handed triad) or
  headings that run clockwise make them go round the other way. Refused (:class:`Mirrored`), naming ``axes``.
- :func:`turn_handedness`: three readings of the vehicle's yaw rate while it drives — the gyro about the
  calibration's up axis, the compass heading's rate (clockwise from north, so ω = −dh/dt), and the
  lateral acceleration against ``v·ω`` (a left turn pushes the specific force to the left, +y).
  They agree in sign on a right-handed sensor; a negative correlation refuses, naming the cue that
  disagrees and the option — except where the lateral cue alone disagrees and the longitudinal one (``a_x``
  against ``dv/dt``) runs backwards too: x and y both reversed is the calibration's yaw half a turn off (the
  stops' headings from downhill), no mirror image, and the check fails (not confident) saying so.
- :func:`gyro_scale`: the same cues' sizes. The gyro's yaw rate against the heading's rate and against
  ``a_y / v`` is 1 (a few per cent: scale errors, sideslip); 57.3 is a gyro logged in deg/s and read as rad/s,
  1/57.3 one in rad/s stated to be deg/s. Refused with what states the unit when ``a_y / v`` (which has no
  unit to get wrong) says so and the heading, if any, agrees; the heading alone (its unit is a convention
  too) only says it. A quiet gyro on a highway, which no rate at rest or in a tight turn gives away
  (:mod:`mountcal.stops.gyro_unit`), still turns.
- :func:`heading_agreement`: two ways of reading a heading — the protocol's β (counter-clockwise
  from uphill) and the log's compass heading (clockwise from north) — must add up to one uphill
  azimuth; β − h constant instead means one of them runs the wrong way (the result is not confident).
- :func:`half_turn`: the stops' yaw against the drive's: half a turn apart, the headings were measured
  from downhill — the finding names the uphill azimuth (or the protocol) and the value that agrees.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from mountcal.core.conventions import FloatArray
from mountcal.core.errors import InputError
from mountcal.core.findings import Finding
from mountcal.core.option_names import option
from mountcal.core.result import Calibration, Check
from mountcal.io.input_conventions import negated
from mountcal.io.samples import Samples
from mountcal.stops.gyro_unit import DEG_PER_RAD, fix
from mountcal.stops.table import StopTable

SENSE_CLEAR = 0.9  # |mean e^{i(φ ∓ β)}| of the sense the stops follow
SENSE_OTHER = 0.5  # ... and at most this for the other sense
TURN_R = 0.5  # a correlation beyond ±0.5 between two yaw-rate cues decides their relative sign
TURN_BIN_S = 1.0  # the cues are compared as 1 s means (vibration and the clocks' jitter averaged out)
TURN_Z = 5.0  # ... and lies this many σ from no correlation (a refusal must not come from noise)
BINS_PER_INDEPENDENT = 3.0  # 1 s means of a drive correlate over a few seconds
MIN_SPEED_MPS = 3.0
SCALE_BAND = 2.5  # a yaw-rate ratio within this factor of 57.3 (or of 1/57.3) is a unit; within it of 1, agreement
HALF_TURN_DEG = 150.0  # stops and drive further apart than this in yaw: half a turn, not noise
AXES = "xyz"
TurnCues = dict[str, FloatArray] | None  # "gyro", "heading", "lateral": yaw rates as 1 s means while moving
# and, where the yaw is known and a speed logged, "forward" (a_x) and "speeding" (dv/dt), m/s², which tell a yaw
# half a turn off (x and y both reversed) from a mirror image (y alone)


class Mirrored(InputError):
    """The refusal of data that turn the wrong way (a mirror image): what a sign only assumed where the log
    was read can be turned round on (:mod:`mountcal.calibration.pipeline`)."""


# --------------------------------------------------------------------------- the stops' sense


def stops_sense(table: StopTable) -> Check:
    """Whether the stops go round their circle the way their headings say (see the module's docstring).

    Raises
    ------
    InputError
        They clearly go round the other way: a mirrored sensor or clockwise headings.
    """
    name = "handedness_stops"
    if table.beta_rad is None or table.headings == "none":
        return Check(name, None, "no headings: the stops' order round their circle cannot be compared with β")
    if table.site is not None and np.unique(table.site.astype(str)).size > 1:
        return Check(name, None, "stops at several sites (several circles): not tested")
    beta = table.beta_rad
    if abs(np.mean(np.exp(2j * beta))) > 0.5:
        return Check(name, None, "the headings are (nearly) opposite pairs only: both senses fit them")
    phi, normal = _phases(table.acc_s)
    right = float(abs(np.mean(np.exp(1j * (phi + beta)))))  # right-handed: φ = −β + const
    mirror = float(abs(np.mean(np.exp(1j * (phi - beta)))))
    if right >= SENSE_CLEAR and mirror <= SENSE_OTHER:
        return Check(name, True, f"the stops go round their circle counter-clockwise as β grows (|R| = {right:.2f})")
    if mirror >= SENSE_CLEAR and right <= SENSE_OTHER:
        fix = _suggested_flip(normal)
        raise Mirrored(
            table.source,
            "stop means that go round their circle counter-clockwise about the up axis as β grows (a "
            "right-handed sensor; β counter-clockwise from uphill, seen from above)",
            f"the opposite sense: the stops follow −β (|R| = {mirror:.2f}; the right sense {right:.2f})",
            f"Either the sensor's triad is left-handed (one axis reversed: a DBC sign, NovAtel RAWIMU's y, a phone "
            f"export): state its axes, e.g. {option('axes', fix.text)} (any one axis reversed gives the same "
            "vehicle-frame data; the angles refer to the axes you state, so reverse the one your device's "
            "documentation names) — or the headings run clockwise (compass headings: give them as the column "
            f"heading_deg with {option('uphill_azimuth')}, or β = 360° − heading from uphill).",
        )
    return Check(
        name,
        None,
        f"the stops' circle is too small against their scatter to show its sense (|R| {right:.2f} one way, "
        f"{mirror:.2f} the other)",
    )


def _phases(acc: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Each stop's angle round the circle about the up axis (right-handed basis), and that axis."""
    mean = acc.mean(axis=0)
    centred = acc - mean
    _, _, vt = np.linalg.svd(centred, full_matrices=True)
    normal = vt[2] if vt[2] @ mean > 0 else -vt[2]  # the circle's axis, +g up
    e1 = vt[0] - (vt[0] @ normal) * normal
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    u, v = centred @ e1, centred @ e2
    # Kåsa's circle fit: u² + v² = 2a·u + 2b·v + c (the stops need not be evenly spread)
    design = np.column_stack([2 * u, 2 * v, np.ones_like(u)])
    (a, b, _), *_ = np.linalg.lstsq(design, u**2 + v**2, rcond=None)
    return np.arctan2(v - b, u - a), normal


def _suggested_flip(up_s: FloatArray) -> Any:
    """The one axis to reverse in an example: z when the sensor reads −g up along it, else y."""
    return negated(2 if up_s[2] < -0.5 else 1)


# --------------------------------------------------------------------------- turns


def turn_handedness(samples: Samples, rot_vs: Rotation, cues: TurnCues) -> Check:
    """Whether the gyro, the heading and the lateral acceleration turn the same way (module docstring).

    ``cues`` are :func:`turn_cues` of ``samples`` with ``rot_vs``, the calibration (its up axis levels the
    gyro). Each available pair is compared over 1 s means while moving.

    Raises
    ------
    InputError
        A pair turns opposite ways: which cue disagrees, and the option that fixes it.
    """
    name = "handedness_turns"
    if cues is None:
        return Check(name, None, "the log holds no two of gyro, heading channel and speed with turns to compare")
    pairs = {}
    for a, b, ref in (("gyro", "heading", "heading"), ("lateral", "gyro", "gyro"), ("lateral", "heading", "heading")):
        if a in cues and b in cues:
            r = _sign_test(cues[a], cues[b], cues[ref])
            if r is not None:
                pairs[(a, b)] = r
    if not pairs:
        return Check(name, None, "too little turning to compare the cues (no correlation beyond 5σ)")
    shown = "; ".join(f"{_CUE[a]} against {_CUE[b]}: r = {r:+.2f}" for (a, b), r in pairs.items())
    wrong = {p for p, r in pairs.items() if r < 0}
    if not wrong:
        return Check(name, True, f"the cues turn the same way ({shown})")
    backwards = _backwards(wrong, set(pairs), cues)
    if backwards is not None:  # x reversed as well as y: no mirror image but a yaw half a turn off
        return Check(name, False, f"{backwards} ({shown})")
    raise Mirrored(
        samples.source or "log",
        "a gyro, heading and lateral acceleration that turn the same way (a right-handed sensor, a compass "
        "heading clockwise from north)",
        f"opposite turns: {shown}",
        _turn_advice(wrong, set(pairs), rot_vs),
    )


def _backwards(wrong: set[tuple[str, str]], tested: set[tuple[str, str]], cues: dict[str, FloatArray]) -> str | None:
    """Why only the lateral cue turns the wrong way, where the longitudinal one runs backwards too; else None."""
    # the lateral cue alone turns the wrong way, or it and the gyro disagree with no third cue to say which
    lateral = _odd(wrong, tested) == {"lateral"} or wrong == tested == {("lateral", "gyro")}
    if not lateral or "forward" not in cues:
        return None
    # the lateral cue already failed: this only chooses between two readings of it, so the correlation's
    # significance decides it without a floor on its size (grades and body pitch dilute a_x against dv/dt)
    r = _sign_test(cues["forward"], cues["speeding"], cues["speeding"], min_r=0.0)
    if r is None or r > 0:
        return None
    return (
        f"the calibration's yaw is half a turn off: the lateral acceleration turns mirrored and the longitudinal one "
        f"falls as the speed rises (r = {r:+.2f}), so its x and y axes both point the wrong way — a yaw turned by "
        "180°, not a mirror image. A yaw from the stops' headings turns so when they are half a turn off: an uphill "
        "azimuth that names the downhill direction, β measured from downhill, courses over ground of a vehicle that "
        "reversed into its spots"
    )


def gyro_scale(samples: Samples, cues: TurnCues) -> Check:
    """The gyro's yaw rate over the heading's rate and over ``a_y / v``, where they turn together (module docstring);
    ``cues`` are :func:`turn_cues` of ``samples``.

    Raises
    ------
    InputError
        Every reference puts the gyro 57.3 times too large (deg/s read as rad/s) or too small (rad/s said deg/s).
    """
    name = "gyro_scale"
    if cues is None or "gyro" not in cues:
        return Check(name, None, "the log holds no gyro beside a heading channel or a speed with turns to compare")
    ratios = {}
    for ref in ("heading", "lateral"):
        if ref in cues and (r := _sign_test(cues["gyro"], cues[ref], cues[ref])) is not None and r > 0:
            ok = np.isfinite(cues["gyro"]) & np.isfinite(cues[ref])
            ratios[ref] = float(np.std(cues["gyro"][ok]) / np.std(cues[ref][ok]))
    if not ratios:
        return Check(name, None, "too little turning to compare the gyro's yaw rate with another cue's")
    shown = "; ".join(f"{ratio:.3g} times {_CUE[ref]}" for ref, ratio in ratios.items())
    if "lateral" not in ratios and not 1.0 / SCALE_BAND < ratios["heading"] < SCALE_BAND:
        # a heading channel's unit is a convention too (--heading-unit): only a_y / v, which has none, can tell
        return Check(
            name,
            None,
            f"the gyro's yaw rate is {shown}: a gyro's or a heading channel's unit off by 57.3 would give it, and "
            "without turns at speed nothing in the log tells which",
        )
    if all(DEG_PER_RAD / SCALE_BAND < k < DEG_PER_RAD * SCALE_BAND for k in ratios.values()):
        raise InputError(
            samples.source or "log",
            "angular rates in rad/s, the gyro's unit as the format, the columns or the mapping state it",
            f"a yaw rate 57.3 times too large while the vehicle turns, as a gyro in deg/s reads: {shown}",
            f"The gyro is logged in deg/s: {fix(samples.source or '', samples.channels)}",
        )
    if all(1.0 / (DEG_PER_RAD * SCALE_BAND) < k < SCALE_BAND / DEG_PER_RAD for k in ratios.values()):
        raise InputError(
            samples.source or "log",
            "angular rates in rad/s, converted from the unit stated for the gyro",
            f"a yaw rate 57.3 times too small while the vehicle turns, as rad/s stated to be deg/s reads: {shown}",
            "The gyro is in rad/s already: drop the deg/s stated for it (a column map's :deg/s, a CAN mapping's "
            "[units] gyro, the DBC signal's unit).",
        )
    if all(1.0 / SCALE_BAND < k < SCALE_BAND for k in ratios.values()):
        return Check(name, True, f"the gyro's yaw rate is {shown}")
    if 1.0 / SCALE_BAND < ratios.get("lateral", 0.0) < SCALE_BAND:
        said = f"the gyro agrees with v·ω, the heading channel's rate does not (its unit, {option('heading_unit')}?)"
        return Check(name, None, f"the gyro's yaw rate is {shown}: {said}")
    return Check(name, None, f"the gyro's yaw rate is {shown}: no unit explains it, and it is not judged")


_CUE = {
    "gyro": "the gyro's yaw rate",
    "heading": "the heading's rate",
    "lateral": "the lateral acceleration (against v·ω)",
}


def _odd(wrong: set[tuple[str, str]], tested: set[tuple[str, str]]) -> set[str]:
    """The cue that disagrees: in every pair that turns the wrong way, and in no pair that agrees (empty when no
    single cue is)."""
    odd = {
        c
        for c in ("gyro", "heading", "lateral")
        if all(c in p for p in wrong) and all(p in wrong for p in tested if c in p)
    }
    return odd if len(odd) == 1 else set()


def _turn_advice(wrong: set[tuple[str, str]], tested: set[tuple[str, str]], rot_vs: Rotation) -> str:
    matrix = rot_vs.as_matrix()
    lateral_axis = AXES[int(np.argmax(np.abs(matrix[1])))]  # the sensor axis nearest the vehicle's y
    vertical_axis = AXES[int(np.argmax(np.abs(matrix[2])))]
    flip_lateral = negated(AXES.index(lateral_axis)).text
    odd = _odd(wrong, tested)
    mirrored = (
        f"the sensor is a mirror image (a left-handed triad: one axis reversed): state its axes with "
        f"{option('axes', flip_lateral)} (here the axis nearest the vehicle's lateral axis, sensor {lateral_axis}; "
        "reverse the one your device's documentation names)"
    )
    if odd == {"lateral"}:
        return f"The accelerometer reads turns mirrored: {mirrored}."
    if odd == {"gyro"}:
        return (
            f"The gyro turns the other way round than the heading and the accelerometer: its axis nearest the "
            f"vertical (sensor {vertical_axis}) has the wrong sign — a DBC sign or a gyro triad mirrored against the "
            f"accelerometer's. Correct it at its source ({option('axes')} reverses the accelerometer and the gyro "
            "together)."
        )
    if odd == {"heading"}:
        return (
            "The heading channel turns the other way round than the gyro and the accelerometer agree on: either it "
            "is no compass heading (clockwise from north) — an ENU yaw, counter-clockwise from east, converts as "
            f"90° − yaw — or the accelerometer alone is mirrored along its axis nearest the vertical (sensor "
            f"{vertical_axis}; a DBC sign): correct that signal at its source."
        )
    return f"Either {mirrored}, or one of the signals has the wrong sign at its source (a DBC factor)."


def turn_cues(samples: Samples, rot_vs: Rotation, yaw_known: bool) -> TurnCues:
    """The cues as 1 s means while moving: yaw rates (rad/s) and the lateral acceleration's ``a_y / v`` (which
    needs the calibration's yaw, ``yaw_known``); None when fewer than two are in the log."""
    t = samples.t_s
    if len(samples) < 10 or t[-1] - t[0] < 4 * TURN_BIN_S:
        return None
    edges = np.arange(t[0], t[-1], TURN_BIN_S)
    idx = np.searchsorted(t, edges)
    keep = np.diff(np.append(idx, t.size)) > 0
    edges, idx = edges[keep], idx[keep]
    counts = np.diff(np.append(idx, t.size)).astype(float)
    centre = edges + 0.5 * TURN_BIN_S

    def means(x: FloatArray) -> FloatArray:
        return np.asarray(np.add.reduceat(x, idx, axis=0) / counts[:, None], dtype=np.float64)

    cues: dict[str, FloatArray] = {}
    speed = samples.channels.get("speed_mps")
    moving = np.ones(centre.size, dtype=bool)
    v = None
    if speed is not None and speed.t_s.size >= 2:
        v = np.interp(centre, speed.t_s, speed.value)
        moving = v >= MIN_SPEED_MPS
    if samples.gyro_s is not None:
        cues["gyro"] = rot_vs.apply(means(samples.gyro_s))[:, 2]
    heading = samples.channels.get("heading_deg")
    if heading is not None and heading.t_s.size >= 4:
        h = np.unwrap(np.radians(heading.value))
        at = np.interp(np.append(edges, edges[-1] + TURN_BIN_S), heading.t_s, h)
        inside = (centre >= heading.t_s[0]) & (centre <= heading.t_s[-1])
        rate = -np.diff(at) / TURN_BIN_S  # compass: clockwise from north; ω counter-clockwise
        cues["heading"] = np.where(inside, rate, np.nan)
    if yaw_known and v is not None:
        acc_v = rot_vs.apply(means(samples.acc_s))
        with np.errstate(divide="ignore", invalid="ignore"):
            cues["lateral"] = np.where(moving, acc_v[:, 1] / v, np.nan)  # ω = a_y / v in a steady turn
        cues["forward"], cues["speeding"] = acc_v[:, 0], np.gradient(v, centre)
    available = [k for k in ("gyro", "heading", "lateral") if k in cues]
    if len(available) < 2:
        return None
    return {k: np.where(moving, c, np.nan) for k, c in cues.items()}


@dataclass
class TurnWatch:
    """:func:`turn_handedness` and :func:`gyro_scale` over a stream's chunks, with a calibration made elsewhere
    (``mountcal rotate``): the chunks' 1 s cues are gathered until the turns decide, then the watch stops.

    A log rotated with a calibration from another session has had none of the checks ``calibrate`` runs on it: a
    gyro stated deg/s that logs rad/s (57.3 times too small once converted), a gyro axis reversed by a DBC sign,
    a calibration whose yaw is half a turn off for this vehicle would each be written as vehicle-frame data. A
    mismatch raises (the output is then dropped); ``checks`` says what was found or why nothing was tested.
    """

    rot_vs: Rotation
    yaw_known: bool
    scale: bool = True  # the gyro's unit checked too (a DataFrame's gyro may be in any unit)
    unable: str = ""  # why the log's turns cannot be checked at all (it holds no speed and no heading)
    checks: tuple[Check, ...] = ()
    _parts: list[dict[str, FloatArray]] = field(default_factory=list)

    @classmethod
    def of(cls, cal: Calibration, scale: bool = True) -> TurnWatch:
        """The watch for a log rotated with ``cal`` (the lateral cue needs its yaw)."""
        return cls(cal.rot_vs, cal.yaw_determined, scale)

    @property
    def done(self) -> bool:
        """Every check the gathered cues allow has decided (with no gyro, there is no scale to check)."""
        return bool(self.unable) or (bool(self.checks) and all(c.passed is not None for c in self.checks))

    def lines(self) -> tuple[str, ...]:
        """What the turns showed, for a report (a mismatch was refused before)."""
        if self.unable or not self.checks:
            why = self.unable or "too little driving at speed beside a second cue"
            return (f"gyro scale and turn handedness not checked: {why}",)
        return tuple(f"{c.name}: {'checked' if c.passed else 'not checked'}, {c.reason}" for c in self.checks)

    def look(self, samples: Samples) -> None:
        """Gather ``samples``' cues and check all gathered so far.

        Raises
        ------
        InputError
            The turns show a gyro off by 57.3, cues that turn opposite ways, or a yaw half a turn off.
        """
        if self.done:
            return
        cues = turn_cues(samples, self.rot_vs, self.yaw_known)
        if cues is None:
            return
        self._parts.append(cues)
        keys = {k for part in self._parts for k in part}
        gathered = {
            k: np.concatenate([p.get(k, np.full(next(iter(p.values())).size, np.nan)) for p in self._parts])
            for k in keys
        }
        try:
            half = turn_handedness(samples, self.rot_vs, gathered)
        except Mirrored as err:  # or the calibration is not this log's mounting: a sensor moved since
            raise InputError(
                err.where,
                err.expected,
                err.found,
                f"The calibration was made from another log: if the sensor was moved or remounted since, calibrate "
                f"this log. Otherwise: {err.todo}",
            ) from err
        self.checks = (half, gyro_scale(samples, gathered)) if self.scale and "gyro" in gathered else (half,)
        if half.passed is False:
            raise InputError(
                samples.source or "log",
                "a calibration whose vehicle frame points where this vehicle drives",
                half.reason,
                "The calibration was made from another log: if the sensor was moved or remounted since, calibrate "
                "this log; otherwise calibrate the vehicle again (the stops' headings from uphill, or a drive in the "
                "same log) and rotate with that calibration.",
            )


def _sign_test(a: FloatArray, b: FloatArray, reference: FloatArray, min_r: float = TURN_R) -> float | None:
    """The correlation of two cues over the 1 s bins both have, when it decides their relative sign: beyond
    ±:data:`TURN_R` and :data:`TURN_Z` σ from none (Fisher's z, neighbouring bins counted as one in
    :data:`BINS_PER_INDEPENDENT`). ``reference`` is the cue whose turning must be present in those bins; ``min_r``
    the size below which a correlation decides nothing however significant."""
    ok = np.isfinite(a) & np.isfinite(b) & np.isfinite(reference)
    n_eff = ok.sum() / BINS_PER_INDEPENDENT
    if n_eff < 4:
        return None
    x, y = a[ok] - a[ok].mean(), b[ok] - b[ok].mean()
    den = float(np.sqrt((x @ x) * (y @ y)))
    if den == 0:
        return None
    r = float(np.clip(x @ y / den, -0.999999, 0.999999))
    decided = abs(r) >= min_r and abs(np.arctanh(r)) * np.sqrt(n_eff - 3) >= TURN_Z
    return r if decided else None


# --------------------------------------------------------------------------- two readings of a heading


def heading_agreement(table: StopTable) -> Check:
    """β (stated from uphill) against the log's compass heading at each stop: β + h must be one azimuth."""
    name = "heading_directions"
    compass = table.heading_deg
    if table.beta_rad is None or table.headings != "uphill" or compass is None:
        return Check(name, None, "no stated β from uphill beside a compass heading channel")
    if any(c.name == "uphill_azimuth" for c in table.conventions):
        return Check(name, None, "β were computed from the compass heading (one reading)")
    beta = np.degrees(table.beta_rad)
    same = np.exp(1j * np.radians(beta + compass))
    r_same, r_opposite = float(abs(same.mean())), float(abs(np.mean(np.exp(1j * np.radians(beta - compass)))))
    azimuth = float(np.degrees(np.angle(same.mean())) % 360.0)
    if r_same >= SENSE_CLEAR:
        return Check(
            name, True, f"β and the compass heading imply one uphill azimuth, {azimuth:.1f}° (|R| = {r_same:.2f})"
        )
    if r_opposite >= SENSE_CLEAR and r_same <= SENSE_OTHER:
        return Check(
            name,
            False,
            f"β (counter-clockwise from uphill) and the heading channel (a compass heading, clockwise from north) turn "
            f"opposite ways from stop to stop (|R| {r_opposite:.2f} against {r_same:.2f}): one of them is not what its "
            "convention says",
        )
    return Check(name, None, f"inconclusive (|R| {r_same:.2f} for one azimuth)")


# --------------------------------------------------------------------------- half a turn


def half_turn(
    stops_yaw_deg: float | None, drive_yaw_deg: float | None, uphill_azimuth_deg: float | None, protocol: bool
) -> tuple[Check, Finding | None]:
    """The stops' yaw against the drive's: half a turn apart names the headings' reference."""
    name = "stops_vs_driving_direction"
    if stops_yaw_deg is None or drive_yaw_deg is None:
        return Check(name, None, "the stops and the drive do not both determine yaw"), None
    diff = float((drive_yaw_deg - stops_yaw_deg + 180.0) % 360.0 - 180.0)
    if abs(diff) < HALF_TURN_DEG:
        return Check(name, True, f"the stops' yaw and the drive's are {abs(diff):.1f}° apart, not half a turn"), None
    if uphill_azimuth_deg is not None:
        fix = (
            f"the uphill azimuth {option('uphill_azimuth', f'{uphill_azimuth_deg:g}')} names the downhill direction: "
            f"{option('uphill_azimuth', f'{(uphill_azimuth_deg + 180.0) % 360.0:g}')} makes them agree (or the "
            "heading channel is a course over ground, the direction of motion, and the vehicle reversed into its "
            "spots)"
        )
    elif protocol:
        fix = "the protocol's β are measured from downhill: add 180° to its beta_deg"
    else:
        fix = "the headings' β are measured from downhill: add 180° to them"
    size = f"{diff:+.1f}° (stops {stops_yaw_deg:.2f}°, drive {drive_yaw_deg:.2f}°): {fix}"
    finding = Finding(
        test=name,
        what="the stops' yaw and the drive's differ by half a turn (the headings' reference)",
        size=size,
        statistic=abs(diff),
        dof=None,
        p_value=None,
        log10_p=None,
        reason="a difference in degrees, no test statistic: half a turn is a reference, not noise",
    )
    return Check(name, False, size), finding
