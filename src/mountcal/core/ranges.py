"""The physical range of every number mountcal reads: one table, for options and file columns alike.

A number from outside — a command-line option, a column of a stop table, sample table or
protocol sheet, a time stamp or id of a CAN log, a value of a calibration, triad or imucal
file — is finite and inside the range of its quantity (:data:`QUANTITIES`), or it is refused with
its name. Inside these ranges nothing downstream overflows: the widest is far from where a
square, a product or a sum of a million of them leaves the doubles, so no written file can hold
an ``inf`` or a ``NaN`` that came from an input.

- Options: every numeric option of every command is declared with :class:`Number` (one value)
  or :func:`numbers` (a tuple of values, e.g. ``--fix LAT LON ALT``), naming its quantity; a test
  walks every parser and fails on a ``float`` or ``int`` option, so a new option cannot skip it.
- Files: :data:`COLUMNS` names the quantity of each column a reader checks; :func:`check_values`
  does the check on whole arrays.

The table is stated in docs/reliability.md; a test regenerates it from here (:func:`markdown`), so
the two cannot drift. Imports nothing numerical: the parser is built with it.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from mountcal.core.errors import InputError


@dataclass(frozen=True)
class Quantity:
    """A physical range: ``lo`` to ``hi`` in ``unit``, each end closed unless stated open."""

    lo: float
    hi: float
    unit: str
    what: str
    open_lo: bool = False
    open_hi: bool = False
    whole: bool = False  # a count: whole numbers only
    slip: str = ""  # past the range: the unit slip that puts a value there, said with the refusal

    def holds(self, value: float) -> bool:
        if not math.isfinite(value):
            return False
        above = self.lo < value if self.open_lo else self.lo <= value
        below = value < self.hi if self.open_hi else value <= self.hi
        return above and below and (not self.whole or value == int(value))

    def interval(self) -> str:
        """``(0, 180]`` in the notation of the docs' table."""
        return f"{'(' if self.open_lo else '['}{_num(self.lo)}, {_num(self.hi)}{')' if self.open_hi else ']'}"

    def expected(self) -> str:
        kind = "a whole number" if self.whole else "a finite number"
        return f"{kind} in {self.interval()}{' ' + self.unit if self.unit else ''}"


def _num(x: float) -> str:
    """``536870911``, ``1e10``, ``4.1e9``, ``1e-09``: whole numbers exactly unless %g says them exactly."""
    short = f"{x:g}".replace("e+0", "e").replace("e+", "e")
    if x == int(x) and (abs(x) < 1e7 or float(short) != x):
        return f"{int(x)}"
    return short


