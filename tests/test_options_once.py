"""Each option that reaches the estimator: one default, one validation, at the edge (issue 24).

For every such option: the default ``--help`` shows is the typed value's (read both), a bad value
is refused once, with a message naming the flag, and the library refuses it with the same rule;
the stops path, the driving path and the fleet refuse the same value alike. The literals that
were written in several places are written once in ``src/``.
"""

from __future__ import annotations

import argparse
import ast
import inspect
import re
from pathlib import Path
from typing import Any

import pytest

from mountcal.apply import rotate_log as rotate_log_module
from mountcal.apply.rotate_log import to_frame
from mountcal.calibration.options import DEFAULT_USE, Options, default
from mountcal.calibration.pipeline import LogJob, _driving_alone, calibrate_log
from mountcal.cli import build_parser, main
from mountcal.core.errors import InputError
from mountcal.estimate.triad import session_stops
from mountcal.estimate.triad_session import MIN_STOP_S, TRIM_S
from mountcal.io.reader import CHUNK_SAMPLES
from mountcal.simulate.drive import simulate_drive

REPO = Path(__file__).resolve().parents[1]
SRC = REPO / "src" / "mountcal"
STOPS = REPO / "data" / "zhang2011_stops.csv"


def _parser(command: str) -> argparse.ArgumentParser:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    parser: argparse.ArgumentParser = sub.choices[command]
    return parser


def _action(command: str, flag: str) -> argparse.Action:
    return next(a for a in _parser(command)._actions if flag in a.option_strings)


# --------------------------------------------------------------------------- one default

# (command, flag, the home of its default)
DEFAULTS = [
    *[(c, "--model", default(Options, "model")) for c in ("calibrate", "fleet", "live")],
    *[(c, "--method", default(Options, "method")) for c in ("calibrate", "fleet")],
    *[(c, "--max-yaw-sigma", default(Options, "max_yaw_sigma_deg")) for c in ("calibrate", "fleet")],
    *[(c, "--use", default(LogJob, "use")) for c in ("calibrate", "fleet")],
    ("rotate", "--chunk", CHUNK_SAMPLES),
    ("triad", "--min-stop-s", MIN_STOP_S),
    ("triad", "--trim-s", TRIM_S),
]


@pytest.mark.parametrize(("command", "flag", "home"), DEFAULTS, ids=[f"{c} {f}" for c, f, _ in DEFAULTS])
def test_the_default_help_shows_is_the_typed_value_s(command: str, flag: str, home: Any) -> None:
    action = _action(command, flag)
    assert action.default == home
    shown = _parser(command).format_help()
    if "%(default)s" in (action.help or ""):
        assert f"default {home}" in " ".join(shown.split())


def test_the_library_s_defaults_are_the_same_homes() -> None:
    assert default(LogJob, "use") == DEFAULT_USE == inspect.signature(calibrate_log).parameters["use"].default
    chunk = inspect.signature(rotate_log_module.rotate_log).parameters["chunk_samples"].default
    assert chunk == CHUNK_SAMPLES
    stops = inspect.signature(session_stops).parameters
    assert (stops["min_stop_s"].default, stops["trim_s"].default) == (MIN_STOP_S, TRIM_S)
    assert Options().terms is None and Options(model="rotation,slope,bias").terms == ("rotation", "slope", "bias")


# --------------------------------------------------------------------------- one validation, naming the flag

# (flag, bad value, the library's Options of the same value)
BAD = [
    ("--model", "rotation,bogus", {"model": "rotation,bogus"}),
    ("--model", "slope,rotation", {"model": "slope,rotation"}),
    ("--method", "nope", {"method": "nope"}),
    ("--max-yaw-sigma", "0", {"max_yaw_sigma_deg": 0.0}),
    ("--gravity", "5", {"gravity_mps2": 5.0}),
]


@pytest.mark.parametrize(("flag", "value", "given"), BAD, ids=[f"{f} {v}" for f, v, _ in BAD])
def test_a_bad_value_is_refused_once_naming_the_flag(
    flag: str, value: str, given: dict[str, Any], capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) if flag in ("--method", "--max-yaw-sigma") else _returns(2):
        code = main(["calibrate", str(STOPS), flag, value])
        assert code == 2
    err = capsys.readouterr().err
    assert flag in err
    said = [line for line in err.splitlines() if flag in line and not line.lstrip().startswith(("usage", "["))]
    assert len(said) == 1, err  # refused once
    with pytest.raises(InputError) as refused:  # the library refuses it with the same rule
        Options(**given)
    python_name = {"--max-yaw-sigma": "max_yaw_sigma_deg", "--gravity": "gravity_mps2"}.get(flag, flag[2:])
    assert python_name in str(refused.value)


class _returns:
    """A no-op context (the CLI returns its exit code instead of raising)."""

    def __init__(self, code: int) -> None:
        self.code = code

    def __enter__(self) -> None:
        return None

    def __exit__(self, *exc: object) -> bool:
        return False


@pytest.fixture(scope="module")
def drive_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    log = tmp_path_factory.mktemp("drive") / "drive.parquet"
    to_frame(simulate_drive(roll_deg=5.0, pitch_deg=6.0, yaw_deg=7.0, seed=3).to_samples()).to_parquet(log, index=False)
    return log


