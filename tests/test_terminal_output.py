"""The terminal output of every command, enumerated from the parser (a new command cannot be left out).

The rules (``mountcal --help``'s epilog, :data:`mountcal.cli.options.QUIET_RULE`):
- stdout holds a result only when asked (``-o -``, ``--json``); a plain run leaves it empty;
- ``--json`` is accepted by every command and puts one JSON document on stdout, nothing else;
- the first line on stderr is the command's answer in one line (angles each with its σ, or
  ``undetermined``; ``confident`` or ``NOT CONFIDENT: …``), then what supports it, then notes;
- no line is printed twice (a note, a reason for doubt);
- ``-q`` keeps the answer line alone, ``-qq`` not even that.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from mountcal.cli import build_parser, main

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "data"
STOPS = DATA / "zhang2011_stops.csv"
PARKING, PROTOCOL = DATA / "parking.mcap", DATA / "parking_protocol.csv"
DBC, MAPPING = str(DATA / "imu_mm5_10.dbc"), str(DATA / "imu_mm5_10.toml")
BETA = (0.0, 90.0, 180.0, 270.0)

_ANGLE = r"(-?\d+\.\d{3} ± \d+\.\d{3}°|undetermined)"
ANSWER = rf"roll {_ANGLE}  pitch {_ANGLE}  yaw {_ANGLE}  slope {_ANGLE}  (confident|NOT CONFIDENT: \S.*)"

# the answer line of each command (a command missing here fails test_every_command_is_covered)
ANSWERS = {
    "calibrate": rf"{ANSWER}",
    "stops": r"\d+ stops (at \d+ headings \(.+\)|without headings), from \d+ samples: \S+",
    "inspect": r"\S.*: \w+, \d+\.\d s, \d+ streams?(; parked periods: .+)?",
    "rotate": rf"wrote \d+ samples in the (vehicle|levelled) frame to \S+ with {ANSWER}",
    "report": rf"report of {ANSWER} \(\d+ figures\): \S+",
    "fleet": r"fleet: \d+ logs of \d+ vehicles on .+: \d+ ok, \d+ failed; .+",
    "simulate": r"simulated \d+ stops .*: roll \S+°, pitch \S+°, yaw \S+°, slope \S+°.*",
    "plan": r"(plan: \d+ stops of \S+ s each on a \S+° slope, headings .+|not reachable, because .+)",
    "live": rf"session ended \((bus silent|target met|interrupted)\), \d+ stops: {ANSWER}",
    "export": rf"exported to [\w-]+ \(.+\): {ANSWER}",
    "triad": r"triad calibration from \d+ stops, .+: \S+",
}


def parser_commands() -> list[str]:
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    assert isinstance(sub.choices, dict)
    return sorted(sub.choices)


@pytest.fixture(scope="module")
def inputs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A result of the sample log, a triad session's stops, and a short simulated CAN session for live."""
    from mountcal.io import writers as export
    from mountcal.simulate.stops import simulate_parking_log

    folder = tmp_path_factory.mktemp("inputs")
    result = folder / "result.json"
    assert main(["calibrate", str(PARKING), "--protocol", str(PROTOCOL), "-o", str(result), "-qq"]) == 0
    rng = np.random.default_rng(1)
    grid = np.array(np.meshgrid([-1, 0, 1], [-1, 0, 1], [-1, 0, 1])).reshape(3, -1).T
    faces = np.array([9.80665 * v / np.linalg.norm(v) for v in grid if 0 < abs(v).sum() < 3])
    acc = faces + rng.normal(0, 1e-3, faces.shape)
    triad = folder / "faces.csv"
    pd.DataFrame(acc, columns=["ax", "ay", "az"]).assign(sx=0.01, sy=0.01, sz=0.01, n=100).to_csv(triad, index=False)
    blf = folder / "session.blf"
    session = simulate_parking_log(beta_deg=BETA, stop_s=15.0, drive_s=5.0, seed=11)
    export.write_log(blf, session, dbc_path=DBC, with_fix=(56.15, 10.2, 40.0))
    return {"result": result, "triad": triad, "blf": blf}


