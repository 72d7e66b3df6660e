"""Reading a calibration result file as untrusted input: bounded parse, then every value checked.

A result is applied to every log of a vehicle, so a tampered or corrupted one must be refused
before use, never half-applied: a NaN bias would turn every row into NaN, a quaternion that
contradicts its angles would rotate by something nobody reported.

- :func:`read_json` parses within the run's budget (:mod:`mountcal.core.budget`: size, a nesting-depth
  limit found by a linear scan — a deep array would exhaust the parser's recursion), and no
  ``NaN``/``Infinity`` literals.
- :func:`check_document` checks the untyped fields a :class:`~mountcal.core.result.Calibration` uses
  (the typed parts are checked by :func:`mountcal.core.typed_json.from_plain`): types, finiteness,
  ranges, shapes, and that the rotation agrees with its angles within
  :data:`ROTATION_TOLERANCE_DEG`. The same rules are published as a JSON Schema
  (``mountcal/schema/calibration.schema.json``) for other tools; the consistency of the rotation
  with its angles is beyond JSON Schema and checked here only.

Written by hand rather than with the ``jsonschema`` package: no new core dependency, and the
checks JSON Schema cannot state (finite floats, the rotation) are needed anyway.
"""

from __future__ import annotations

import json
import math
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from mountcal.core import paths
from mountcal.core.conventions import G_N, rot_vs_from_angles
from mountcal.core.errors import InputError
from mountcal.core.paths import PathLike
from mountcal.core.ranges import QUANTITIES

ROTATION_TOLERANCE_DEG = 1e-6  # the stored angles and quaternion are both written at full precision
MAX_BIAS_MPS2 = G_N  # readings within 0.7–1.3 g cannot produce a bias beyond 1 g
GRAVITY_RANGE_MPS2 = (0.7 * G_N, 1.3 * G_N)  # the stop tables' gravity band
SCHEMA = "schema/calibration.schema.json"


def schema() -> dict[str, Any]:
    """The published JSON Schema of a result file."""
    text = resources.files("mountcal").joinpath(SCHEMA).read_text(encoding="utf-8")
    return dict(json.loads(text))  # the packaged schema is a JSON object


def write_schema(typed: dict[str, Any]) -> None:
    """Replace the typed parts of the published schema (``$defs``, their properties) with ``typed``."""
    path = Path(str(resources.files("mountcal").joinpath(SCHEMA)))
    doc = schema()
    doc["$defs"] = typed["$defs"]
    doc["properties"].update(typed["properties"])
    path.write_text(json.dumps(doc, indent=2, ensure_ascii=False) + "\n", encoding="utf-8")


def read_json(path: PathLike, what: str = "a calibration JSON file") -> Any:
    """Parse a JSON file of bounded size and nesting depth, refusing NaN and Infinity literals
    (:func:`mountcal.core.budget.document`: the depth is found by a linear scan before parsing)."""
    return paths.read_document(path, what)


def check_document(doc: dict[str, Any], where: str) -> None:
    """Refuse a result document whose values a Calibration could not safely use (see module doc)."""
    problems: list[str] = []

    def number(path: str, lo: float = -math.inf, hi: float = math.inf, *, null: bool = False) -> float | None:
        value = _get(doc, path)
        if value is None and null:
            return None
        if isinstance(value, bool) or not isinstance(value, int | float):
            problems.append(f"{path} = {_show(value)} (expected a number{' or null' if null else ''})")
            return None
        if not (math.isfinite(value) and lo <= value <= hi):
            problems.append(f"{path} = {_show(value)} (expected a finite number in [{lo:g}, {hi:g}])")
            return None
        return float(value)

    def vector(path: str, n: int, lo: float, hi: float, *, null: bool = False, items_null: bool = False) -> None:
        value = _get(doc, path)
        if value is None and null:
            return
        if not isinstance(value, list) or len(value) != n:
            problems.append(f"{path} = {_show(value)} (expected {n} numbers)")
            return
        for i in range(n):
            number(f"{path}.{i}", lo, hi, null=items_null)

    for key, kind in (("method", str), ("model", list)):
        if not isinstance(doc.get(key), kind):
            problems.append(f"{key} = {_show(doc.get(key))} (expected a {kind.__name__})")
    if isinstance(doc.get("model"), list) and not all(isinstance(t, str) for t in doc["model"]):
        problems.append("model (expected a list of names)")
    roll = number("mounting.roll_deg", -180, 180)
    pitch = number("mounting.pitch_deg", -90, 90)
    yaw = number("mounting.yaw_deg", -180, 180, null=True)
    number("slope_deg", -90, 90, null=True)
    # a σ may be large (an angle barely determined), within the ranges of mountcal.core.ranges: finite, and
    # far from where a square or a conversion overflows downstream (export, report)
    sigma_deg, sigma_mps2 = QUANTITIES["result_sigma_deg"], QUANTITIES["result_sigma_mps2"]
    for name in ("roll_deg", "pitch_deg"):
        number(f"uncertainty.{name}", sigma_deg.lo, sigma_deg.hi)
    number("uncertainty.yaw_deg", sigma_deg.lo, sigma_deg.hi, null=yaw is None)
    number("uncertainty.slope_deg", sigma_deg.lo, sigma_deg.hi, null=True)
    vector("uncertainty.rotation_about_vehicle_xyz_deg", 3, sigma_deg.lo, sigma_deg.hi, items_null=True)
    vector("bias_mps2", 3, -MAX_BIAS_MPS2, MAX_BIAS_MPS2, null=True)
    vector("uncertainty.bias_mps2", 3, sigma_mps2.lo, sigma_mps2.hi, null=_get(doc, "bias_mps2") is None)
    number("gravity.value_mps2", *GRAVITY_RANGE_MPS2)
    number("residual_rms_mps2", 0, 2 * G_N)
    if isinstance(doc.get("observability"), dict):  # the report formats it
        number("observability.condition_number", 1 - 1e-9, QUANTITIES["result_value"].hi, null=True)
    if not isinstance(_get(doc, "gravity.source"), str):
        problems.append(f"gravity.source = {_show(_get(doc, 'gravity.source'))} (expected a text)")
    determined = _get(doc, "yaw.determined")
    if determined is not (yaw is not None) and not (yaw is None and any("yaw_deg" in p for p in problems)):
        problems.append(f"yaw.determined = {_show(determined)} while mounting.yaw_deg = {_show(yaw)}")
    if not isinstance(_get(doc, "yaw.reason"), str | None):
        problems.append(f"yaw.reason = {_show(_get(doc, 'yaw.reason'))} (expected a text or null)")
    _check_residuals(doc, problems)
    _check_notes(doc, problems)
    quat = _quaternion(doc, problems)
    if quat is not None and roll is not None and pitch is not None:
        _check_rotation(doc, quat, roll, pitch, yaw, problems)
    if problems:
        raise InputError(
            where,
            "a calibration document with finite values in range and a rotation that matches its angles",
            "; ".join(problems[:6]) + (f"; and {len(problems) - 6} more" if len(problems) > 6 else ""),
            "The file was altered or corrupted: re-create it with `mountcal calibrate`.",
        )


