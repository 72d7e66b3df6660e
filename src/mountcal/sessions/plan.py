"""Plan a parking session from the Cramér–Rao bound: how many stops, which headings, how long, what slope.

The bound of the chosen model (docs/conventions.md §5) is evaluated for evenly spaced headings at a nominal
mounting (aligned sensor; the σ of roll, pitch and yaw about the vehicle axes hardly depend on it).
Noise assumption: the accelerometer noise is white, so a stop mean averages it down to
``σ_mean = σ_sample / √(rate · t_avg)``, where ``t_avg = dwell − 2·trim`` is what stop detection keeps
of each parked period (it trims settling at both ends). Correlated vibration averages down more
slowly; ``noise_from_log`` therefore takes the *white-equivalent* noise ``√(n · var(mean))`` of real
stops, whose variance of the mean comes from batch means and includes that correlation.

Every σ a calibration reports is total: the statistical part (the bound) and the systematic part, the
sensor's limits propagated through the fit's gain (:mod:`mountcal.loop.systematic`) — so the plan predicts
both at each design and searches on their root sum of squares. Scale and cross-axis errors are not seen
by stops on one slope: their part is a floor no number of stops or dwell lowers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from mountcal.calibration.fit import BASE, WITH_OFFSET
from mountcal.calibration.options import parse_model
from mountcal.core.angles import ANGLE_NAMES, AngleName, AngleValues
from mountcal.core.atomic import atomic_path
from mountcal.core.conventions import G_N, FloatArray
from mountcal.core.errors import InputError, NotEnoughInformation
from mountcal.core.option_names import option
from mountcal.core.output_suffix import check_output_suffix
from mountcal.core.ranges import QUANTITIES, check
from mountcal.core.result import Systematic
from mountcal.estimate import effects as registry
from mountcal.estimate.bound import crb_deg, true_state
from mountcal.estimate.sensor_errors import SensorErrors, from_spec
from mountcal.io.logs import read_log
from mountcal.io.reader import LogOptions
from mountcal.io.sensor_spec import DEFAULT as DEFAULT_SPEC
from mountcal.loop.systematic import angle_sigmas, propagate
from mountcal.simulate.stops import simulate_stops
from mountcal.stops.detect import StopDetection, detect_stops
from mountcal.stops.protocol_clock import PLAN_MARK
from mountcal.stops.table import StopTable

ANGLES: tuple[AngleName, ...] = ANGLE_NAMES[:3]  # the angles a target names
DWELLS_S = (15.0, 20.0, 30.0, 45.0, 60.0, 90.0, 120.0, 180.0, 300.0)  # candidate dwell times when not given
SLOPES_DEG = tuple(float(s) for s in np.arange(1.0, 15.01, 0.5))  # candidate slopes when not given
FLOOR_NOISE_MPS2 = 1e-7  # stop noise standing for "noise-free" in the systematic floor (10 ng)
MIN_STOPS = 4  # three headings determine the circle only just; one more gives the fit a residual


@dataclass(frozen=True)
class Noise:
    """Per-sample accelerometer noise (1σ per axis, m/s²) and the sample rate; where they came from."""

    sample_sigma_mps2: float
    rate_hz: float
    source: str

    def stop_sigma_mps2(self, averaged_s: float) -> float:
        """1σ of a stop mean over ``averaged_s`` seconds (white noise)."""
        return self.sample_sigma_mps2 / math.sqrt(self.rate_hz * averaged_s)


@dataclass(frozen=True)
class Request:
    """What the user asks for (targets are 1σ in degrees; yaw may be left out)."""

    target_deg: dict[str, float]
    noise: Noise
    terms: tuple[str, ...] = WITH_OFFSET
    slope_deg: float | None = None  # None: find the smallest slope that reaches the target
    max_stops: int = 24
    stop_s: float | None = None  # None: choose the dwell
    drive_s: float = 60.0  # time to reposition between stops (counts in the session time)
    detection: StopDetection = field(default_factory=StopDetection)
    sensor: SensorErrors = field(default_factory=lambda: from_spec(DEFAULT_SPEC))  # limits for the systematic part


@dataclass(frozen=True)
class Plan:
    """A protocol and the σ it predicts; ``reachable`` False with ``reason`` when none meets the target."""

    request: Request
    reachable: bool
    slope_deg: float
    beta_deg: tuple[float, ...]  # in driving order
    stop_s: float
    sigma_deg: AngleValues  # predicted total 1σ of roll, pitch, yaw (and slope), as calibrate reports
    statistical_deg: AngleValues  # its statistical part (the bound)
    systematic_deg: AngleValues  # its systematic part (the sensor's limits)
    reason: str = ""

    @property
    def n_stops(self) -> int:
        return len(self.beta_deg)

    @property
    def session_s(self) -> float:
        return session_time(self.n_stops, self.stop_s, self.request.drive_s)

    def protocol_frame(self) -> pd.DataFrame:
        """The protocol sheet: planned times from the session start (replace them with the log's clock)."""
        starts = np.arange(self.n_stops) * (self.stop_s + self.request.drive_s)
        return pd.DataFrame({"t_start_s": starts, "t_end_s": starts + self.stop_s, "beta_deg": self.beta_deg})

    def lines(self) -> list[str]:
        """A readable answer."""
        req = self.request
        model = ", ".join(req.terms)
        noise = (
            f"noise {req.noise.sample_sigma_mps2 * 1e3 / G_N:.3g} mg per sample at {req.noise.rate_hz:g} Hz "
            f"({req.noise.source}; white noise assumed)"
        )
        pred = ", ".join(
            f"{a} {_fmt(self.sigma_deg.get(a))} (target {req.target_deg[a]:g}°)" for a in ANGLES if a in req.target_deg
        )
        parts = ", ".join(
            f"{a} {_fmt(self.statistical_deg.get(a))} / {_fmt(self.systematic_deg.get(a))}"
            for a in ANGLES
            if a in req.target_deg
        )
        sensor = f"  σ statistical / systematic: {parts} (sensor: {req.sensor.source})"
        if not self.reachable:
            return [
                f"not reachable, because {self.reason}",
                f"  best within the limits: {self.n_stops} stops of {self.stop_s:g} s on a {self.slope_deg:g}° slope: "
                + pred,
                sensor,
                f"  model {model}; {noise}",
            ]
        return [
            f"plan: {self.n_stops} stops of {self.stop_s:g} s each on a {self.slope_deg:g}° slope, headings "
            f"{', '.join(f'{b:g}°' for b in self.beta_deg)} (β from uphill, in driving order)",
            f"  predicted 1σ (total): {pred}",
            sensor,
            f"  session ≈ {self.session_s / 60:.0f} min with {req.drive_s:g} s between stops; model {model}",
            f"  {noise}",
        ]

    def write_protocol(self, path: str | Path) -> None:
        """Write the protocol sheet that ``calibrate --protocol`` reads (atomically; CSV, whatever the name
        says but another format)."""
        check_output_suffix(option("output"), path, (".csv",))
        header = (
            f"{PLAN_MARK} {self.n_stops} stops of {self.stop_s:g} s on a {self.slope_deg:g}° slope. The times are "
            "placeholders from the session start: replace t_start_s, t_end_s with the log's clock.\n"
        )
        with atomic_path(path) as tmp:
            tmp.write_text(header + self.protocol_frame().to_csv(index=False, float_format="%.6g"), encoding="utf-8")


def session_time(n_stops: int, stop_s: float, drive_s: float) -> float:
    return n_stops * stop_s + (n_stops - 1) * drive_s


def parse_target(spec: str) -> dict[str, float]:
    """``roll=0.1,pitch=0.1,yaw=0.5`` → {"roll": 0.1, ...} (any subset, positive degrees)."""
    out: dict[str, float] = {}
    for part in (p.strip() for p in spec.split(",") if p.strip()):
        name, _, value = part.partition("=")
        try:
            number = float(value)
        except ValueError:
            number = float("nan")
        if name.strip() not in ANGLES or not QUANTITIES["sigma_deg"].holds(number) or name.strip() in out:
            raise InputError(
                "the target",
                f"a comma list of roll=σ, pitch=σ, yaw=σ (1σ in degrees, {QUANTITIES['sigma_deg'].interval()}, "
                "each at most once)",
                repr(spec),
                "For example roll=0.1,pitch=0.1,yaw=0.5.",
            )
        out[name.strip()] = number
    if not out:
        raise InputError("the target", "at least one of roll=σ, pitch=σ, yaw=σ", repr(spec), "Name a target.")
    return out


def plan_terms(model: str) -> tuple[str, ...]:
    """The fixed model a plan is made for: rotation,slope or rotation,slope,bias (the offset)."""
    terms = parse_model(model)
    if terms not in (BASE, WITH_OFFSET):
        off = registry.offset().name
        raise InputError(
            "the model of the plan",
            f"{','.join(BASE)} (no {off}) or {','.join(WITH_OFFSET)} (an unknown constant {off})",
            repr(model),
            "A plan needs a fixed model; choose the one you will calibrate with.",
        )
    return terms


def unit_bound(n_stops: int, slope_deg: float, terms: tuple[str, ...]) -> AngleValues:
    """Bound (degrees) of roll, pitch, yaw, slope for ``n_stops`` evenly spaced headings at 1 m/s² stop noise."""
    return bound_of_headings(headings(n_stops), slope_deg, terms, 1.0)


def headings(n_stops: int) -> tuple[float, ...]:
    """Evenly spaced headings in driving order (one loop around the circle)."""
    return tuple(float(b) for b in np.arange(n_stops) * 360.0 / n_stops)


def bound_of_headings(
    beta_deg: tuple[float, ...] | FloatArray, slope_deg: float, terms: tuple[str, ...], stop_sigma_mps2: float
) -> AngleValues:
    """The bound for given headings and stop-mean noise, at a nominal (aligned) mounting."""
    return table_bound(_design_table(beta_deg, slope_deg, stop_sigma_mps2), slope_deg, terms)


def _design_table(beta_deg: tuple[float, ...] | FloatArray, slope_deg: float, stop_sigma_mps2: float) -> StopTable:
    """Noise-free stops at an aligned mounting, each mean with covariance ``stop_sigma² I``."""
    table, _ = simulate_stops(0.0, 0.0, 0.0, slope_deg=slope_deg, beta_deg=np.asarray(beta_deg), noise_g=0.0)
    return replace(table, cov_s=np.broadcast_to(np.eye(3) * stop_sigma_mps2**2, (len(table), 3, 3)).copy())


def table_bound(table: StopTable, slope_deg: float, terms: tuple[str, ...]) -> AngleValues:
    """The bound of a stop table (its stop covariances) at an aligned mounting on ``slope_deg``."""
    from scipy.spatial.transform import Rotation

    crb = crb_deg(table, true_state(Rotation.identity(), slope_deg, G_N), terms, G_N)
    return AngleValues(None, None, None, None) if crb is None else crb


def systematic_of_headings(
    beta_deg: tuple[float, ...] | FloatArray,
    slope_deg: float,
    terms: tuple[str, ...],
    stop_sigma_mps2: float,
    sensor: SensorErrors,
) -> AngleValues:
    """The systematic 1σ (degrees) calibrate would report for this design: ``sensor``'s limits through the gain."""
    return _systematic(_design_table(beta_deg, slope_deg, 1.0), slope_deg, terms, stop_sigma_mps2, sensor)


def _systematic(
    unit: StopTable, slope_deg: float, terms: tuple[str, ...], stop_sigma_mps2: float, sensor: SensorErrors
) -> AngleValues:
    """As calibrate's (mountcal.loop.systematic.assess) at the design's true state; ``unit``: stops with unit
    covariance.

    The gain does not depend on the stop noise; what the residual sees of an error does, as 1/σ,
    which is the noise scale ``propagate`` divides by.
    """
    from scipy.spatial.transform import Rotation

    from mountcal.estimate import full

    state = true_state(Rotation.identity(), slope_deg, G_N)
    names = tuple(full.StaticModel(unit, terms, G_N).names)
    cov, _, _, _ = propagate(unit, state, names, terms, G_N, sensor, stop_sigma_mps2)
    sig = Systematic.angles_of(angle_sigmas(cov, names, state.rot_vs, yaw=True, slope=True))
    return AngleValues(*(float(v or 0.0) for _, v in sig.items()))


def _total(stat: AngleValues, sys: AngleValues) -> AngleValues:
    """Root sum of squares, as calibrate combines them (an undetermined angle stays undetermined)."""
    return AngleValues(*(None if v is None else float(np.hypot(v, sys[k] or 0.0)) for k, v in stat.items()))


def make_plan(req: Request) -> Plan:
    """The shortest session (stops × dwell + drives) meeting every target, or why none does.

    Without a slope the smallest candidate slope at which the target is reachable is chosen (a
    gentle slope is easier to find); the session is then the shortest at that slope.
    """
    cfg = req.detection
    shortest = cfg.min_duration_s + 2 * cfg.trim_s
    if req.stop_s is not None and req.stop_s < shortest:
        raise InputError(
            "the dwell of each stop",
            f"a dwell of at least {shortest:g} s (stop detection trims {cfg.trim_s:g} s at both ends and keeps "
            f"stops of ≥ {cfg.min_duration_s:g} s)",
            f"{req.stop_s:g} s",
            "Plan longer stops.",
        )
    if req.max_stops < MIN_STOPS:
        raise InputError("the most stops", f"at least {MIN_STOPS}", str(req.max_stops), "Allow more stops.")
    # the search tries every count up to it on every candidate slope: a stated maximum bounds its time
    check("planned_stops", req.max_stops, "the most stops", todo="Plan with fewer stops (12–24 is usual).")
    if req.slope_deg is not None and not 0.0 <= req.slope_deg < 45.0:
        raise InputError("the slope", "a slope in [0°, 45°)", f"{req.slope_deg:g}°", "Give the slope in degrees.")
    dwells = (req.stop_s,) if req.stop_s is not None else tuple(d for d in DWELLS_S if d >= shortest)
    slopes = (req.slope_deg,) if req.slope_deg is not None else SLOPES_DEG
    best_miss: tuple[float, Plan] | None = None
    for slope in slopes:
        found = _best_at_slope(req, slope, dwells)
        if found.reachable:
            return found
        miss = max(_shortfall(found.sigma_deg, req.target_deg).values())
        if best_miss is None or miss < best_miss[0]:
            best_miss = (miss, found)
    assert best_miss is not None
    plan = best_miss[1]
    return replace(plan, reason=_why_not(req, plan, dwells))


def _best_at_slope(req: Request, slope: float, dwells: tuple[float, ...]) -> Plan:
    """The shortest protocol on one slope whose total σ reaches the target, else the most precise one."""
    trim = 2 * req.detection.trim_s
    candidates = []
    for n in range(MIN_STOPS, req.max_stops + 1):
        unit = unit_bound(n, slope, req.terms)
        table = _design_table(headings(n), slope, 1.0)
        for dwell in dwells:
            s = req.noise.stop_sigma_mps2(dwell - trim)
            stat = unit.times(s)
            sys = _systematic(table, slope, req.terms, s, req.sensor)
            candidates.append((session_time(n, dwell, req.drive_s), n, dwell, stat, sys))
    reachable = [c for c in candidates if max(_shortfall(_total(c[3], c[4]), req.target_deg).values()) <= 1.0]
    if reachable:
        _, n, dwell, stat, sys = min(reachable, key=lambda c: (c[0], c[1]))
        return Plan(req, True, slope, headings(n), dwell, _total(stat, sys), stat, sys)
    _, n, dwell, stat, sys = min(
        candidates, key=lambda c: (max(_shortfall(_total(c[3], c[4]), req.target_deg).values()), c[0])
    )
    return Plan(req, False, slope, headings(n), dwell, _total(stat, sys), stat, sys)


def systematic_floor(req: Request, slope: float) -> AngleValues:
    """The systematic σ on one slope with noise-free stops: what no number of stops or dwell lowers."""
    n = req.max_stops
    return _systematic(_design_table(headings(n), slope, 1.0), slope, req.terms, FLOOR_NOISE_MPS2, req.sensor)


def _shortfall(sigma: AngleValues, target: dict[str, float]) -> dict[str, float]:
    """σ / target per targeted angle (inf when the angle is not determined)."""
    return {a: (np.inf if (s := sigma[a]) is None else s / t) for a, t in target.items()}


def _why_not(req: Request, plan: Plan, dwells: tuple[float, ...]) -> str:
    over = [a for a, r in _shortfall(plan.sigma_deg, req.target_deg).items() if r > 1.0]
    slopes = (req.slope_deg,) if req.slope_deg is not None else SLOPES_DEG
    floors = [systematic_floor(req, slope) for slope in slopes]
    floor = {a: min(f[a] or 0.0 for f in floors) for a in over}
    below = [a for a in over if floor[a] >= req.target_deg[a]]
    parts = []
    if below:
        where = (
            f"a {req.slope_deg:g}° slope" if req.slope_deg is not None else f"any one slope up to {SLOPES_DEG[-1]:g}°"
        )
        parts.append(
            "the sensor's systematic part ("
            + ", ".join(f"{a} ≥ {floor[a]:.3g}°, target {req.target_deg[a]:g}°" for a in below)
            + f"; {req.sensor.source}) cannot be reached by any number of stops or dwell on {where}: scale and "
            "cross-axis errors are not seen by stops on one slope. A triad calibration (`mountcal triad`, then "
            f"{option('triad')}), the sensor's own spec ({option('sensor_spec')}, if tighter), or stops on two slopes "
            "of different inclination would remove it"
            + (
                f"; yaw's floor is also the headings' ±{req.sensor.limits.heading_deg}° against the fall "
                f"line (heading_deg in {option('sensor_spec')}, if better known; or yaw from a drive with speed)"
                if "yaw" in below and req.sensor.heading_u_rad > 0
                else ""
            )
        )
    for a in (a for a in over if a not in below):
        got = plan.sigma_deg.get(a)
        text = (
            f"{a} is not determined"
            if got is None
            else f"{a} reaches at best {got:.3g}° (target {req.target_deg[a]:g}°)"
        )
        text += f" with ≤ {req.max_stops} stops of ≤ {max(dwells):g} s"
        if req.slope_deg is not None:
            text += f" on a {req.slope_deg:g}° slope"
            need = _slope_needed(req, a, dwells)
            if need is not None:
                text += f"; it needs a slope of ≥ {need:g}°"
            elif a == "yaw" and req.slope_deg < SLOPES_DEG[-1]:
                text += f"; not even on a {SLOPES_DEG[-1]:g}° slope"
        else:
            text += f" on any slope up to {SLOPES_DEG[-1]:g}°"
        parts.append(text)
    why = "; ".join(parts)
    rest = [a for a in over if a not in below]
    if "yaw" in rest:
        why += " (yaw precision grows as 1/sin(slope): on level ground yaw is unobservable)"
    if registry.offset().name in req.terms and any(a in rest for a in ("roll", "pitch")):
        why += " (with an unknown bias, roll and pitch come from the circle's radius g·sin(slope) only)"
    return why + (". Allow more or longer stops, a steeper slope, or a quieter sensor." if rest else ".")


def _slope_needed(req: Request, angle: str, dwells: tuple[float, ...]) -> float | None:
    """The smallest candidate slope at which ``angle`` alone reaches its target within the limits."""
    one = replace(req, target_deg={angle: req.target_deg[angle]})
    for slope in SLOPES_DEG:
        if _best_at_slope(one, slope, dwells).reachable:
            return slope
    return None


def noise_from_log(paths: list[str], options: LogOptions, detection: StopDetection | None = None) -> Noise:
    """The white-equivalent per-sample noise and the sample rate from a log's still periods."""
    samples = read_log(paths, options)
    stops = detect_stops(samples, detection)
    where = " + ".join(paths)
    if not stops:
        raise NotEnoughInformation(
            f"{where}: no parked period found to measure the noise on; record a log with the vehicle parked "
            "(engine as in the session), or give the sensor's noise."
        )
    rate = 1.0 / float(np.median(np.diff(samples.t_s)))
    equivalent = [float(np.sqrt(np.mean(np.diag(s.acc_cov_mean_s)) * s.n)) for s in stops]
    return Noise(
        float(np.median(equivalent)),
        rate,
        f"measured on {len(stops)} still period(s) of {where}, white-equivalent of the stop means' variance",
    )


def _fmt(x: float | None) -> str:
    return "not determined" if x is None else f"{x:.3g}°"


def monte_carlo_rms(plan: Plan, runs: int, seed: int, bias_mg: float = 20.0) -> dict[str, float]:
    """RMS error (degrees) of ``calibrate`` with the plan's fixed model over simulated sessions of the plan.

    Each run draws a mounting (roll, pitch within ±10°, any yaw) and, for a model with a bias, a
    bias of ``bias_mg`` in a random direction; the stop means carry the noise the plan assumes.
    """
    from mountcal.calibration.fit import calibrate
    from mountcal.calibration.options import Options
    from mountcal.simulate.stops import random_bias

    rng = np.random.default_rng(seed)
    req = plan.request
    averaged = plan.stop_s - 2 * req.detection.trim_s
    stop_sigma = req.noise.stop_sigma_mps2(averaged)
    options = Options(model=",".join(req.terms))
    errors: dict[str, list[float]] = {a: [] for a in ANGLES}
    for _ in range(runs):
        roll, pitch = rng.uniform(-10.0, 10.0, size=2)
        yaw = rng.uniform(-180.0, 180.0)
        bias = random_bias(bias_mg * 1e-3 * G_N, rng) if registry.offset().name in req.terms else None
        table, truth = simulate_stops(
            roll,
            pitch,
            yaw,
            slope_deg=plan.slope_deg,
            beta_deg=np.asarray(plan.beta_deg),
            noise_g=stop_sigma / G_N,
            samples_per_stop=max(int(req.noise.rate_hz * averaged), 2),
            bias_mps2=bias,
            seed=rng,
        )
        cal = calibrate(table, options)
        for a, true in zip(ANGLES, truth.angles_deg, strict=True):
            if a in req.target_deg:
                got = cal.angles.value(a)
                errors[a].append(np.nan if got is None else float((got - true + 180.0) % 360.0 - 180.0))
    return {a: float(np.sqrt(np.mean(np.square(e)))) for a, e in errors.items() if e}