def invocation(command: str, inputs: dict[str, Path], out: Path) -> list[str]:
    """A plain run of ``command`` that writes its files into ``out`` (nothing asked on stdout)."""
    return {
        "calibrate": ["calibrate", str(PARKING), "--protocol", str(PROTOCOL), "-o", str(out / "r.json")],
        "stops": ["stops", str(PARKING), "--protocol", str(PROTOCOL), "-o", str(out / "s.csv")],
        "inspect": ["inspect", str(PARKING)],
        "rotate": ["rotate", str(PARKING), "--calibration", str(inputs["result"]), "-o", str(out / "v.parquet")],
        "report": ["report", str(inputs["result"]), "-o", str(out / "r.html")],
        "fleet": ["fleet", str(STOPS), "-o", str(out / "f.parquet"), "--workers", "1"],
        "simulate": ["simulate", "-o", str(out / "sim.csv"), "--truth", str(out / "truth.json")],
        "plan": ["plan", "--target", "roll=0.7,pitch=0.7,yaw=0.9", "--noise", "5"],
        "live": ["live", "--interface", "virtual", "--channel", "terminal", "--dbc", DBC, "--mapping", MAPPING,
                 "--timeout", "0.3", "-o", str(out / "session"), "--json-events", str(out / "events.jsonl")],
        "export": ["export", str(inputs["result"]), "--to", "ros2-static-tf", "-o", str(out / "tf.txt")],
        "triad": ["triad", str(inputs["triad"]), "-o", str(out / "t.json")],
    }[command]  # fmt: skip


Run = Callable[..., tuple[int, str, str]]


