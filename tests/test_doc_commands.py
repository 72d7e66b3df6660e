"""Every ``mountcal`` command shown in README.md and docs/*.md runs, and shows what it prints.

What is collected, from the shell fences (```console, ```sh, ```bash, ```shell) of each page:

- in ```console, the ``$ …`` lines are commands and the lines after one are its output;
- in the others, every line that is not a comment is a command (a trailing ``\\`` joins the next);
- a line is split at ``&&``; a part is a mountcal command when it starts (after ``VAR=value``
  prefixes) with ``mountcal``, ``…/mountcal`` or ``python -m mountcal``. The other parts (set-up,
  benchmarks, pytest) are listed as such and not run here: benchmarks run for minutes and write the
  docs' figures (their commands are on the pages that hold those figures).

Markers, on the last non-blank line before a fence:

- ``<!-- not run: REASON -->``: its commands are exceptions, counted and listed (few, each with a reason);
- ``<!-- usage: … -->``: a synopsis; its commands and ``--options`` are checked against the parser;
- ``<!-- output -->``: the fence is the output of the page's last mountcal command before it;
- ``<!-- file: NAME -->``: the fence is a file the commands read (as is a ```toml fence whose first
  line is ``# NAME.toml``).

A page's commands run in order (later ones read what earlier ones wrote) through ``mountcal.cli.main``
in one folder per page holding a copy of ``data/`` and links to the real recordings (``../shared/data/real``
in a command means that folder). A command that reads the real recordings, or a file written by a
command that was skipped, is skipped with the reason where they are absent. A trailing comment
``# exits N`` states a documented non-zero exit code. Output lines are compared in order, each to a
printed line (stdout and stderr as one stream): ``…`` alone stands for any lines, ``…`` within a line
for any text, and a number matches to the last digit shown.

docs/exporters.md, docs/inputs.md and docs/field-logs.md need inputs that their own tests build
(a sensors_calibration.yaml, bags converted with rosbags, phone exports, a truck log written with
python-can) and are run there; here their collectors are checked to see the same commands.
"""

from __future__ import annotations

import argparse
import contextlib
import glob
import io
import os
import re
import shlex
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from mountcal.cli import build_parser, main

REPO = Path(__file__).resolve().parents[1]
REAL_DATA = Path(
    os.environ.get("MOUNTCAL_REAL_DATA", REPO / ".." / "shared" / "data" / "real")
).resolve()  # as conftest
PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
SHELLS = {"console", "sh", "bash", "shell"}
FENCE = re.compile(r"^(?P<indent>[ \t]*)```(?P<lang>[\w-]*)[ \t]*\n(?P<body>.*?)^(?P=indent)```[ \t]*$", re.M | re.S)
MARKER = re.compile(r"<!--\s*(?P<kind>not run|usage|output|file)\b:?\s*(?P<text>.*?)\s*-->")
EXIT = re.compile(r"#.*\bexits? (\d+)\b")
NUMBER = re.compile(r"[-+]?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")
ELLIPSIS = re.compile(r"…|\.\.\.")
REAL_FOLDERS = ("canedge", "comma2k19", "dbc", "imu_tk-xsens", "imucal-ferraris", "robot_localization")
OWNED = {  # pages whose commands need inputs their own test builds: page -> that test
    "exporters.md": "tests/test_exporters_docs.py",
    "inputs.md": "tests/io/test_inputs_doc.py",
    "field-logs.md": "tests/io/test_field_logs.py",
}
MAX_EXCEPTIONS = 5


@dataclass
class Command:
    page: Path
    line: int
    text: str  # the mountcal part, as written
    kind: str  # "run", "not run", "usage"
    reason: str = ""
    output: list[str] = field(default_factory=list)  # the lines the page shows it printing
    exit_code: int = 0

    @property
    def where(self) -> str:
        return f"{self.page.relative_to(REPO)}:{self.line}"


@dataclass
class Page:
    path: Path
    commands: list[Command] = field(default_factory=list)
    files: dict[str, str] = field(default_factory=dict)
    other: list[str] = field(default_factory=list)  # shell lines that are not mountcal commands
    variables: dict[str, str] = field(default_factory=dict)


def _marker(text: str, start: int) -> tuple[str, str] | None:
    before = text[:start].rstrip().rsplit("\n", 1)[-1].strip()
    m = MARKER.fullmatch(before)
    return (m["kind"], m["text"]) if m else None