QUANTITIES: dict[str, Quantity] = {
    # times and durations
    "time_s": Quantity(-1e10, 1e10, "s", "a time stamp or time column (Unix or relative; 1e10 s is the year 2286)"),
    "unix_time_s": Quantity(
        86_400, 2e9, "s", "a Unix time to write into a log (1970-01-02 to 2033: ROS 2 stamps hold 32-bit seconds)"
    ),
    "duration_s": Quantity(0, 86_400, "s", "a duration or window of stop detection, a dwell", open_lo=True),
    "trim_s": Quantity(0, 3_600, "s", "a settling time cut from a stop"),
    "drive_s": Quantity(0, 86_400, "s", "the time between stops of a plan"),
    "file_duration_s": Quantity(0, 1e7, "s", "a stop's duration in a stop table"),
    "timeout_s": Quantity(0, 86_400, "s", "how long a silent bus is waited for", open_lo=True),
    "simulated_s": Quantity(1, 3_600, "s", "a simulated stop or drive"),
    "rate_hz": Quantity(0.1, 100_000, "Hz", "a sample rate"),
    "simulated_rate_hz": Quantity(1, 10_000, "Hz", "a simulated sample rate"),
    # accelerations
    "acc_mps2": Quantity(-1_000, 1_000, "m/s²", "an acceleration (±100 g)"),
    "gravity_mps2": Quantity(9.70, 9.90, "m/s²", "local gravity (anywhere a vehicle drives: 9.78–9.84, with margin)"),
    "acc_limit_mps2": Quantity(0, 100, "m/s²", "a stillness threshold on the accelerometer", open_lo=True),
    "sample_std_mps2": Quantity(1e-9, 1_000, "m/s²", "the spread of a stop's samples (0.1 µg to 100 g)"),
    "mean_std_mps2": Quantity(1e-12, 1_000, "m/s²", "the 1σ of a stop mean"),
    "sample_count": Quantity(1, 1e12, "", "samples averaged in a stop"),
    "correlation": Quantity(-1, 1, "", "a correlation between axes", open_lo=True, open_hi=True),
    "lsb_mps2": Quantity(0, 10, "m/s²", "a simulated quantisation step"),
    "noise_g": Quantity(
        0, 0.1, "g", "the simulated noise of a stop mean", slip="The value is in g: 1 mg is 0.001 (plan --noise: mg)."
    ),
    "noise_mg": Quantity(1e-6, 10_000, "mg", "an accelerometer's noise per sample"),
    "bias_mg": Quantity(-2_000, 2_000, "mg", "a simulated accelerometer bias"),
    # angular rates
    "gyro_rad_s": Quantity(-100, 100, "rad/s", "an angular rate"),
    "gyro_limit_rad_s": Quantity(
        0, 35, "rad/s", "a stillness threshold on the gyro (35 rad/s = 2000 °/s)", open_lo=True
    ),
    "gyro_bias_dps": Quantity(-1_000, 1_000, "°/s", "a simulated gyro bias"),
    "gyro_lsb_dps": Quantity(0, 100, "°/s", "a simulated gyro quantisation step"),
    # angles
    "angle_deg": Quantity(-360, 360, "°", "a mounting angle, azimuth or heading offset"),
    "heading_deg": Quantity(-3_600, 3_600, "°", "a heading column (may be unwrapped over ten turns)"),
    "slope_deg": Quantity(0, 90, "°", "a slope", open_hi=True),
    "planned_slope_deg": Quantity(0, 45, "°", "the slope of a plan", open_hi=True),
    "sigma_deg": Quantity(0, 180, "°", "a 1σ or target of an angle", open_lo=True),
    "tolerance_deg": Quantity(0, 360, "°", "a heading wander tolerance", open_lo=True),
    "floor_deg": Quantity(0, 180, "°", "a mounting scatter added to each σ"),
    "result_sigma_deg": Quantity(0, 3_600, "°", "the 1σ of an angle in a result (beyond ten turns: undetermined)"),
    # positions and motion
    "lat_deg": Quantity(-90, 90, "°", "a latitude"),
    "lon_deg": Quantity(-360, 360, "°", "a longitude"),
    "alt_m": Quantity(-1_000, 100_000, "m", "an altitude"),
    "offset_m": Quantity(
        -50, 50, "m", "a lever arm on a vehicle", slip="The value is in metres: 350 mm is 0.35 m, 35 cm is 0.35 m."
    ),
    "speed_mps": Quantity(-150, 150, "m/s", "a vehicle speed (negative: reversing)"),
    "speed_limit_mps": Quantity(0, 150, "m/s", "a stillness threshold on the speed"),
    "temperature_c": Quantity(-100, 200, "°C", "a sensor temperature"),
    # calibration files
    "result_sigma_mps2": Quantity(0, 1_000, "m/s²", "the 1σ of a bias in a result"),
    "result_value": Quantity(-1e150, 1e150, "", "any other number of a result (its square stays finite)"),
    "triad_bias_mps2": Quantity(-1_000, 1_000, "m/s²", "a triad's or imucal's bias"),
    "triad_covariance": Quantity(-1e6, 1e6, "", "an entry of a triad's covariance"),
    "imucal_matrix": Quantity(-1_000, 1_000, "", "an entry of imucal's K_a or R_a"),
    "spec_limit": Quantity(0, 1_000, "", "a sensor spec limit (fraction, m/s², mg, °)", open_hi=True),
    # counts and ids
    "seed": Quantity(0, 2**32 - 1, "", "a random seed", whole=True),
    "simulated_samples": Quantity(
        1, 1_000_000, "", "samples of a simulated session (14 times the default)", whole=True
    ),
    "planned_stops": Quantity(3, 100, "", "the most stops a plan may have", whole=True),
    "chunk_samples": Quantity(1, 100_000_000, "", "samples per chunk", whole=True),
    "workers": Quantity(1, 1_024, "", "worker processes", whole=True),
    "can_channel": Quantity(0, 255, "", "a CAN channel number", whole=True),
    "can_id": Quantity(0, 2**29 - 1, "", "a CAN arbitration id (29 bits)", whole=True),
}

