"""Every path option of every command is declared (input or output) where its parser is built, and the
one check made from the declarations holds for each of them (issue 27).

The walk is over the parsers themselves: an option added later is tested here without a line of
its own, and a path option added with plain ``add_argument`` fails
:func:`test_every_path_option_is_declared`.
"""

from __future__ import annotations

import argparse
import os
import socket
import stat
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from mountcal import cli
from mountcal.cli.path_options import PathOption, command_parser, declared, label
from mountcal.core import ranges
from mountcal.core.paths import output_lock

REPO = Path(__file__).resolve().parents[1]

# String-valued options that name no file (by dest). Any other option taking a string must be declared
# with mountcal.cli.path_options.add_path: a new one fails the test below until it is (or is listed here).
NOT_PATHS = {
    "topic",
    "field",
    "columns",
    "model",
    "scheduler",
    "storage_option",
    "preset",
    "target",
    "interface",
    "channel",
    "parent",
    "child",
    "axes",  # a signed axis map (x,-y,z)
}
# values for required options that are not paths
REQUIRED_VALUES = {"interface": "virtual", "channel": "test-paths", "target": "roll=1"}


def parsers() -> dict[str, argparse.ArgumentParser]:
    parser = cli.build_parser()
    return {name: command_parser(parser, name) for name in cli.COMMANDS}


def takes_text(action: argparse.Action) -> bool:
    """An option whose value is free text (could be a path): not a flag, a number (of a quantity of
    mountcal.core.ranges, perhaps with its unit) or a choice."""
    if action.nargs == 0 or action.choices is not None or isinstance(action, argparse._HelpAction):
        return False
    return action.type not in (int, float) and ranges.option_quantities(action) is None


def path_actions(role: str) -> list[tuple[str, argparse.Action, PathOption]]:
    found = []
    for command, p in parsers().items():
        for action in p._actions:
            spec = declared(action)
            if spec is not None and spec.role == role:
                found.append((command, action, spec))
    return found


OUTPUTS = path_actions("output")
INPUTS = path_actions("input")
PAIRS = [(c, o, i) for c, o, _ in OUTPUTS for c2, i, _ in INPUTS if c == c2]
PAIR_IDS = [f"{c}:{label(o)}<-{label(i)}" for c, o, i in PAIRS]


def ids(cases: list[tuple[str, argparse.Action, PathOption]]) -> list[str]:
    return [f"{c}:{label(a)}" for c, a, _ in cases]


def test_every_path_option_is_declared() -> None:
    undeclared = [
        f"{command} {label(action)} ({action.dest})"
        for command, p in parsers().items()
        for action in p._actions
        if takes_text(action) and declared(action) is None and action.dest not in NOT_PATHS
    ]
    assert not undeclared, f"declare these with add_path (or list them in NOT_PATHS): {undeclared}"
    assert len(INPUTS) >= 30 and len(OUTPUTS) >= 15  # the walk found the declarations
    for name in cli.COMMANDS:
        assert any(c == name for c, _, _ in INPUTS), f"{name} declares no input"


def test_the_walk_catches_an_undeclared_path_option() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--new-output", help="also write something here")
    assert any(takes_text(a) and declared(a) is None and a.dest not in NOT_PATHS for a in p._actions)


# ------------------------------------------------------------------ building a command line for any option


def fill(tmp: Path, command: str, skip: set[str]) -> list[str]:
    """The command with every required option filled: inputs as small files, outputs as new paths."""
    argv, positional = [command], []
    for action in parsers()[command]._actions:
        if not action.required or action.dest in skip:
            continue
        spec = declared(action)
        if spec is None:
            value = next(iter(action.choices)) if action.choices else REQUIRED_VALUES[action.dest]
        elif spec.role == "input":
            value = str(tmp / f"in_{action.dest}")
            Path(value).write_bytes(b"x\n")
        else:
            value = str(tmp / f"out_{action.dest}")
        if action.option_strings:
            argv += [action.option_strings[0], str(value)]
        else:
            positional.append(str(value))
    return argv + positional


def with_value(argv: list[str], action: argparse.Action, value: str) -> list[str]:
    if action.option_strings:
        return [*argv, action.option_strings[0], value]
    return [*argv, value]


