"""A simulator of drives: the truth generator for yaw from driving (:mod:`mountcal.estimate.driving`).

A drive is a random but realistic sequence of manoeuvres — launches from standstill, cruising with
gentle speed changes and curves, braking to a stop, slow 90° turns at junctions — on a road whose
grade and cross slope vary with the distance travelled. The body pitches and rolls on its
suspension with the longitudinal and lateral acceleration. The IMU sees (docs/conventions.md §1)::

    acc_s = R_vsᵀ · f_v + b + n,      gyro_s = R_vsᵀ · ω_v + b_ω + n_ω

with ``f_v`` the specific force of the body (kinematic acceleration minus gravity, so +g up at
rest) and ``ω_v`` its angular rate, both in the vehicle frame (ISO 8855: x forward, y left, z up).
The speed channel is the along-road speed sampled on its own clock, ``t_logged = t_true +
speed_delay_s``, with noise, quantisation and an optional scale error (tyre radius), as a CAN,
OBD or GNSS speed would be.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from mountcal.core.conventions import G_N, FloatArray, angles_from_rot_vs, rot_vs_from_angles
from mountcal.io.samples import Channel, Samples

PITCH_PER_ACC_RAD = 0.0025  # body pitch (nose up) per m/s² of longitudinal acceleration (≈ 1.4°/g)
ROLL_PER_ACC_RAD = 0.008  # body roll (outward) per m/s² of lateral acceleration (≈ 4.5°/g)


@dataclass(frozen=True)
class DriveTruth:
    """The true values behind a simulated drive (units in the names)."""

    rot_vs: Rotation
    g_mps2: float
    bias_mps2: FloatArray = field(default_factory=lambda: np.zeros(3))
    gyro_bias_rad_s: FloatArray = field(default_factory=lambda: np.zeros(3))
    speed_delay_s: float = 0.0  # the speed clock lags the IMU clock by this much
    speed_scale: float = 1.0  # logged speed / true speed
    scale_matrix: FloatArray = field(default_factory=lambda: np.eye(3))  # acc_s = M · R_vsᵀ f_v + b
    pitch_per_acc_rad: float = 0.0  # body pitch (nose up) per m/s² of longitudinal acceleration
    roll_per_acc_rad: float = 0.0  # body roll (outward) per m/s² of lateral acceleration
    remount_at_s: float | None = None  # from this time on the sensor is mounted by remount_rot_vs
    remount_rot_vs: Rotation | None = None

    @property
    def angles_deg(self) -> tuple[float, float, float]:
        """Roll, pitch, yaw in degrees."""
        return tuple(float(np.degrees(a)) for a in angles_from_rot_vs(self.rot_vs))  # type: ignore[return-value]


@dataclass(frozen=True)
class DriveLog:
    """A simulated drive: the IMU on its clock, the speed on its own, and the truth.

    Attributes
    ----------
    t_s : ndarray, shape (n,)
        IMU sample times, s.
    acc_s, gyro_s : ndarray, shape (n, 3)
        Specific force (m/s²) and angular rate (rad/s), sensor frame.
    speed_t_s, speed_mps : ndarray, shape (m,)
        The speed channel: its logged times (s, on the speed clock) and values (m/s).
    heading_deg : ndarray, shape (n,)
        Compass heading of the vehicle (clockwise from north), on the IMU clock.
    speed_true_mps, acc_long_mps2 : ndarray, shape (n,)
        True along-road speed and its time derivative on the IMU clock.
    grade_rad, bank_rad : ndarray, shape (n,)
        Road grade (uphill positive) and cross slope (right side down positive).
    alt_m : ndarray, shape (n,)
        True altitude above the start, m, on the IMU clock.
    f_v, omega_v : ndarray, shape (n, 3)
        True specific force (m/s²) and angular rate (rad/s) in the vehicle frame.
    truth : DriveTruth
    """

    t_s: FloatArray
    acc_s: FloatArray
    gyro_s: FloatArray
    speed_t_s: FloatArray
    speed_mps: FloatArray
    heading_deg: FloatArray
    speed_true_mps: FloatArray
    acc_long_mps2: FloatArray
    grade_rad: FloatArray
    bank_rad: FloatArray
    f_v: FloatArray
    omega_v: FloatArray
    truth: DriveTruth
    alt_m: FloatArray = field(default_factory=lambda: np.zeros(0))
    altitude: Channel | None = None  # the logged altitude (a GNSS's, with noise), when simulated

    def to_samples(self, gyro: bool = True, heading: bool = False) -> Samples:
        """The drive as a reader would deliver it: IMU samples with a ``speed_mps`` channel (and ``alt_m``
        when an altitude was simulated)."""
        channels = {"speed_mps": Channel(self.speed_t_s.copy(), self.speed_mps.copy())}
        if heading:
            channels["heading_deg"] = Channel(self.t_s.copy(), self.heading_deg.copy())
        if self.altitude is not None:
            channels["alt_m"] = Channel(self.altitude.t_s.copy(), self.altitude.value.copy())
        return Samples(
            self.t_s.copy(),
            self.acc_s.copy(),
            self.gyro_s.copy() if gyro else None,
            channels,
            source="<simulated drive>",
        )


def simulate_drive(
    roll_deg: float = 5.0,
    pitch_deg: float = 6.0,
    yaw_deg: float = 7.0,
    *,
    rot_vs: Rotation | None = None,
    duration_s: float = 1200.0,
    rate_hz: float = 100.0,
    noise_mps2: float = 0.05,
    vibration_mps2: float = 0.15,
    gyro_noise_rad_s: float = 0.002,
    bias_mps2: FloatArray | None = None,
    gyro_bias_rad_s: FloatArray | None = None,
    speed_rate_hz: float = 50.0,
    speed_delay_s: float = 0.08,
    speed_noise_mps: float = 0.02,
    speed_resolution_mps: float = 0.01 / 3.6,
    speed_scale: float = 1.0,
    max_grade: float = 0.05,
    cross_slope: float = 0.02,
    cross_slope_variation: float = 0.01,
    g_mps2: float = G_N,
    seed: int | np.random.Generator | None = None,
    scale_matrix: FloatArray | None = None,
    pitch_per_acc_rad: float = PITCH_PER_ACC_RAD,
    roll_per_acc_rad: float = ROLL_PER_ACC_RAD,
    remount_at_s: float | None = None,
    remount_rot_vs: Rotation | None = None,
    altitude_noise_m: float | None = None,
) -> DriveLog:
    """Simulate a mixed drive of ``duration_s`` seconds.

    Parameters
    ----------
    roll_deg, pitch_deg, yaw_deg : float
        Mounting angles (docs/conventions.md §1); ignored when ``rot_vs`` is given.
    duration_s, rate_hz : float
        Length of the drive and IMU sample rate (100–200 Hz is typical).
    noise_mps2, vibration_mps2 : float
        White accelerometer noise, and the amplitude of engine/road vibration (a few tones
        between 12 and 35 Hz, stronger with speed), both 1σ-ish in m/s² per axis.
    gyro_noise_rad_s : float
        White gyro noise, rad/s.
    bias_mps2, gyro_bias_rad_s : array_like, shape (3,), optional
        Constant sensor-frame biases.
    speed_rate_hz, speed_delay_s, speed_noise_mps, speed_resolution_mps, speed_scale : float
        The speed channel: rate, clock lag behind the IMU (logged time = true time + delay),
        white noise, quantisation step and scale (tyre radius) error.
    max_grade, cross_slope, cross_slope_variation : float
        Largest road grade (rise over run), the mean cross slope of the road (crown) and the
        amplitude of its variation along the road.
    g_mps2 : float
        Local gravity.
    seed : int or Generator, optional
    scale_matrix : array_like, shape (3, 3), optional
        Scale and cross-axis errors of the accelerometer: ``acc_s = M · R_vsᵀ f_v + b``.
    pitch_per_acc_rad, roll_per_acc_rad : float
        The body's pitch (nose up) per m/s² of longitudinal acceleration and roll (outward) per m/s² of
        lateral acceleration on its suspension.
    remount_at_s, remount_rot_vs : float and Rotation, optional
        The sensor is mounted by ``remount_rot_vs`` from ``remount_at_s`` on (a remount mid-drive).
    altitude_noise_m : float, optional
        Log an altitude channel (``alt_m``, 1 Hz, as a GNSS would) with this white noise.
    """
    rng = np.random.default_rng(seed)
    rot = rot_vs if rot_vs is not None else rot_vs_from_angles(*np.radians([roll_deg, pitch_deg, yaw_deg]))
    bias = np.zeros(3) if bias_mps2 is None else np.asarray(bias_mps2, dtype=float)
    gyro_bias = np.zeros(3) if gyro_bias_rad_s is None else np.asarray(gyro_bias_rad_s, dtype=float)
    dt = 1.0 / rate_hz
    n = round(duration_s * rate_hz)
    t: FloatArray = np.arange(n, dtype=np.float64) * dt

    acc_long, yaw_rate = _manoeuvres(n, dt, rng)
    v = np.clip(np.cumsum(acc_long) * dt, 0.0, None)
    distance = np.cumsum(v) * dt
    grade, bank = _road(distance, max_grade, cross_slope, cross_slope_variation, rng)
    yaw_rate = np.where(v > 0.5, yaw_rate, 0.0)  # a parked car does not turn
    heading = np.cumsum(yaw_rate) * dt  # counter-clockwise from east, rad

    # Kinematic acceleration in the navigation frame (ENU) from the velocity along the road.
    cg = np.cos(grade)
    vel_n = v[:, None] * np.column_stack([np.cos(heading) * cg, np.sin(heading) * cg, np.sin(grade)])
    acc_n = np.gradient(vel_n, dt, axis=0)
    # Body attitude: road (heading, grade, cross slope) plus suspension pitch and roll.
    a_lat = v * yaw_rate
    body_pitch_up = grade + pitch_per_acc_rad * acc_long
    body_roll_right = bank + roll_per_acc_rad * a_lat
    rot_nv = Rotation.from_euler("ZYX", np.column_stack([heading, -body_pitch_up, body_roll_right]))
    f_v = rot_nv.inv().apply(acc_n + np.array([0.0, 0.0, g_mps2]))
    omega_v = _body_rate(rot_nv, dt)

    vibration = _vibration(t, v, vibration_mps2, rng)
    scale_m = np.eye(3) if scale_matrix is None else np.asarray(scale_matrix, dtype=float)
    sensed, turned = rot.inv().apply(f_v + vibration), rot.inv().apply(omega_v)
    if remount_at_s is not None and remount_rot_vs is not None:
        late = t >= remount_at_s
        sensed[late] = remount_rot_vs.inv().apply((f_v + vibration)[late])
        turned[late] = remount_rot_vs.inv().apply(omega_v[late])
    acc_s = sensed @ scale_m.T + bias + rng.normal(0.0, noise_mps2, size=(n, 3))
    gyro_s = turned + gyro_bias + rng.normal(0.0, gyro_noise_rad_s, size=(n, 3))

    speed_t_true = np.arange(0.0, t[-1], 1.0 / speed_rate_hz)
    speed = np.interp(speed_t_true, t, v) * speed_scale + rng.normal(0.0, speed_noise_mps, speed_t_true.size)
    if speed_resolution_mps > 0:
        speed = np.round(speed / speed_resolution_mps) * speed_resolution_mps
    speed = np.clip(speed, 0.0, None)  # wheel speed and GNSS speed are unsigned
    alt = np.cumsum(vel_n[:, 2]) * dt
    altitude = None
    if altitude_noise_m is not None:  # drawn last: the rest of the drive is the same with or without it
        t_alt = np.arange(0.0, t[-1], 1.0)
        altitude = Channel(t_alt, np.interp(t_alt, t, alt) + rng.normal(0.0, altitude_noise_m, t_alt.size))
    truth = DriveTruth(
        rot,
        g_mps2,
        bias,
        gyro_bias,
        speed_delay_s,
        speed_scale,
        scale_m,
        pitch_per_acc_rad,
        roll_per_acc_rad,
        remount_at_s,
        remount_rot_vs,
    )
    return DriveLog(
        t_s=t,
        acc_s=acc_s,
        gyro_s=gyro_s,
        speed_t_s=speed_t_true + speed_delay_s,
        speed_mps=speed,
        heading_deg=np.mod(90.0 - np.degrees(heading), 360.0),
        speed_true_mps=v,
        acc_long_mps2=acc_long,
        grade_rad=grade,
        bank_rad=bank,
        f_v=f_v,
        omega_v=omega_v,
        truth=truth,
        alt_m=alt,
        altitude=altitude,
    )


def _pulse(n: int, area: float) -> FloatArray:
    """A smooth (jerk-limited) pulse of n samples, sin² shaped, whose samples sum to ``area``."""
    shape = np.sin(np.pi * (np.arange(n) + 0.5) / n) ** 2
    return area * shape / float(shape.sum())


def _manoeuvres(n: int, dt: float, rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
    """Longitudinal acceleration (m/s²) and yaw rate (rad/s) of a random mixed drive, shape (n,)."""
    acc, rate = np.zeros(n), np.zeros(n)
    i, v = int(rng.uniform(3.0, 10.0) / dt), 0.0  # idle at the start

    def put(values: FloatArray, target: FloatArray, at: int) -> int:
        m = max(min(values.size, n - at), 0)
        target[at : at + m] += values[:m]
        return at + values.size

    while i < n:
        if v < 0.5:  # launch from standstill, sometimes into a junction turn
            dv = rng.uniform(8.0, 22.0)
            dur = 2.0 * dv / rng.uniform(1.2, 3.0)  # a sin² pulse of peak a lasts 2·Δv/a
            k = int(dur / dt)
            if rng.random() < 0.4:  # turn 90° while pulling away
                put(_pulse(int(6.0 / dt), np.pi / 2 * rng.choice([-1.0, 1.0]) / dt), rate, i + int(1.0 / dt))
            i = put(_pulse(k, dv / dt), acc, i)
            v += dv
            continue
        # Cruise: gentle speed changes and curves.
        cruise_end = i + int(rng.uniform(15.0, 60.0) / dt)
        while i < min(cruise_end, n):
            k = int(rng.uniform(4.0, 10.0) / dt)
            dv = float(np.clip(rng.normal(0.0, 1.5), 3.0 - v, 28.0 - v))
            i = put(_pulse(k, dv / dt), acc, i)
            v += dv
            if rng.random() < 0.5:  # a curve: lateral acceleration up to ~2 m/s²
                k_curve = int(rng.uniform(5.0, 15.0) / dt)
                peak = rng.uniform(0.3, 2.0) / max(v, 3.0) * rng.choice([-1.0, 1.0])
                put(_pulse(k_curve, peak * k_curve / 2.0), rate, i)
                i += k_curve
        choice = rng.random()
        if choice < 0.35:  # brake to a stop, wait
            dur = 2.0 * v / rng.uniform(1.5, 4.0)
            i = put(_pulse(int(dur / dt), -v / dt), acc, i)
            v = 0.0
            i += int(rng.uniform(5.0, 25.0) / dt)
        elif choice < 0.6:  # slow down for a junction, turn, pull away
            dv = max(v - rng.uniform(4.0, 7.0), 0.0)
            if dv > 0.5:
                i = put(_pulse(int(2.0 * dv / rng.uniform(1.5, 3.0) / dt), -dv / dt), acc, i)
                v -= dv
            i = put(_pulse(int(6.0 / dt), np.pi / 2 * rng.choice([-1.0, 1.0]) / dt), rate, i)
        else:  # a firmer speed change
            dv = float(np.clip(rng.normal(0.0, 6.0), 3.0 - v, 30.0 - v))
            i = put(_pulse(int(max(2.0 * abs(dv) / rng.uniform(1.0, 2.5), 2.0) / dt), dv / dt), acc, i)
            v += dv
    return acc, rate


def _road(
    distance_m: FloatArray, max_grade: float, cross_slope: float, variation: float, rng: np.random.Generator
) -> tuple[FloatArray, FloatArray]:
    """Road grade (uphill positive) and cross slope (right side down positive), rad, along the path."""
    grade = np.zeros_like(distance_m)
    for _ in range(4):
        wavelength = rng.uniform(300.0, 2000.0)
        grade += rng.uniform(0.2, 0.5) * max_grade * np.sin(2 * np.pi * distance_m / wavelength + rng.uniform(0, 6.3))
    bank = cross_slope + variation * np.sin(2 * np.pi * distance_m / rng.uniform(200.0, 800.0))
    return np.arctan(np.clip(grade, -max_grade, max_grade)), np.arctan(bank)


def _body_rate(rot_nv: Rotation, dt: float) -> FloatArray:
    """Angular rate of the body in its own (vehicle) frame, rad/s, shape (n, 3)."""
    step = (rot_nv[:-1].inv() * rot_nv[1:]).as_rotvec() / dt  # between consecutive samples
    mid = np.concatenate([step[:1], 0.5 * (step[1:] + step[:-1]), step[-1:]])
    return np.asarray(mid, dtype=float)


def _vibration(t: FloatArray, v: FloatArray, amplitude: float, rng: np.random.Generator) -> FloatArray:
    """Engine and road vibration: a few tones per axis, growing with speed, m/s², shape (n, 3)."""
    out = np.zeros((t.size, 3))
    level = amplitude * (0.3 + np.clip(v / 20.0, 0.0, 1.5))
    for axis in range(3):
        for _ in range(3):
            out[:, axis] += (
                level * rng.uniform(0.2, 0.6) * np.sin(2 * np.pi * rng.uniform(12.0, 35.0) * t + rng.uniform(0, 6.3))
            )
    return out