def _mountcal_words(part: str) -> list[str] | None:
    """The arguments of a mountcal command (``None`` when the part runs something else)."""
    words = shlex.split(part, comments=True)
    while words and re.fullmatch(r"[A-Za-z_]\w*=\S*", words[0]):
        words = words[1:]
    if words and (words[0] == "mountcal" or words[0].endswith("/mountcal")):
        return words[1:]
    if len(words) >= 3 and re.fullmatch(r"(.*/)?python3?", words[0]) and words[1:3] == ["-m", "mountcal"]:
        return words[3:]
    return None


def _lines(body: str, lang: str) -> list[tuple[int, str, list[str]]]:
    """(offset in lines, command, output lines) of a shell fence."""
    rows = body.split("\n")
    found: list[tuple[int, str, list[str]]] = []
    k = 0
    while k < len(rows):
        row, start = rows[k], k
        if lang == "console":
            if not row.startswith("$ "):
                if found:
                    found[-1][2].append(row)
                k += 1
                continue
            row = row[2:]
        if not row.strip() or row.lstrip().startswith("#"):
            k += 1
            continue
        while row.rstrip().endswith("\\") and k + 1 < len(rows):
            k += 1
            row = row.rstrip()[:-1] + " " + rows[k].strip()
        found.append((start, row.strip(), []))
        k += 1
    return found


def collect(path: Path) -> Page:
    text = path.read_text(encoding="utf-8")
    page = Page(path)
    last: Command | None = None
    for fence in FENCE.finditer(text):
        marker = _marker(text, fence.start())
        indent, lang = fence["indent"], fence["lang"]
        body = "\n".join(line[len(indent) :] if line.startswith(indent) else line for line in fence["body"].split("\n"))
        first_line = text.count("\n", 0, fence.start()) + 2
        if marker and marker[0] == "file":
            page.files[marker[1]] = body
            continue
        if marker and marker[0] == "output":
            assert last is not None, f"{path.name}:{first_line}: an output block with no command before it"
            last.output = body.rstrip("\n").split("\n")
            continue
        if lang == "toml" and (name := re.match(r"# (\S+\.toml)\b", body)):
            page.files[name[1]] = body
            continue
        if lang not in SHELLS:
            continue
        if marker and marker[0] == "usage":  # a synopsis continues on indented lines
            body = re.sub(r"\n[ \t]+(?=\S)", " ", body)
        for offset, line, output in _lines(body, lang):
            assignment = re.fullmatch(r"([A-Za-z_]\w*)=(\S+)", line)
            if assignment:
                page.variables[assignment[1]] = assignment[2]
                continue
            for part in line.split("&&"):
                if _mountcal_words(part) is None:
                    page.other.append(part.strip())
                    continue
                kind = {"not run": "not run", "usage": "usage"}.get(marker[0] if marker else "", "run")
                exits = EXIT.search(part)
                last = Command(
                    path,
                    first_line + offset,
                    part.strip(),
                    kind,
                    marker[1] if marker and kind != "run" else "",
                    output,
                    int(exits[1]) if exits else 0,
                )
                page.commands.append(last)
    return page


COLLECTED = [collect(p) for p in PAGES]
RUN = [c for p in COLLECTED if p.path.name not in OWNED for c in p.commands if c.kind == "run"]


# --- comparing what a page shows with what the command prints ----------------------------------------


def _literal(text: str) -> str:
    words = text.split()
    if not words:
        return r"\s*"
    core = r"\s+".join(re.escape(w) for w in words)
    return (r"\s*" if text[0].isspace() else "") + core + (r"\s*" if text[-1].isspace() else "")


def _line_pattern(shown: str) -> tuple[re.Pattern[str], list[str]]:
    """A shown line as a pattern (``…`` any text, numbers captured, spaces loose) and its numbers."""
    pieces, numbers = [], []
    for k, chunk in enumerate(ELLIPSIS.split(shown.strip())):
        if k:
            pieces.append(".*?")
        for j, literal in enumerate(NUMBER.split(chunk)):
            if j:
                pieces.append(f"({NUMBER.pattern})")
            pieces.append(_literal(literal))
        numbers += NUMBER.findall(chunk)
    return re.compile("".join(pieces)), numbers