def written_by(command: str, action: argparse.Action, spec: PathOption, value: str, argv: list[str]) -> list[str]:
    """The files an output option writes for ``value`` (live's -o PREFIX: four)."""
    if spec.writes is None:
        return [value]
    args = cli.build_parser().parse_args(with_value(argv, action, value))
    return [path for path, _ in spec.writes(value, args)]


def snapshot(path: Path) -> tuple[int, bytes]:
    return path.stat().st_ino, path.read_bytes()


def run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    code = cli.main(argv)
    return code, capsys.readouterr().err


# ------------------------------------------------------------------ each output refuses each input


@pytest.mark.parametrize(("command", "output", "input_"), PAIRS, ids=PAIR_IDS)
def test_each_output_refuses_each_input_of_its_command(
    command: str,
    output: argparse.Action,
    input_: argparse.Action,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    argv = fill(tmp_path, command, skip={output.dest, input_.dest})
    out_spec = declared(output)
    assert out_spec is not None
    files = written_by(command, output, out_spec, str(tmp_path / "victim"), with_value(argv, input_, "placeholder"))
    for victim in map(Path, files):  # every file the output writes, each in turn the input's path
        victim.write_bytes(b"the input's bytes\n")
        before = snapshot(victim)
        code, err = run(with_value(with_value(argv, input_, str(victim)), output, str(tmp_path / "victim")), capsys)
        assert code == 2, err
        assert "never overwrites its input" in err and str(victim) in err and "Traceback" not in err
        assert snapshot(victim) == before
        victim.unlink()


@pytest.fixture(scope="module")
def real_inputs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Valid inputs, so that on the code before the check each reproduction ran to the end and wrote."""
    import shutil

    import numpy as np

    from mountcal.estimate.triad import Triad

    d = tmp_path_factory.mktemp("real_inputs")
    assert cli.main(["simulate", "-o", str(d / "s.csv"), "--seed", "3"]) == 0
    assert cli.main(["simulate", "--log", str(d / "log.mcap"), "--rate-hz", "50"]) == 0
    Triad(np.array([0.01, -0.02, 0.03]), np.zeros(6), np.eye(9) * 1e-8, "test").save(d / "t.json")
    (d / "spec.toml").write_text("scale = 0.01\ncross_axis = 0.005\n")
    shutil.copy(REPO / "data" / "imu_mm5_10.dbc", d / "b.dbc")
    shutil.copy(REPO / "data" / "parking_protocol.csv", d / "s_protocol.csv")
    return {p.name: p for p in d.iterdir()}


LIVE = ["live", "--interface", "virtual", "--channel", "issue27", "--timeout", "0.2"]
REPRODUCTIONS = {  # issue 27, reproduction 1: each exited 0 with the input destroyed (inputs valid here)
    "calibrate --triad": ["calibrate", "s.csv", "--triad", "t.json", "-o", "t.json"],
    "calibrate --sensor-spec": ["calibrate", "s.csv", "--sensor-spec", "spec.toml", "-o", "spec.toml"],
    "calibrate --report over --triad": ["calibrate", "s.csv", "--triad", "t.json", "--report", "t.json"],
    "triad --imucal": ["triad", "s.csv", "--imucal", "t.json", "-o", "t.json"],
    "plan --from-log": ["plan", "--target", "roll=1", "--from-log", "log.mcap", "-o", "log.mcap"],
    "live --json-events over --dbc": [*LIVE, "--dbc", "b.dbc", "--json-events", "b.dbc", "-o", "x"],
    "live --report over --dbc": [*LIVE, "--dbc", "b.dbc", "--report", "b.dbc", "-o", "x"],
    "live -o over --plan": [*LIVE, "--dbc", "b.dbc", "--plan", "s_protocol.csv", "-o", "s"],
}


@pytest.mark.parametrize("case", list(REPRODUCTIONS))
def test_the_reproductions_of_issue_27_keep_their_input(
    case: str, real_inputs: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    folder = next(iter(real_inputs.values())).parent
    argv = [str(folder / a) if a in real_inputs or a in ("x", "s") else a for a in REPRODUCTIONS[case]]
    before = {p: snapshot(p) for p in folder.iterdir()}
    code, err = run(argv, capsys)
    assert code == 2 and "never overwrites its input" in err, err
    assert {p: snapshot(p) for p in folder.iterdir()} == before


# ------------------------------------------------------------------ outputs: never a special file


SPECIALS = ("fifo", "socket", "directory", "device", "symlink loop")
KIND = {"fifo": "a FIFO", "socket": "a socket", "directory": "a directory", "device": "a character device",
        "symlink loop": "a symlink loop"}  # fmt: skip


def make(kind: str, path: Path) -> Iterator[None]:
    """``path`` made into ``kind`` for the block; afterwards it must still be one."""
    held = None
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "socket":
        held = socket.socket(socket.AF_UNIX)
        held.bind(str(path))
    elif kind == "directory":
        path.mkdir()
    elif kind == "device":
        path.symlink_to("/dev/null")
    else:
        path.symlink_to(path.name)
    try:
        yield
        mode = os.lstat(path).st_mode
        still = {"fifo": stat.S_ISFIFO, "socket": stat.S_ISSOCK, "directory": stat.S_ISDIR, "device": stat.S_ISLNK,
                 "symlink loop": stat.S_ISLNK}[kind](mode)  # fmt: skip
        assert still, f"{path} is no longer {kind}"
        assert stat.S_ISCHR(os.stat("/dev/null").st_mode)
    finally:
        if held is not None:
            held.close()


@pytest.fixture
def short_dir() -> Iterator[Path]:
    """A folder with a short path (a Unix socket's path has at most 107 bytes)."""
    import shutil
    import tempfile

    folder = Path(tempfile.mkdtemp(prefix="mc-", dir="/tmp"))
    yield folder
    shutil.rmtree(folder)


@pytest.mark.parametrize("kind", SPECIALS)
@pytest.mark.parametrize(("command", "output", "spec"), OUTPUTS, ids=ids(OUTPUTS))
def test_no_output_replaces_a_special_file(
    command: str,
    output: argparse.Action,
    spec: PathOption,
    kind: str,
    short_dir: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    argv = fill(short_dir, command, skip={output.dest})
    value = str(short_dir / "out")
    for target in map(Path, written_by(command, output, spec, value, argv)):  # live's -o PREFIX: each of its files
        gen = make(kind, target)
        next(gen)
        code, err = run(with_value(argv, output, value), capsys)
        assert code == 2, err
        assert KIND[kind] in err and str(target) in err and "Traceback" not in err
        next(gen, None)
        if kind == "directory":
            target.rmdir()
        else:
            target.unlink()


@pytest.mark.parametrize("kind", ["fifo", "socket", "directory", "device", "symlink loop", "missing", "too large"])
@pytest.mark.parametrize(("command", "input_", "spec"), INPUTS, ids=ids(INPUTS))
def test_every_input_is_a_regular_file_or_a_folder_where_one_is_taken(
    command: str,
    input_: argparse.Action,
    spec: PathOption,
    kind: str,
    short_dir: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    argv = fill(short_dir, command, skip={input_.dest})
    path = short_dir / "in"
    expected = {"missing": "no such file", "too large": "MOUNTCAL_MAX_INPUT_MB", **KIND}[kind]
    if spec.globs and kind in ("missing", "symlink loop"):
        expected = ""  # nothing at the path: a glob the command expands, and says what it found
    if kind == "too large":
        if not spec.small:
            pytest.skip("a log: read in chunks, no size limit")
        path.write_bytes(b"x" * 2000)
        monkeypatch.setenv("MOUNTCAL_MAX_INPUT_MB", str(1000 / 2**20))
    elif kind == "directory" and spec.folders:
        pytest.skip("this input takes folders")
    elif kind != "missing":
        gen = make(kind, path)
        next(gen)
    code, err = run(with_value(argv, input_, str(path)), capsys)
    assert code == 2, err
    assert expected in err and str(path) in err and "Traceback" not in err
    assert not [p for p in short_dir.iterdir() if p.name.startswith("out")]  # nothing written


def test_outputs_of_one_command_never_share_a_path(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    dbc = tmp_path / "b.dbc"
    dbc.write_text('VERSION ""\n')
    live = ["live", "--interface", "virtual", "--channel", "x", "--dbc", str(dbc)]
    for argv in (
        [*live, "--json-events", str(tmp_path / "s.json"), "-o", str(tmp_path / "s")],  # the result's PREFIX.json
        [*live, "--report", str(tmp_path / "r.html"), "--json-events", str(tmp_path / "r.html")],
        ["simulate", "--log", str(tmp_path / "a.mcap"), str(tmp_path / "a.mcap")],
        ["simulate", "--log", str(tmp_path / "a.mcap"), "--protocol", str(tmp_path / "a.mcap")],
    ):
        code, err = run(argv, capsys)
        assert code == 2 and "different paths" in err, (argv, err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.dbc"]


def test_aliases_of_an_input_are_the_input(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "sub").mkdir()
    triad, stops = tmp_path / "t.json", tmp_path / "s.csv"
    triad.write_text("{}")
    stops.write_text("x\n")
    os.link(triad, tmp_path / "hard.json")
    (tmp_path / "soft.json").symlink_to(triad)
    (tmp_path / "linkdir").symlink_to(tmp_path / "sub")
    before = snapshot(triad)
    for alias in (
        tmp_path / "hard.json",
        tmp_path / "soft.json",
        tmp_path / "sub" / ".." / "t.json",
        tmp_path / "linkdir" / ".." / "t.json",
        Path(os.path.relpath(triad)),
    ):
        code, err = run(["calibrate", str(stops), "--triad", str(triad), "-o", str(alias)], capsys)
        assert code == 2 and "never overwrites its input" in err, (alias, err)
    assert snapshot(triad) == before


def test_a_symlink_loop_in_an_output_s_folder_is_a_message(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "loop").symlink_to("loop")
    stops = tmp_path / "s.csv"
    stops.write_text("x\n")
    code, err = run(["calibrate", str(stops), "-o", str(tmp_path / "loop" / "r.json")], capsys)
    assert code == 2 and "a symlink loop" in err and "Traceback" not in err


# ------------------------------------------------------------------ lock files


@pytest.mark.parametrize("planted", ["symlink", "hard link", "fifo"])
def test_a_file_planted_as_the_lock_file_is_refused_and_its_target_kept(tmp_path: Path, planted: str) -> None:
    victim = tmp_path / "precious.txt"
    victim.write_text("keep me\n")
    out = tmp_path / "fleet.parquet"
    lock = tmp_path / ".fleet.parquet.lock"
    if planted == "symlink":
        lock.symlink_to(victim)
    elif planted == "hard link":
        os.link(victim, lock)
    else:
        os.mkfifo(lock)
    from mountcal.core.errors import InputError

    with pytest.raises(InputError, match=r"lock file.*(a symlink|a hard link|a FIFO)"), output_lock(out):
        pass
    assert victim.read_text() == "keep me\n"


def test_fleet_refuses_a_symlink_planted_as_its_lock_file(tmp_path: Path) -> None:
    victim = tmp_path / "precious.txt"
    victim.write_text("keep me\n")
    (tmp_path / ".f.parquet.lock").symlink_to(victim)
    stops = tmp_path / "logs"
    assert cli.main(["simulate", "-o", str(stops / "s.csv")]) == 0
    env = {**os.environ, "PYTHONPATH": str(REPO / "src")}
    done = subprocess.run(
        [sys.executable, "-m", "mountcal", "fleet", str(stops), "-o", str(tmp_path / "f.parquet"), "--workers", "1"],
        capture_output=True, text=True, env=env, timeout=300,
    )  # fmt: skip
    assert done.returncode == 2 and "a symlink" in done.stderr and "Traceback" not in done.stderr, done.stderr
    assert victim.read_text() == "keep me\n"


def test_the_lock_file_is_created_and_reused(tmp_path: Path) -> None:
    out = tmp_path / "f.parquet"
    for _ in range(2):
        with output_lock(out):
            lock = tmp_path / ".f.parquet.lock"
            assert lock.read_text() == f"{os.getpid()}\n" and stat.S_ISREG(os.lstat(lock).st_mode)
