"""The effects are a registry (issue 24): no module outside ``estimate/effects/`` knows a built-in one by name,
and an effect another package registers is fitted, reported and summarised with no other module edited."""

from __future__ import annotations

import ast
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from tests.effect_plugin import Q_TRUE, install, quadratic

from mountcal.calibration.fit import calibrate
from mountcal.calibration.options import Options
from mountcal.calibration.summary import summary
from mountcal.estimate import effects as registry
from mountcal.simulate.stops import simulate_stops
from mountcal.stops.table import StopTable

SRC = Path(__file__).resolve().parents[1] / "src" / "mountcal"
EFFECTS = SRC / "estimate" / "effects"

# Strings equal to a built-in effect's name, report key or parameter name that are no effect (or are a published
# format's field, filled and read through the registry in one place). Path (under src/mountcal) → string → why.
ALLOWED: dict[str, dict[str, str]] = {
    # the v2 calibration JSON: its bias_mps2 fields (filled by effects.offset_fields, read by effects.offset_of) and
    # its gravity object (the gravity in force and its source, whatever the model)
    "core/result.py": {"bias_mps2": "format field", "gravity": "format object"},
    "core/result_file.py": {"bias_mps2": "the format's validation of that field"},
    "apply/rotate_log.py": {"bias_mps2": "the rotated log's metadata, a copy of the result's field"},
    "core/ranges.py": {
        "gravity_mps2": "the range of a given --gravity",
        "bias": "a key of the triad file format's table of ranges",
    },
    # options and input conventions named gravity: the user's --gravity, not the fitted effect
    "core/option_names.py": {"gravity": "the --gravity option"},
    "cli/options.py": {"gravity": "the --gravity option's attribute"},
    "cli/calibrate.py": {"gravity_mps2": "the Options field --gravity fills"},
    "cli/triad.py": {"gravity_mps2": "the Options field --gravity fills"},
    "calibration/options.py": {"gravity": "the --gravity option in a message"},
    "calibration/record.py": {"gravity": "the input convention 'gravity' (given, inferred or default)"},
    "calibration/summary.py": {"gravity": "that input convention (the summary's gravity line says it)"},
    "io/input_conventions.py": {"gravity": "the input convention", "gravity_mps2": "its column and field"},
    "loop/plausibility.py": {"gravity": "the name of the plausibility check of the gravity in force"},
    # a temperature channel of a log or table: the sensor's reading, not the effect that may use it
    "io/ros/topics.py": {"temperature": "a ROS topic kind"},
    "io/ros/pieces.py": {"temperature": "a ROS message kind and its samples"},
    "io/can/mapping.py": {"temperature": "a CAN signal role"},
    "io/can/signals.py": {"temperature": "a CAN signal role"},
    "io/mcap/read.py": {"temperature": "a ROS message kind and its field"},
    "io/mcap/records.py": {"temperature": "a ROS message kind"},
    "io/ros/kinds.py": {"temperature": "a ROS message kind and its field"},
    "io/ros2/cdr.py": {"temperature": "a ROS 2 message kind and its field"},
    "io/table/layout.py": {"temperature": "a column alias of a stop table"},
    "io/writers.py": {"temperature": "a ROS message kind and field the test-log writers produce"},
    "outputs/report/html.py": {"temperature": "the label of the report's residual-trend figure"},
    # a datasheet's fields (sensor_spec) and the simulator's truth: the user's words for the sensor, not a term
    "io/sensor_spec.py": {"scale": "a datasheet field", "bias_mps2": "a datasheet field"},
    "simulate/session.py": {"bias_mps2": "the simulated session's truth parameter"},
    # the triad's sphere fit: its own model (mountcal triad --terms), not the static model's effects
    "estimate/sphere.py": {
        name: "a term or parameter of the triad's sphere fit"
        for name in ("bias", "scale", "bias_x", "bias_y", "bias_z", "cross_xy", "cross_xz", "cross_yz")
    },
}


def _builtin_words() -> set[str]:
    table = StopTable(acc_s=np.zeros((3, 3)), source="<names>")
    words: set[str] = set()
    for name in registry.BUILTIN:
        effect = registry.get(name)
        words |= {effect.name, effect.report_key, *effect.parameters(table)}
    return words


def _strings(path: Path) -> Iterator[tuple[int, str]]:
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            yield node.lineno, node.value