def test_an_unknown_model_term_is_refused_alike_on_every_path(
    drive_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The stops path, the driving-only path, the automatic path and the fleet: the same refusal."""
    runs = [
        ["calibrate", str(STOPS)],
        ["calibrate", str(drive_log), "--use", "driving"],
        ["calibrate", str(drive_log), "--use", "stops"],
        ["calibrate", str(drive_log)],
        ["fleet", str(drive_log.parent), "-o", str(tmp_path / "fleet.parquet")],
    ]
    messages = []
    for run in runs:
        assert main([*run, "--model", "rotation,bogus"]) == 2
        err = capsys.readouterr().err
        messages.append(err[err.index("--model") :].strip())
    assert len(set(messages)) == 1, messages
    assert "unknown: bogus" in messages[0]
    with pytest.raises(InputError, match="unknown: bogus"):
        calibrate_log(drive_log, options=Options(model="rotation,bogus"), use="driving")


def test_driving_refuses_a_model_term_it_cannot_estimate(drive_log: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["calibrate", str(drive_log), "--use", "driving", "--model", "rotation,slope,bias"]) == 2
    err = capsys.readouterr().err
    assert "--model rotation,slope,bias with --use driving" in err and "bias" in err
    with pytest.raises(InputError, match="use='driving'"):
        LogJob(paths=(str(drive_log),), options=Options(model="rotation,slope,bias"), use="driving")
    with pytest.raises(InputError, match="use="):
        LogJob(paths=(str(drive_log),), use="both")  # type: ignore[arg-type]


def test_a_result_from_driving_alone_states_the_model_it_did_not_apply() -> None:
    from mountcal.estimate.driving import estimate_driving

    samples = simulate_drive(yaw_deg=7.0, seed=3).to_samples()
    fit = estimate_driving(samples)
    job = LogJob(paths=("drive.parquet",), options=Options(model="rotation,slope,bias"))
    cal = _driving_alone(fit, samples, job)
    assert any("model='rotation,slope,bias' was not applied" in n and "bias" in n for n in cal.notes)
    plain = _driving_alone(fit, samples, LogJob(paths=("drive.parquet",)))
    assert not any("was not applied" in n for n in plain.notes)


# --------------------------------------------------------------------------- one home in the source


def _sources() -> dict[Path, str]:
    return {p: p.read_text(encoding="utf-8") for p in SRC.rglob("*.py")}


def _count(pattern: str) -> list[str]:
    return [
        f"{p.relative_to(SRC)}:{s[: m.start()].count(chr(10)) + 1}"
        for p, s in _sources().items()
        for m in re.finditer(pattern, s)
    ]


def test_the_chunk_default_is_written_once() -> None:
    """``100_000`` samples per chunk: io/reader.py's CHUNK_SAMPLES (core's other 100_000 are other quantities)."""
    found = [c for c in _count(r"(?<![\d_])100_?000(?![\d_])") if not c.startswith("core/")]
    assert found == ["io/reader.py:25"], found


def _numeric_defaults(tree: ast.AST, params: tuple[str, ...], flags: tuple[str, ...]) -> list[tuple[int, str]]:
    """(line, name) of each parameter in ``params`` or parser flag in ``flags`` whose default is a number literal."""
    found = []
    for node in ast.walk(tree):
        pairs: list[tuple[str, ast.expr | None]] = []
        line = getattr(node, "lineno", 0)
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            a = node.args
            padded = [None] * (len(a.args) - len(a.defaults)) + list(a.defaults)
            given = [*zip(a.args, padded, strict=True), *zip(a.kwonlyargs, a.kw_defaults, strict=True)]
            pairs = [(p.arg, d) for p, d in given if p.arg in params]
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "add_argument":
            named = [a.value for a in node.args if isinstance(a, ast.Constant) and a.value in flags]
            pairs = [(f, k.value) for f in named for k in node.keywords if k.arg == "default"]
        found += [(line, n) for n, d in pairs if isinstance(d, ast.Constant) and type(d.value) in (int, float)]
    return found


def test_the_triad_session_defaults_are_written_once() -> None:
    """A hand-held session's --min-stop-s and --trim-s: estimate/triad_session.py; the parser and
    session_stops name them, no parameter or flag of these names has a number of its own."""
    params, flags = ("min_stop_s", "trim_s"), ("--min-stop-s", "--trim-s")
    found = [
        f"{p.relative_to(SRC)}:{line} {name}"
        for p, s in _sources().items()
        for line, name in _numeric_defaults(ast.parse(s), params, flags)
    ]
    assert found == [], found
    written_twice = ast.parse("def f(min_stop_s=3.0): ...\np.add_argument('--trim-s', default=0.5)")
    assert _numeric_defaults(written_twice, params, flags) == [(1, "min_stop_s"), (2, "--trim-s")]  # it finds them


def test_the_base_terms_are_written_once() -> None:
    found = _count(r"\(\s*\"rotation\",\s*\"slope\"")
    assert len(found) == 1 and found[0].startswith("estimate/effects/__init__.py"), found


def test_stop_table_or_log_is_decided_in_one_function() -> None:
    calls = _count(r"(?<![\w.])input_kind\(")
    assert all(c.startswith("io/kind.py") for c in calls), calls
    assert len(_count(r"kind_of_input\(")) >= 2  # the pipeline (calibrate, fleet) and the triad session


def test_level_only_is_decided_once_and_passed_on() -> None:
    text = (SRC / "apply" / "rotate_log.py").read_text(encoding="utf-8")
    assert "level_only=True" not in text
    assert text.count("check_applicable(") == 1  # the CLI leaves it to rotate_log (and names the file)
    assert "check_applicable" not in (SRC / "cli" / "rotate.py").read_text(encoding="utf-8")


def test_require_confident_is_refused_by_one_function() -> None:
    assert len(_count(r"a confident calibration")) == 1
    assert len(_count(r"refuse_not_confident\(")) == 3  # its definition, rotate, fleet


def test_simulated_logs_are_written_with_the_core_atomic_forms() -> None:
    text = (SRC / "io" / "writers.py").read_text(encoding="utf-8")
    assert "open(tmp" not in text and "os.replace" not in text
