"""mountcal: how an accelerometer or IMU is mounted in a vehicle, with honest uncertainties.

Conventions (docs/conventions.md §1–2; the only code that converts angles is :mod:`mountcal.core.conventions`):

- Sensor frame ``s``: the accelerometer axes as logged, right-handed, SI units (m/s², rad/s, s).
- Vehicle frame ``v``: ISO 8855, x forward, y left, z up.
- ``rot_vs`` maps sensor to vehicle coordinates, ``acc_v = rot_vs.apply(acc_s)``, and
  ``rot_vs = Rz(yaw) · Ry(pitch) · Rx(roll)`` (intrinsic z-y'-x''; the paper's φ, θ, γ).
- An accelerometer at rest reads +g along "up".
- Heading β: from the slope's uphill direction to the vehicle's x axis, counter-clockwise from above.

Names carry frames and units: ``acc_s`` (sensor-frame specific force, m/s²), ``rot_vs``,
``slope_deg``, ``t_s``. Angles in results are degrees; every estimate carries its 1σ.

Pipeline: a log → :func:`calibrate_log` (:mod:`mountcal.calibration.pipeline`: stops and/or driving, what
``mountcal calibrate LOG`` and ``mountcal fleet`` run); a stop table (:mod:`mountcal.stops.table`) →
fit (:mod:`mountcal.calibration.fit`, with :mod:`mountcal.estimate`) → result (:mod:`mountcal.core.result`) →
apply (:mod:`mountcal.apply.rotate`); :mod:`mountcal.simulate` is the shared truth generator.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from mountcal.core import lazy

if TYPE_CHECKING:
    from mountcal.apply.rotate import acc_to_sensor, acc_to_vehicle, frame_to_sensor, frame_to_vehicle
    from mountcal.apply.rotate_log import to_frame
    from mountcal.calibration.fit import calibrate
    from mountcal.calibration.options import Options
    from mountcal.calibration.pipeline import calibrate_log
    from mountcal.calibration.summary import summary
    from mountcal.core.result import Calibration
    from mountcal.estimate.driving import estimate_driving
    from mountcal.io.logs import read_log
    from mountcal.io.reader import LogOptions
    from mountcal.simulate.stops import simulate_preset, simulate_stops
    from mountcal.stops.table import StopTable, read_stop_table, stop_table_from_frame

# Exported names, imported on first use (PEP 562): `import mountcal` and the command line start in
# a fraction of a second; each name comes from the module that defines it.
_HOMES = {
    "__version__": "mountcal.core.version",
    "Calibration": "mountcal.core.result",
    "LogOptions": "mountcal.io.reader",
    "Options": "mountcal.calibration.options",
    "StopTable": "mountcal.stops.table",
    "acc_to_sensor": "mountcal.apply.rotate",
    "acc_to_vehicle": "mountcal.apply.rotate",
    "calibrate": "mountcal.calibration.fit",
    "calibrate_log": "mountcal.calibration.pipeline",
    "estimate_driving": "mountcal.estimate.driving",
    "frame_to_sensor": "mountcal.apply.rotate",
    "frame_to_vehicle": "mountcal.apply.rotate",
    "read_log": "mountcal.io.logs",
    "read_stop_table": "mountcal.stops.table",
    "simulate_preset": "mountcal.simulate.stops",
    "simulate_stops": "mountcal.simulate.stops",
    "stop_table_from_frame": "mountcal.stops.table",
    "summary": "mountcal.calibration.summary",
    "to_frame": "mountcal.apply.rotate_log",
}


lazy.install(__name__, _HOMES)

__all__ = [
    "Calibration",
    "LogOptions",
    "Options",
    "StopTable",
    "__version__",
    "acc_to_sensor",
    "acc_to_vehicle",
    "calibrate",
    "calibrate_log",
    "estimate_driving",
    "frame_to_sensor",
    "frame_to_vehicle",
    "read_log",
    "read_stop_table",
    "simulate_preset",
    "simulate_stops",
    "stop_table_from_frame",
    "summary",
    "to_frame",
]
