"""A simulator of static parking sessions: one truth generator for tests, notebooks and users.

The measurement model is docs/conventions.md §2 with the optional effects of §6::

    a_s,i = M · R_vsᵀ · f_v(α, β_i; g) + b + k · (T_i − T_ref) + d_i + n_i

with M the scale/cross-axis matrix, b a constant bias, k a bias drift per °C, d_i a disturbance
of some stops (not really still) and n_i Gaussian noise of the stop mean.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from mountcal.core.conventions import G_N, FloatArray, angles_from_rot_vs, rot_vs_from_angles, specific_force_v
from mountcal.stops.table import Headings, StopTable

ZHANG2011 = {  # the paper's simulation (its Table 1), docs/conventions.md §3
    "roll_deg": 5.0,
    "pitch_deg": 6.0,
    "yaw_deg": 7.0,
    "slope_deg": 5.0,
    "beta_deg": tuple(range(0, 360, 30)),
    "noise_g": 0.001,
}
PRESETS = {"zhang2011": ZHANG2011}


@dataclass(frozen=True)
class Truth:
    """The true values behind a simulated session (units in the names)."""

    rot_vs: Rotation
    slope_deg: float
    beta_deg: FloatArray
    g_mps2: float
    bias_mps2: FloatArray = field(default_factory=lambda: np.zeros(3))
    scale_matrix: FloatArray = field(default_factory=lambda: np.eye(3))
    temp_coeff_mps2_per_c: FloatArray = field(default_factory=lambda: np.zeros(3))
    temp_ref_c: float = 20.0
    disturbance_mps2: FloatArray | None = None  # shape (n, 3); zero rows for undisturbed stops
    heading_offset_deg: float = 0.0

    @property
    def angles_deg(self) -> tuple[float, float, float]:
        """Roll, pitch, yaw in degrees."""
        return tuple(float(np.degrees(a)) for a in angles_from_rot_vs(self.rot_vs))  # type: ignore[return-value]


def simulate_stops(
    roll_deg: float = 5.0,
    pitch_deg: float = 6.0,
    yaw_deg: float = 7.0,
    *,
    rot_vs: Rotation | None = None,
    slope_deg: float = 5.0,
    beta_deg: FloatArray | tuple[float, ...] = ZHANG2011["beta_deg"],  # type: ignore[assignment]
    noise_g: float = 0.001,
    samples_per_stop: int = 1000,
    g_mps2: float = G_N,
    bias_mps2: FloatArray | None = None,
    scale_matrix: FloatArray | None = None,
    temperature_c: FloatArray | None = None,
    temp_coeff_mps2_per_c: FloatArray | None = None,
    temp_ref_c: float = 20.0,
    disturbance_mps2: FloatArray | None = None,
    lat_deg: float | None = None,
    alt_m: float | None = None,
    headings: Headings = "uphill",
    heading_offset_deg: float = 0.0,
    seed: int | np.random.Generator | None = None,
) -> tuple[StopTable, Truth]:
    """Simulate the stop table of one parking session and return it with the truth.

    Parameters
    ----------
    roll_deg, pitch_deg, yaw_deg : float
        Mounting angles (docs/conventions.md §1); ignored when ``rot_vs`` is given.
    slope_deg : float
        Slope α of the parking plane.
    beta_deg : array_like, shape (n,)
        Headings β of the stops from the uphill direction.
    noise_g : float
        1σ noise of each stop mean per axis, in units of gₙ. Each stop averages
        ``samples_per_stop`` samples of noise ``noise_g·√samples_per_stop``; the table carries the
        sample standard deviation (as a real logger would) and the count.
    g_mps2 : float
        True local gravity.
    bias_mps2 : array_like, shape (3,), optional
        Constant accelerometer bias, sensor frame.
    scale_matrix : array_like, shape (3, 3), optional
        Scale and cross-axis matrix M.
    temperature_c, temp_coeff_mps2_per_c, temp_ref_c
        Temperature of each stop and the bias drift per °C (sensor frame) around ``temp_ref_c``.
    disturbance_mps2 : array_like, shape (n, 3), optional
        Extra specific force on some stops (a stop that was not really still).
    lat_deg, alt_m : float, optional
        Position written into the table (local gravity is ``g_mps2`` regardless).
    headings : {"uphill", "relative", "none"}
        What the table tells about β: the truth, the truth plus ``heading_offset_deg`` (an
        unknown common offset), or nothing.
    seed : int or Generator, optional
    """
    rng = np.random.default_rng(seed)
    rot = rot_vs if rot_vs is not None else rot_vs_from_angles(*np.radians([roll_deg, pitch_deg, yaw_deg]))
    beta = np.asarray(beta_deg, dtype=float)
    n = beta.size
    scale_m = np.eye(3) if scale_matrix is None else np.asarray(scale_matrix, dtype=float)
    bias = np.zeros(3) if bias_mps2 is None else np.asarray(bias_mps2, dtype=float)
    k_temp = np.zeros(3) if temp_coeff_mps2_per_c is None else np.asarray(temp_coeff_mps2_per_c, dtype=float)

    f_v = specific_force_v(np.radians(slope_deg), np.radians(beta), g_mps2)
    acc = rot.inv().apply(f_v) @ scale_m.T + bias
    if temperature_c is not None:
        acc += np.outer(np.asarray(temperature_c, dtype=float) - temp_ref_c, k_temp)
    if disturbance_mps2 is not None:
        acc += np.asarray(disturbance_mps2, dtype=float)

    sigma_mean = noise_g * G_N
    acc += rng.normal(0.0, sigma_mean, size=(n, 3))
    # The logger reports each stop's sample spread: s² ~ σ² χ²(m−1)/(m−1) around the true spread.
    m = samples_per_stop
    sample_sd = sigma_mean * np.sqrt(m) * np.sqrt(rng.chisquare(m - 1, size=(n, 3)) / (m - 1))
    cov = np.zeros((n, 3, 3))
    cov[:, [0, 1, 2], [0, 1, 2]] = sample_sd**2 / m

    table = StopTable(
        acc_s=acc,
        beta_rad=None if headings == "none" else np.radians(beta + heading_offset_deg),
        headings=headings,
        cov_s=cov if noise_g > 0 else None,  # noise-free stops carry no spread to weigh by
        temperature_c=None if temperature_c is None else np.asarray(temperature_c, dtype=float),
        t_s=np.arange(n, dtype=float) * 120.0,
        lat_deg=None if lat_deg is None else np.full(n, lat_deg),
        alt_m=None if alt_m is None else np.full(n, 0.0 if alt_m is None else alt_m),
        source="<simulated>",
    )
    truth = Truth(
        rot_vs=rot,
        slope_deg=slope_deg,
        beta_deg=beta,
        g_mps2=g_mps2,
        bias_mps2=bias,
        scale_matrix=scale_m,
        temp_coeff_mps2_per_c=k_temp,
        temp_ref_c=temp_ref_c,
        disturbance_mps2=None if disturbance_mps2 is None else np.asarray(disturbance_mps2, dtype=float),
        heading_offset_deg=heading_offset_deg,
    )
    return table, truth


def simulate_preset(
    name: str, seed: int | np.random.Generator | None = None, **overrides: object
) -> tuple[StopTable, Truth]:
    """Simulate a named scenario (``"zhang2011"``), with keyword overrides."""
    try:
        preset = dict(PRESETS[name])
    except KeyError as err:
        raise ValueError(f"unknown preset {name!r}; known: {', '.join(PRESETS)}") from err
    preset.update(overrides)
    return simulate_stops(seed=seed, **preset)  # type: ignore[arg-type]


def random_bias(magnitude_mps2: float, rng: np.random.Generator) -> FloatArray:
    """A bias vector of the given magnitude in a uniformly random direction."""
    v = rng.normal(size=3)
    return magnitude_mps2 * v / np.linalg.norm(v)


@dataclass(frozen=True)
class ParkingLog:
    """A simulated parking session as a time series: what a logger records, plus its protocol."""

    t_s: FloatArray  # shape (n,)
    acc_s: FloatArray  # shape (n, 3), m/s², sensor frame
    gyro_s: FloatArray  # shape (n, 3), rad/s, sensor frame
    speed_mps: FloatArray  # shape (n,)
    heading_deg: FloatArray  # shape (n,), compass (clockwise from north)
    temperature_c: FloatArray  # shape (n,)
    protocol: list[tuple[float, float, float]]  # (t_start_s, t_end_s, beta_deg) of each stop
    uphill_azimuth_deg: float
    truth: Truth


def simulate_parking_log(
    roll_deg: float = 5.0,
    pitch_deg: float = 6.0,
    yaw_deg: float = 7.0,
    *,
    slope_deg: float = 5.0,
    beta_deg: tuple[float, ...] = tuple(range(0, 360, 30)),
    stop_s: float = 40.0,
    drive_s: float = 20.0,
    rate_hz: float = 100.0,
    noise_mps2: float = 0.05,
    gyro_noise_rad_s: float = 0.002,
    bias_mps2: FloatArray | None = None,
    uphill_azimuth_deg: float = 30.0,
    g_mps2: float = G_N,
    seed: int | np.random.Generator | None = None,
    gyro_bias_rad_s: FloatArray | None = None,
    acc_lsb_mps2: float = 0.0,
    gyro_lsb_rad_s: float = 0.0,
    paired_stamps: bool = False,
    wander_deg: tuple[float, ...] | None = None,
) -> ParkingLog:
    """A parking session on one slope: stops at the headings β, driven between with turns.

    Between stops the vehicle launches, turns to the next heading and brakes (peak speed
    ≈ 6 m/s); the specific force then adds the longitudinal acceleration and the centripetal
    one (``v · ω``). Engine-idle vibration is white noise of ``noise_mps2`` on every sample.

    What field loggers add: a constant gyro bias; quantisation of the accelerometer and gyro to
    steps of ``acc_lsb_mps2`` and ``gyro_lsb_rad_s`` (0: none); samples stamped in pairs (two
    readings per stamp, ``paired_stamps``); and a vehicle that slowly turns by ``wander_deg[i]``
    during stop i (the protocol's β is the heading at the stop's start).
    """
    rng = np.random.default_rng(seed)
    rot = rot_vs_from_angles(*np.radians([roll_deg, pitch_deg, yaw_deg]))
    bias = np.zeros(3) if bias_mps2 is None else np.asarray(bias_mps2, dtype=float)
    dt = 1.0 / rate_hz
    betas = np.asarray(beta_deg, dtype=float)
    pieces_t, pieces_beta, pieces_v, pieces_acc_long = [], [], [], []
    protocol = []
    t0 = 0.0
    wander = np.zeros(betas.size) if wander_deg is None else np.asarray(wander_deg, dtype=float)
    for i, b in enumerate(betas):
        n_stop = int(stop_s * rate_hz)
        tt = t0 + np.arange(n_stop) * dt
        pieces_t.append(tt)
        pieces_beta.append(b + wander[i] * np.arange(n_stop) / n_stop)
        pieces_v.append(np.zeros(n_stop))
        pieces_acc_long.append(np.zeros(n_stop))
        protocol.append((float(tt[0]), float(tt[-1]), float(b)))
        t0 = tt[-1] + dt
        if i + 1 < betas.size:
            n_drive = int(drive_s * rate_hz)
            tau = np.arange(n_drive) / n_drive
            b = b + wander[i]  # the drive starts where the stop's heading ended
            turn = ((betas[i + 1] - b + 180.0) % 360.0) - 180.0 + 360.0  # a full loop plus the change
            v_peak = 6.0
            v = v_peak * np.sin(np.pi * tau) ** 2
            pieces_t.append(t0 + np.arange(n_drive) * dt)
            pieces_beta.append(b + turn * (tau - np.sin(2 * np.pi * tau) / (2 * np.pi)))
            pieces_v.append(v)
            pieces_acc_long.append(v_peak * np.pi / drive_s * np.sin(2 * np.pi * tau))
            t0 = pieces_t[-1][-1] + dt
    t = np.concatenate(pieces_t)
    beta = np.concatenate(pieces_beta)
    v = np.concatenate(pieces_v)
    a_long = np.concatenate(pieces_acc_long)
    omega_z = np.gradient(np.unwrap(np.radians(beta)), t)  # β counter-clockwise, as the yaw rate
    f_v = specific_force_v(np.radians(slope_deg), np.radians(beta), g_mps2)
    f_v[:, 0] += a_long
    f_v[:, 1] += v * omega_z
    acc = rot.inv().apply(f_v) + bias + rng.normal(0.0, noise_mps2, size=f_v.shape)
    gyro_v = np.column_stack([np.zeros_like(omega_z), np.zeros_like(omega_z), omega_z])
    gyro = rot.inv().apply(gyro_v) + rng.normal(0.0, gyro_noise_rad_s, size=f_v.shape)
    if gyro_bias_rad_s is not None:
        gyro = gyro + np.asarray(gyro_bias_rad_s, dtype=float)
    if acc_lsb_mps2 > 0:
        acc = np.round(acc / acc_lsb_mps2) * acc_lsb_mps2
    if gyro_lsb_rad_s > 0:
        gyro = np.round(gyro / gyro_lsb_rad_s) * gyro_lsb_rad_s
    temperature = 25.0 + 5.0 * t / t[-1] + rng.normal(0.0, 0.05, size=t.size)
    truth = Truth(rot_vs=rot, slope_deg=slope_deg, beta_deg=betas, g_mps2=g_mps2, bias_mps2=bias)
    return ParkingLog(
        t_s=t[np.arange(t.size) // 2 * 2] if paired_stamps else t,
        acc_s=acc,
        gyro_s=gyro,
        speed_mps=v,
        heading_deg=(uphill_azimuth_deg - beta) % 360.0,
        temperature_c=temperature,
        protocol=protocol,
        uphill_azimuth_deg=uphill_azimuth_deg,
        truth=truth,
    )