def _close(shown: str, printed: str) -> bool:
    """A shown number is the printed one to the last digit shown (half a unit, and float noise)."""
    mantissa, _, exponent = shown.lower().partition("e")
    decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
    unit = 10.0 ** (int(exponent or 0) - decimals)
    return abs(float(shown) - float(printed)) <= 0.5 * unit + 1e-9 * max(1.0, abs(float(shown)))


def _matches(shown: str, printed: str) -> bool:
    pattern, numbers = _line_pattern(shown)
    m = pattern.fullmatch(printed.strip())
    return m is not None and all(_close(s, p) for s, p in zip(numbers, m.groups(), strict=True))


def missing_lines(shown: list[str], printed: str) -> list[str]:
    """The shown lines that the printed text lacks, in order (``…`` alone: any lines may come between)."""
    lines = [line for line in printed.split("\n") if line.strip()]
    at, free, missing = 0, True, []
    for want in (s for s in shown if s.strip()):
        if want.strip() in ("…", "..."):
            free = True
            continue
        hit = next((k for k in range(at, len(lines)) if _matches(want, lines[k]) and (free or k == at)), None)
        if hit is None:
            missing.append(want)
            free = True  # the lines after a missing one are looked for on their own
            continue
        at, free = hit + 1, False
    return missing


# --- running a page ---------------------------------------------------------------------------------


@dataclass
class Outcome:
    code: int | None = None  # None: skipped
    printed: str = ""
    reason: str = ""
    seconds: float = 0.0


def _expand(words: list[str], variables: dict[str, str], cwd: Path) -> list[str]:
    out = []
    for word in words:
        for name, value in variables.items():
            word = word.replace(f"${{{name}}}", value).replace(f"${name}", value)
        word = word.replace("../shared/data/real", str(REAL_DATA))
        if any(ch in word for ch in "*?["):
            hits = sorted(glob.glob(word, root_dir=None if Path(word).is_absolute() else cwd))
            out.extend(hits or [word])
        else:
            out.append(word)
    return out


def _outputs(words: list[str]) -> list[str]:
    return [words[k + 1] for k, w in enumerate(words[:-1]) if w in ("-o", "--output", "--report", "--truth")]