# What each file reader checks, by column: the table of docs/reliability.md lists them by quantity.
COLUMNS: dict[str, dict[str, str]] = {
    "stop table": {
        "ax, ay, az": "acc_mps2",
        "sx, sy, sz": "sample_std_mps2",
        "n": "sample_count",
        "sx_mean, sy_mean, sz_mean": "mean_std_mps2",
        "rxy, rxz, ryz": "correlation",
        "beta_deg, heading_deg": "heading_deg",
        "t_s": "time_s",
        "duration_s": "file_duration_s",
        "temperature_c": "temperature_c",
        "lat_deg": "lat_deg",
        "lon_deg": "lon_deg",
        "alt_m": "alt_m",
    },
    "protocol sheet": {"t_start_s, t_end_s": "time_s", "beta_deg": "heading_deg"},
    "sample table": {
        "t_s": "time_s",
        "ax, ay, az": "acc_mps2",
        "gx, gy, gz": "gyro_rad_s",
        "speed_mps": "speed_mps",
        "heading_deg": "heading_deg",
        "temperature_c": "temperature_c",
        "lat_deg": "lat_deg",
        "lon_deg": "lon_deg",
        "alt_m": "alt_m",
    },
    "CAN log (text formats)": {"time stamp": "time_s", "arbitration id": "can_id"},
    "calibration result": {
        "uncertainty of roll, pitch, yaw, slope": "result_sigma_deg",
        "uncertainty.bias_mps2": "result_sigma_mps2",
        "every other number": "result_value",
    },
    "triad": {"bias": "triad_bias_mps2", "covariance": "triad_covariance"},
    "imucal JSON": {"K_a, R_a": "imucal_matrix", "b_a": "triad_bias_mps2"},
    "sensor spec": {"every limit": "spec_limit"},
    "simulate --log": {"rate × session duration": "simulated_samples"},
}


def check(quantity: str, value: float, name: str, where: str = "", todo: str = "") -> float:
    """``value`` when it is inside ``quantity``'s range, else an :class:`InputError` naming ``name``
    (and the file ``where`` it came from)."""
    q = QUANTITIES[quantity]
    if isinstance(value, bool) or not isinstance(value, int | float) or not q.holds(float(value)):
        raise InputError(
            f"{where}: {name}" if where else name,
            f"{q.what}: {q.expected()}",
            repr(value),
            todo or "Give a value in that range (the units are in the help and in docs/reliability.md).",
        )
    return value


def check_values(
    quantity: str, values: Any, where: str, name: str, *, scale: float = 1.0, first: int = 0, todo: str = ""
) -> None:
    """Refuse an array (rows × columns) holding a value outside ``quantity``'s range, naming the
    first rows. ``values`` are in the quantity's unit; ``scale`` converts them back for the message
    (the file's own unit). ``name`` names the column(s); ``first`` is the number of rows before these;
    ``todo`` replaces the message's advice."""
    import numpy as np

    q = QUANTITIES[quantity]
    v = np.asarray(values, dtype=float)
    good = in_range(quantity, v)
    if good.all():
        return
    bad = np.argwhere(~good) if v.ndim > 1 else np.flatnonzero(~good)[:, None]
    shown = ", ".join(f"row {first + int(b[0]) + 1}: {float(v[tuple(b)]) / scale:g}" for b in bad[:5])
    more = f" and {len(bad) - 5} more" if len(bad) > 5 else ""
    raise InputError(
        where,
        f"{name}: {q.what}, {q.expected()}",
        f"{shown}{more}",
        todo or "Fix or remove those rows; mountcal refuses numbers no sensor or vehicle produces.",
    )


def in_range(quantity: str, values: Any) -> Any:
    """Which of ``values`` (an array) are finite and inside ``quantity``'s range (a boolean array)."""
    import numpy as np

    q = QUANTITIES[quantity]
    v = np.asarray(values, dtype=float)
    with np.errstate(invalid="ignore"):
        good = np.isfinite(v) & (v > q.lo if q.open_lo else v >= q.lo) & (v < q.hi if q.open_hi else v <= q.hi)
        return good & (v == np.round(v)) if q.whole else good