def _check_residuals(doc: dict[str, Any], problems: list[str]) -> None:
    n, rows = _get(doc, "stops.n"), _get(doc, "stops.residual_s_mps2")
    if isinstance(n, bool) or not isinstance(n, int) or n < 0:
        problems.append(f"stops.n = {_show(n)} (expected a count)")
        return
    if not isinstance(rows, list) or len(rows) != n:
        problems.append(f"stops.residual_s_mps2 ({_show(rows)}) (expected {n} rows)")
        return
    for i, row in enumerate(rows):
        if not (isinstance(row, list) and len(row) == 3) or not all(
            v is None or (not isinstance(v, bool) and isinstance(v, int | float) and math.isfinite(v)) for v in row
        ):
            problems.append(f"stops.residual_s_mps2.{i} = {_show(row)} (expected 3 finite numbers or nulls)")
            return


def _check_notes(doc: dict[str, Any], problems: list[str]) -> None:
    notes = doc.get("notes", [])
    if not isinstance(notes, list) or not all(isinstance(x, str) for x in notes):
        problems.append(f"notes = {_show(notes)} (expected a list of texts)")
    if not isinstance(doc.get("confident", True), bool):
        problems.append(f"confident = {_show(doc.get('confident'))} (expected true or false)")


def _quaternion(doc: dict[str, Any], problems: list[str]) -> Rotation | None:
    q = _get(doc, "rotation.quaternion_xyzw")
    ok = isinstance(q, list) and len(q) == 4
    ok = ok and all(not isinstance(v, bool) and isinstance(v, int | float) and math.isfinite(v) for v in q)
    if not ok or abs(math.hypot(*q) - 1.0) > 1e-6:
        problems.append(f"rotation.quaternion_xyzw = {_show(q)} (expected 4 finite numbers of norm 1)")
        return None
    rot = Rotation.from_quat(q)
    matrix = _get(doc, "rotation.matrix_vs")
    if matrix is not None:
        try:
            m = np.asarray(matrix, dtype=float)
        except (TypeError, ValueError):
            m = np.full((1,), np.nan)
        if m.shape != (3, 3) or not np.all(np.isfinite(m)) or np.max(np.abs(m - rot.as_matrix())) > 1e-6:
            problems.append("rotation.matrix_vs does not match rotation.quaternion_xyzw")
    return rot


def _check_rotation(
    doc: dict[str, Any], rot: Rotation, roll: float, pitch: float, yaw: float | None, problems: list[str]
) -> None:
    """The quaternion agrees with the angles: the whole rotation when yaw is known, else the tilt
    (the vehicle's up axis in sensor coordinates, which yaw does not change)."""
    stated = rot_vs_from_angles(np.radians(roll), np.radians(pitch), np.radians(yaw or 0.0))
    if yaw is not None:
        off = float(np.degrees((stated.inv() * rot).magnitude()))
    else:
        up_stated, up_stored = stated.inv().apply([0.0, 0.0, 1.0]), rot.inv().apply([0.0, 0.0, 1.0])
        cross = float(np.linalg.norm(np.cross(up_stated, up_stored)))
        off = float(np.degrees(np.arctan2(cross, float(np.dot(up_stated, up_stored)))))
    if off > ROTATION_TOLERANCE_DEG:
        problems.append(
            f"rotation.quaternion_xyzw is {off:.3g}° away from the rotation of mounting roll/pitch/yaw "
            f"(tolerance {ROTATION_TOLERANCE_DEG:g}°)"
        )


def _get(doc: Any, path: str) -> Any:
    for key in path.split("."):
        if isinstance(doc, dict):
            doc = doc.get(key)
        elif isinstance(doc, list) and key.isdigit() and int(key) < len(doc):
            doc = doc[int(key)]
        else:
            return None
    return doc


def _show(value: Any) -> str:
    text = json.dumps(value) if not isinstance(value, float) or math.isfinite(value) else repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


__all__ = ["ROTATION_TOLERANCE_DEG", "check_document", "read_json", "schema", "write_schema"]