@pytest.fixture
def run(
    inputs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> Run:
    """Run a command (plain, plus ``extra`` options) in a fresh folder: its exit code, stdout, stderr."""
    from tests.test_live import replay

    import mountcal.io.can.bus as bus

    monkeypatch.setattr(bus, "open_bus", lambda _i, channel: replay(inputs["blf"], f"{channel}-{tmp_path.name}"))
    counter = iter(range(100))

    def call(command: str, *extra: str) -> tuple[int, str, str]:
        out = tmp_path / f"run{next(counter)}"
        out.mkdir()
        capsys.readouterr()
        code = main([*invocation(command, inputs, out), *extra])
        got = capsys.readouterr()
        return code, got.out, got.err

    return call


def test_every_command_is_covered() -> None:
    """Each command of the parser has an answer pattern and a run here."""
    assert set(ANSWERS) == set(parser_commands())


@pytest.mark.parametrize("command", parser_commands())
def test_stdout_is_empty_unless_results_are_asked(command: str, run: Run) -> None:
    code, out, err = run(command)
    assert code == 0, err
    assert out == ""


@pytest.mark.parametrize("command", parser_commands())
def test_json_is_accepted_and_is_the_one_document_on_stdout(command: str, run: Run) -> None:
    code, out, err = run(command, "--json")
    assert code == 0, err
    doc = json.loads(out)  # one document, nothing else
    assert isinstance(doc, dict) and doc


def _summary(command: str, err: str, tmp: Path | None = None) -> list[str]:
    """stderr's lines; a live session's event lines (shown as they come) are taken off the front."""
    lines = err.splitlines()
    if command == "live":
        from mountcal.sessions.live import line_of

        assert tmp is not None
        events = [json.loads(line) for line in next(tmp.glob("run*/events.jsonl")).read_text().splitlines()]
        shown = [line_of(e) for e in events]
        assert lines[: len(shown)] == shown
        lines = lines[len(shown) :]
    return lines


@pytest.mark.parametrize("command", parser_commands())
def test_the_first_line_is_the_answer(command: str, run: Run, tmp_path: Path) -> None:
    code, _, err = run(command)
    assert code == 0, err
    lines = _summary(command, err, tmp_path)
    assert re.fullmatch(ANSWERS[command], lines[0]), lines[0]
    assert not any(re.fullmatch(ANSWERS[command], line) for line in lines[1:])  # said once


@pytest.mark.parametrize("command", parser_commands())
def test_no_line_is_printed_twice(command: str, run: Run, tmp_path: Path) -> None:
    code, _, err = run(command)
    assert code == 0, err
    lines = [line for line in _summary(command, err, tmp_path) if line.strip()]
    assert len(lines) == len(set(lines)), [line for line in lines if lines.count(line) > 1]


@pytest.mark.parametrize("command", parser_commands())
def test_quiet_keeps_the_answer_line_alone(command: str, run: Run) -> None:
    code, out, err = run(command, "-q")
    assert code == 0 and out == ""
    assert len(err.splitlines()) == 1 and re.fullmatch(ANSWERS[command], err.rstrip("\n")), err
    code, out, err = run(command, "-qq")
    assert (code, out, err) == (0, "", "")


def test_a_result_that_is_not_confident_says_its_main_reason_once(tmp_path: Path) -> None:
    """NOT CONFIDENT with the main reason on the answer line; the reasons in full once, in the notes."""
    from mountcal.calibration.fit import calibrate
    from mountcal.calibration.summary import summary
    from mountcal.simulate.stops import simulate_stops

    disturbance = np.random.default_rng(0).normal(0.0, 0.03, (12, 3))
    table, _ = simulate_stops(disturbance_mps2=disturbance, seed=1)
    cal = calibrate(table)
    text = summary(cal)
    first, *rest = text.splitlines()
    assert re.fullmatch(ANSWER, first) and "NOT CONFIDENT: " in first
    reasons = [u.what for u in cal.unexplained]
    assert reasons and reasons[0] in first
    for what in reasons:
        assert sum(what in line for line in rest) == 1, what  # once, in the note that lists them
    assert len(rest) == len(set(rest))


def test_an_undetermined_yaw_is_said_without_a_number() -> None:
    from mountcal.calibration.fit import Options, calibrate
    from mountcal.calibration.summary import answer
    from mountcal.stops.table import read_stop_table

    cal = calibrate(read_stop_table(STOPS, headings="relative"), Options())
    assert cal.yaw_deg is None
    line = answer(cal)
    assert re.fullmatch(ANSWER, line) and "  yaw undetermined  " in line


def test_the_help_states_the_rule() -> None:
    text = " ".join(build_parser().format_help().split())
    assert "-q keeps only the answer line" in text and "results go to stdout only when asked" in text
    helps: dict[str, Any] = next(a for a in build_parser()._actions if a.dest == "command").choices  # type: ignore[assignment]
    for name, p in helps.items():
        assert "--json" in p.format_help(), name
        assert "-q keeps only the answer line" in " ".join(p.format_help().split()), name


def _with_stderr_unread(args: list[str]) -> int:
    """``mountcal ARGS`` with its stderr a pipe nobody reads any more (``2>&1 | head`` once head has ended)."""
    import os
    import subprocess
    import sys

    read, write = os.pipe()
    os.close(read)
    try:
        return subprocess.run(
            [sys.executable, "-m", "mountcal", *args], stderr=write, stdout=subprocess.DEVNULL
        ).returncode
    finally:
        os.close(write)


def test_a_stderr_nobody_reads_does_not_stop_the_results(tmp_path: Path) -> None:
    """The summary cannot be shown, the result is written all the same (it was exit 0 and no file);
    bad input still exits non-zero and writes nothing."""
    unread, read = tmp_path / "unread.json", tmp_path / "read.json"
    assert _with_stderr_unread(["calibrate", str(STOPS), "-o", str(unread)]) == 0
    assert main(["calibrate", str(STOPS), "-o", str(read)]) == 0
    ours, theirs = json.loads(unread.read_text()), json.loads(read.read_text())
    assert ours["mounting"] == theirs["mounting"], (ours["mounting"], theirs["mounting"])
    bad = tmp_path / "bad.csv"
    bad.write_text("a;b\n1;2\n")
    assert _with_stderr_unread(["calibrate", str(bad), "-o", str(tmp_path / "no.json")]) == 2
    assert not (tmp_path / "no.json").exists()


def test_a_progress_bar_nobody_reads_does_not_stop_the_results(tmp_path: Path) -> None:
    """The bars write to stderr themselves (tqdm), not through the status lines: the same holds."""
    (tmp_path / "v").mkdir()
    (tmp_path / "v" / "a.csv").write_bytes(STOPS.read_bytes())
    output = tmp_path / "out" / "fleet.parquet"
    assert _with_stderr_unread(["fleet", str(tmp_path / "v"), "-o", str(output), "--progress"]) == 0
    assert list(pd.read_parquet(output)["status"]) == ["ok"]