class Number:
    """An argparse ``type``: a number of ``quantity``, finite and in its range (the flag is named by
    argparse in the message)."""

    def __init__(self, quantity: str) -> None:
        self.quantity = quantity
        self.__name__ = quantity  # argparse names the type by it in "invalid … value"

    def __call__(self, text: str) -> float | int:
        q = QUANTITIES[self.quantity]
        try:
            value: float | int = int(text) if q.whole else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {q.expected()}, found {text!r}") from None
        if not q.holds(float(value)):
            slip = f". {q.slip}" if q.slip and math.isfinite(value) else ""
            raise argparse.ArgumentTypeError(f"expected {q.what}: {q.expected()}, found {text}{slip}")
        return value


def numbers(*quantities: str) -> type[argparse.Action]:
    """An argparse ``action`` for an option of several values (``nargs=len(quantities)``), each
    checked against its own quantity: ``--fix LAT LON ALT`` is ``numbers("lat_deg", "lon_deg", "alt_m")``."""

    class Numbers(argparse.Action):
        QUANTITIES = quantities

        def __call__(
            self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any, _: Any = None
        ) -> None:
            out = []
            for quantity, text in zip(quantities, values, strict=True):
                try:
                    out.append(Number(quantity)(text))
                except argparse.ArgumentTypeError as err:
                    raise argparse.ArgumentError(self, str(err)) from None
            setattr(namespace, self.dest, out)

    return Numbers


def add_quantity(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup, *flags: str, quantity: str, **argument: Any
) -> argparse.Action:
    """``parser.add_argument(*flags, **argument)`` for a number that may carry its unit (``--gravity 1g``,
    ``--noise 5mg``): the text is kept for :func:`mountcal.io.input_conventions.parse_quantity`, which converts
    it and refuses a value outside ``quantity``'s range; declared here so that the option walk and the
    table of the docs know it."""
    action = parser.add_argument(*flags, **argument)
    setattr(action, _QUANTITIES, (quantity,))
    return action


_QUANTITIES = "mountcal_quantities"


def option_quantities(action: argparse.Action) -> tuple[str, ...] | None:
    """The quantities an option is declared with (None: not a checked number)."""
    if isinstance(action.type, Number):
        return (action.type.quantity,)
    declared: tuple[str, ...] | None = getattr(action, _QUANTITIES, None)
    return declared if declared is not None else getattr(type(action), "QUANTITIES", None)


def markdown(parser: argparse.ArgumentParser) -> str:
    """The table of docs/reliability.md: each quantity, its range, and the options and columns
    read as it (the options found by walking ``parser``'s commands)."""
    uses: dict[str, list[str]] = {name: [] for name in QUANTITIES}
    for command, sub in _commands(parser):
        for action in sub._actions:
            for quantity in dict.fromkeys(option_quantities(action) or ()):
                uses[quantity].append(
                    f"`{command} {action.option_strings[-1] if action.option_strings else action.dest}`"
                )
    for reader, columns in COLUMNS.items():
        for column, quantity in columns.items():
            uses[quantity].append(f"{reader}: {column}")
    lines = ["| quantity | range | unit | read from |", "|---|---|---|---|"]
    for name, q in QUANTITIES.items():
        where = "; ".join(_merge(uses[name])) or "(library only)"
        lines.append(f"| {q.what} | {q.interval()}{' whole' if q.whole else ''} | {q.unit or '—'} | {where} |")
    return "\n".join(lines) + "\n"


def _merge(uses: Sequence[str]) -> list[str]:
    """The same option of several commands once: ``--trim-s`` (calibrate, stops)."""
    by_flag: dict[str, list[str]] = {}
    rest = []
    for use in uses:
        if use.startswith("`"):
            command, flag = use.strip("`").split(" ", 1)
            by_flag.setdefault(flag, []).append(command)
        else:
            rest.append(use)
    return [f"`{flag}` ({', '.join(cmds)})" for flag, cmds in by_flag.items()] + rest


def _commands(parser: argparse.ArgumentParser) -> list[tuple[str, argparse.ArgumentParser]]:
    out = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            out += [(name, sub) for name, sub in action.choices.items()]
    return out


__all__ = [
    "COLUMNS",
    "QUANTITIES",
    "Number",
    "Quantity",
    "add_quantity",
    "check",
    "check_values",
    "markdown",
    "numbers",
]