def test_no_module_outside_the_effects_names_a_builtin_effect() -> None:
    words = _builtin_words()
    assert {"bias", "scale", "gravity", "temperature", "site_slope", "bias_mps2", "bias_x"} <= words
    found: dict[str, set[str]] = {}
    leaks = []
    for path in sorted(SRC.rglob("*.py")):
        if EFFECTS in path.parents:
            continue
        rel = path.relative_to(SRC).as_posix()
        for line, text in _strings(path):
            if text in words:
                found.setdefault(rel, set()).add(text)
                if text not in ALLOWED.get(rel, {}):
                    leaks.append(f"{rel}:{line}: {text!r}")
        names = {n.id for n in ast.walk(ast.parse(path.read_text(encoding="utf-8"))) if isinstance(n, ast.Name)}
        if "WITH_BIAS" in names:
            leaks.append(f"{rel}: WITH_BIAS (the offset's model is WITH_OFFSET, from the registry)")
    assert not leaks, "ask the effect registry instead:\n" + "\n".join(leaks)
    stale = {f"{p}: {s}" for p, allowed in ALLOWED.items() for s in allowed if s not in found.get(p, set())}
    assert not stale, f"allow-list entries no longer needed: {sorted(stale)}"


# --- an effect registered from outside, through the mountcal.effects entry points ---------------------------


@pytest.fixture
def quadratic_effect(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """The plugin's module and distribution metadata on sys.path; the registry asked afresh."""
    monkeypatch.syspath_prepend(install(tmp_path).path_entry)
    registry.registered.cache_clear()
    yield
    registry.registered.cache_clear()


def _stops() -> StopTable:
    table, _ = simulate_stops(slope_deg=10.0, beta_deg=np.arange(0.0, 360.0, 15.0), seed=3)
    return replace(table, acc_s=quadratic(table.acc_s))


def test_an_effect_of_another_package_is_fitted_reported_and_summarised(quadratic_effect: None) -> None:
    assert "quadratic" in registry.names()
    table = _stops()
    cal = calibrate(table, Options(model="rotation,slope,quadratic"))
    assert cal.model[-1] == "quadratic"
    fitted = cal.effect("quadratic_per_mps2")
    assert fitted is not None and fitted.components == ("quad_x", "quad_y")
    assert np.all(np.abs(np.array(fitted.value) - Q_TRUE) < 5 * np.array(fitted.sigma, dtype=float))
    assert any(e["name"] == "quadratic_per_mps2" for e in cal.to_dict()["effects"])  # in the result file
    line = next(x for x in summary(cal).splitlines() if x.strip().startswith("quadratic ("))
    assert "quad_x, quad_y" in line and "1/(m/s²)" in line  # the default summary of BaseEffect
    assert cal.bias_mps2 is None and "bias   (" not in summary(cal)  # no offset fitted: no line of it

    # not in the model: the observability check judges it, the systematic σ propagates its datasheet limits
    plain = calibrate(table, Options(model="rotation,slope"))
    verdicts = {v.effect: v for v in plain.observability.separability}  # type: ignore[union-attr]
    assert verdicts["quadratic"].separable and "quadratic with bias" in verdicts
    assert plain.systematic is not None and {"quad_x", "quad_y"} <= set(plain.systematic.propagated)
    assert any("horizontal nonlinearity" in n for n in plain.notes if "dominated by sensor errors" in n)  # its label


def test_the_offset_field_of_the_result_file_is_the_offset_effect() -> None:
    table, _ = simulate_stops(slope_deg=10.0, bias_mps2=np.array([0.1, -0.2, 0.15]), seed=2)
    cal = calibrate(table, Options(model="rotation,slope,bias"))
    entry = cal.effect(registry.offset().report_key)
    assert cal.bias_mps2 is not None and cal.bias_sigma_mps2 is not None and entry is not None
    assert np.array_equal(cal.bias_mps2, entry.value)
    assert np.allclose(cal.bias_sigma_mps2, np.array(entry.sigma) * cal.fit.birge_ratio)
    read = registry.offset_of(replace(cal, effects=()))  # a result holding the field only
    assert read is not None and np.array_equal(read.value, cal.bias_mps2)
    assert "bias   (" in summary(cal)  # the summary's line, as before the registry
