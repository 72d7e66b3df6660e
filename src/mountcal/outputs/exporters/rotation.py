"""The rotation in every common parameterisation, with 1σ, as JSON or YAML.

All describe ``rot_vs`` (sensor → vehicle, ISO 8855 vehicle frame: ``a_v = R · a_s``): quaternion
w-first (Hamilton, ``a_v = q ⊗ a_s ⊗ q*``) and x-first (scipy, ROS), the matrix, axis-angle
(right-hand rule) and the intrinsic z-y'-x'' Euler angles (``R = Rz(yaw)·Ry(pitch)·Rx(roll)``).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from mountcal.core.errors import FitFailed
from mountcal.outputs.exporters.common import Exporter, ExportOptions, Mounting, propagate_sigma

if TYPE_CHECKING:
    from scipy.spatial.transform import Rotation

    from mountcal.core.conventions import FloatArray
    from mountcal.core.result import Calibration

AXIS_UNDEFINED_RAD = 1e-6  # below this angle the rotation axis (and its σ) is not meaningful


def _quat_xyzw(reference: FloatArray) -> Callable[[Rotation], FloatArray]:
    def fn(r: Rotation) -> FloatArray:
        q: FloatArray = r.as_quat()  # scipy ships no types; its arrays are float64
        return -q if float(q @ reference) < 0 else q  # the sign of the reference: q and −q are one rotation

    return fn


def _rotvec(r: Rotation) -> FloatArray:
    v: FloatArray = r.as_rotvec()
    return v


def _axis(r: Rotation) -> FloatArray:
    v: FloatArray = r.as_rotvec()
    import numpy as np

    return v / float(np.linalg.norm(v))


def _euler(r: Rotation) -> FloatArray:
    import numpy as np

    from mountcal.core.conventions import angles_from_rot_vs

    roll, pitch, yaw = angles_from_rot_vs(r)
    return np.array([yaw, pitch, roll])


def _matrix(r: Rotation) -> FloatArray:
    m: FloatArray = r.as_matrix()
    return m.ravel()


def _values(values: FloatArray) -> list[float]:
    return [float(v) for v in values]


def parameterisations(mount: Mounting) -> dict[str, Any]:
    """The document: every parameterisation with its 1σ (None where the σ is not known)."""
    import numpy as np

    from mountcal.core.conventions import CONVENTIONS

    rot = mount.rot_vs
    q = rot.as_quat()
    q = -q if q[3] < 0 else q
    q_sigma = propagate_sigma(_quat_xyzw(q), mount)
    angle = float(rot.magnitude())
    euler = _euler(rot)
    euler_sigma = propagate_sigma(_euler, mount, np.array([2 * np.pi] * 3))
    if angle > AXIS_UNDEFINED_RAD:
        axis: list[float] | None = _values(_axis(rot))
        axis_sigma: list[float | None] | None = propagate_sigma(_axis, mount)
    else:
        axis, axis_sigma = None, None
    m_sigma = propagate_sigma(_matrix, mount)
    return {
        "format": "mountcal.rotation",
        "format_version": 1,
        "rotation": "rot_vs: sensor to vehicle coordinates, a_v = R a_s",
        "vehicle_frame": CONVENTIONS["vehicle_frame"],
        "sensor_frame": CONVENTIONS["sensor_frame"],
        "uncertainty": (
            "1 sigma, first order (numeric Jacobian) from the result's sigma of small rotations about the "
            "vehicle x, y, z axes, taken as uncorrelated (the result stores no correlations)"
        ),
        "yaw_assumed_zero": mount.yaw_assumed_zero,
        "notes": list(mount.header[1:]),
        "quaternion_wxyz": {"value": _values(np.roll(q, 1)), "sigma": [q_sigma[3], *q_sigma[:3]]},
        "quaternion_xyzw": {"value": _values(q), "sigma": q_sigma},
        "matrix": {
            "value": rot.as_matrix().tolist(),
            "sigma": [m_sigma[0:3], m_sigma[3:6], m_sigma[6:9]],
        },
        "axis_angle": {
            "axis": axis,
            "axis_sigma": axis_sigma,
            "angle_rad": angle,
            "angle_sigma_rad": _angle_sigma(mount),
            "rotation_vector_rad": _values(rot.as_rotvec()),
            "rotation_vector_sigma_rad": propagate_sigma(_rotvec, mount),
        },
        "euler_zyx": {
            "order": "intrinsic z-y'-x'': R = Rz(yaw) Ry(pitch) Rx(roll)",
            "yaw_pitch_roll_rad": _values(euler),
            "sigma_rad": euler_sigma,
            "yaw_pitch_roll_deg": _values(np.degrees(euler)),
            "sigma_deg": [None if s is None else float(np.degrees(s)) for s in euler_sigma],
        },
    }


def _angle_sigma(mount: Mounting) -> float | None:
    import numpy as np

    return propagate_sigma(lambda r: np.array([r.magnitude()]), mount)[0]


def rotation_json(mount: Mounting) -> str:
    doc = parameterisations(mount)
    _dumps(doc, "the rotation")  # a non-finite value is refused by name, never written
    return json.dumps(doc, indent=2, allow_nan=False) + "\n"


def rotation_yaml(mount: Mounting) -> str:
    return "\n".join(_yaml(parameterisations(mount), 0)) + "\n"


def _yaml(node: Any, indent: int) -> list[str]:
    """Block YAML of plain JSON types; scalars are written as JSON, which YAML reads the same."""
    pad = " " * indent
    lines: list[str] = []
    for key, value in node.items():
        if isinstance(value, dict):
            lines.append(f"{pad}{key}:")
            lines += _yaml(value, indent + 2)
        elif isinstance(value, list) and value and isinstance(value[0], list):
            lines.append(f"{pad}{key}:")
            lines += [f"{pad}  - {_dumps(row, key)}" for row in value]
        else:
            lines.append(f"{pad}{key}: {_dumps(value, key)}")
    return lines


def _dumps(value: Any, key: str) -> str:
    """``value`` as JSON, refusing ``inf`` and ``NaN`` (which JSON has no literal for, and YAML would
    read as ``Infinity`` text): the result's values are in range, so only a bug could bring one."""
    try:
        return json.dumps(value, allow_nan=False)
    except ValueError as err:
        raise FitFailed(f"{key}: a value that is not a finite number ({value!r}); nothing was written") from err


def _json(cal: Calibration, options: ExportOptions) -> str:
    return rotation_json(options.mounting(cal))


def _yaml_document(cal: Calibration, options: ExportOptions) -> str:
    return rotation_yaml(options.mounting(cal))


EXPORTERS = (
    Exporter("json", (".json", ".txt"), "mountcal's rotation in every common parameterisation with 1σ, as JSON", _json),
    Exporter(
        "yaml",
        (".yaml", ".yml", ".txt"),
        "mountcal's rotation in every common parameterisation with 1σ, as YAML",
        _yaml_document,
    ),
)