class Runner:
    """Runs each page's commands in order, once, in a folder of its own."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.done: dict[str, list[Outcome]] = {}
        self.unmade: dict[str, set[str]] = {}  # per page: files that skipped commands would have written

    def outcome(self, command: Command) -> Outcome:
        page = next(p for p in COLLECTED if p.path == command.page)
        runnable = [c for c in page.commands if c.kind == "run"]
        results = self.done.setdefault(page.path.name, [])
        if not results:
            self._prepare(page)
        work = self.root / page.path.stem
        missing = self.unmade.setdefault(page.path.name, set())
        while len(results) <= runnable.index(command):
            c = runnable[len(results)]
            words = _expand(_mountcal_words(c.text) or [], page.variables, work)
            real = [w for w in words if w.split("/")[0] in REAL_FOLDERS or str(REAL_DATA) in w]
            unmade = sorted(set(words) & missing)
            if (real and not REAL_DATA.is_dir()) or unmade:
                why = (
                    f"needs the real recordings ({REAL_DATA})"
                    if real
                    else f"reads {unmade}, written by a skipped command"
                )
                missing.update(_outputs(words))
                results.append(Outcome(reason=why))
                continue
            out = io.StringIO()
            start = time.perf_counter()
            with contextlib.chdir(work), contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
                code = main(words)
            results.append(Outcome(code, out.getvalue(), seconds=time.perf_counter() - start))
        return results[runnable.index(command)]

    def _prepare(self, page: Page) -> None:
        work = self.root / page.path.stem
        work.mkdir()
        shutil.copytree(REPO / "data", work / "data")
        for name in REAL_FOLDERS:
            if (REAL_DATA / name).is_dir():
                (work / name).symlink_to(REAL_DATA / name)
        for name, body in page.files.items():
            (work / name).write_text(body, encoding="utf-8")


@pytest.fixture(scope="module")
def runner(tmp_path_factory: pytest.TempPathFactory) -> Runner:
    return Runner(tmp_path_factory.mktemp("doc-commands"))


@pytest.mark.parametrize("command", RUN, ids=[f"{c.where} {c.text[:60]}" for c in RUN])
def test_the_documented_command_runs_and_prints_what_the_page_shows(runner: Runner, command: Command) -> None:
    outcome = runner.outcome(command)
    if outcome.code is None:
        pytest.skip(f"{command.where}: {outcome.reason}")
    assert outcome.code == command.exit_code, (
        f"{command.where}: `{command.text}` exited {outcome.code}:\n{outcome.printed[-3000:]}"
    )
    missing = missing_lines(command.output, outcome.printed)
    assert not missing, f"{command.where}: `{command.text}` no longer prints {missing}; it printed:\n{outcome.printed}"


def test_the_exceptions_are_few_and_each_has_a_reason() -> None:
    exceptions = [c for p in COLLECTED for c in p.commands if c.kind == "not run"]
    listing = "\n".join(f"{c.where}: {c.text[:70]} — {c.reason}" for c in exceptions)
    print(f"{len(exceptions)} documented commands not run:\n{listing}")
    assert len(exceptions) <= MAX_EXCEPTIONS, listing
    assert all(len(c.reason) > 20 for c in exceptions), listing


def test_the_pages_show_enough_commands_to_be_collected() -> None:
    """The collector sees the commands: a change of fence or marker that hid them would fail here."""
    by_page = {p.path.name: p for p in COLLECTED}
    assert len([c for c in by_page["README.md"].commands if c.kind == "run"]) >= 8
    assert len([c for c in by_page["commands.md"].commands if c.kind == "run"]) >= 3
    assert sum(len(p.commands) for p in COLLECTED) >= 60
    assert any("benchmarks/" in line for p in COLLECTED for line in p.other)  # listed, not run


def test_the_synopses_and_the_commands_not_run_name_real_commands_and_options() -> None:
    """A synopsis (or a command not run here) names commands and options the parser has."""
    parser = build_parser()
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices
    options = {
        name: set(sub._option_string_actions) | set(parser._option_string_actions) for name, sub in commands.items()
    }
    checked = 0
    for command in (c for p in COLLECTED for c in p.commands if c.kind in ("usage", "not run")):
        words = _mountcal_words(command.text) or []
        name = next((w for w in words if not w.startswith(("[", "-"))), "")
        assert name == "COMMAND" or name in options, f"{command.where}: no command {name!r}"
        for option in re.findall(r"(?<![\w-])(--[a-z][\w-]*)", " ".join(words)):
            lacking = [n for n in (options if name == "COMMAND" else [name]) if option not in options[n]]
            assert not lacking, f"{command.where}: `mountcal {' '.join(lacking)}` has no {option}"
            checked += 1
    assert checked >= 40


@pytest.mark.parametrize("name", sorted(OWNED))
def test_pages_run_by_their_own_tests_are_collected_the_same_way(name: str) -> None:
    """The page's own test runs the commands this collector finds on it (none left out)."""
    page = next(p for p in COLLECTED if p.path.name == name)
    ours = [c.text.removeprefix("$ ") for c in page.commands if c.kind == "run"]
    test_file = REPO / OWNED[name]
    source = test_file.read_text(encoding="utf-8")
    assert f'"docs" / "{name}"' in source, f"{OWNED[name]} no longer reads docs/{name}"
    if name == "exporters.md":
        from tests.test_exporters_docs import documented_commands

        theirs = documented_commands(page.path.read_text(encoding="utf-8"))
    else:
        theirs = [
            "mountcal " + line.removeprefix("$ mountcal ")
            for line in page.path.read_text(encoding="utf-8").splitlines()
            if line.startswith("$ mountcal ")
        ]
    assert [shlex.split(c, comments=True) for c in theirs] == [shlex.split(c, comments=True) for c in ours]
    assert len(ours) >= 5


def test_the_output_comparison_can_fail() -> None:
    printed = (
        "mountcal — full method\n  roll   5.001° ± 0.599°\n  pitch  6.001° ± 0.594°\nmountcal: wrote result.json\n"
    )
    assert missing_lines(["  roll   5.001° ± 0.599°", "  pitch  6.001° ± 0.594°"], printed) == []
    assert missing_lines(["  roll 5.0° ± 0.6°"], printed) == []  # to the digits shown
    assert missing_lines(["  roll 5.01° ± 0.599°"], printed) == ["  roll 5.01° ± 0.599°"]
    assert missing_lines(["mountcal — full method", "  pitch 6.001° ± 0.594°"], printed) != []  # not consecutive
    assert missing_lines(["mountcal — full method", "…", "mountcal: wrote …"], printed) == []
    assert missing_lines(["  pitch 6.001° ± 0.594°", "  roll 5.001° ± 0.599°"], printed) != []  # order
