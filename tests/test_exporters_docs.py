"""docs/exporters.md: every command in it runs, and its sample outputs are what the commands print.

The sample outputs are not pasted: the block after each ``<!-- output of: COMMAND -->`` is compared with
what COMMAND prints now (numbers to 1e-7, relative or absolute, so that the last digit of a float may differ
between platforms; all other text exactly). ``MOUNTCAL_UPDATE_DOCS=1`` rewrites those blocks from the
commands. Files the commands read are in the page too, each in the block after ``<!-- file: NAME -->``.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import shlex
import shutil
from pathlib import Path

import pytest

from mountcal.cli import main

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "exporters.md"
OUTPUT_BLOCK = re.compile(r"(<!-- output of: (?P<cmd>.+?) -->\n```text\n)(?P<body>.*?)(```)", re.S)
FORMATS_BLOCK = re.compile(r"(<!-- formats: generated -->\n)(?P<body>.*?)(\n<!-- end of formats -->)", re.S)
FILE_BLOCK = re.compile(r"<!-- file: (?P<name>\S+) -->\n```\w*\n(?P<body>.*?)```", re.S)
NUMBER = re.compile(r"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")


def argv(command: str) -> list[str]:
    """A documented command line as mountcal's arguments (``mountcal …`` or ``python -m mountcal …``)."""
    words = shlex.split(command, comments=True)
    for prefix in (["mountcal"], ["python", "-m", "mountcal"]):
        if words[: len(prefix)] == prefix:
            return words[len(prefix) :]
    raise AssertionError(f"docs/exporters.md: not a mountcal command: {command!r}")


def documented_commands(text: str) -> list[str]:
    blocks = re.findall(r"```sh\n(.*?)```", text, re.S)
    return [line for block in blocks for line in block.splitlines() if shlex.split(line, comments=True)]


def run(command: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv(command))
    return code, out.getvalue(), err.getvalue()


def same_text(documented: str, printed: str) -> bool:
    """Equal text, with numbers equal to 1e-7 (the last digits of a float are not the text's meaning)."""
    if NUMBER.sub("#", documented) != NUMBER.sub("#", printed):
        return False
    for a, b in zip(NUMBER.findall(documented), NUMBER.findall(printed), strict=True):
        x, y = float(a), float(b)
        if abs(x - y) > 1e-7 * max(1.0, abs(x), abs(y)):
            return False
    return True


@pytest.fixture(scope="module")
def page(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, dict[str, tuple[int, str, str]]]:
    """The page, and what each of its commands returned, run in order in a fresh folder with the sample data."""
    text = DOC.read_text(encoding="utf-8")
    work = tmp_path_factory.mktemp("exporters-doc")
    (work / "data").mkdir()
    for name in ("parking.mcap", "parking_protocol.csv"):
        shutil.copy(REPO / "data" / name, work / "data" / name)
    for match in FILE_BLOCK.finditer(text):
        (work / match["name"]).write_text(match["body"], encoding="utf-8")
    results: dict[str, tuple[int, str, str]] = {}
    with contextlib.chdir(work):
        for command in documented_commands(text):
            results[command] = run(command)
        for match in OUTPUT_BLOCK.finditer(text):
            if match["cmd"] not in results:
                results[match["cmd"]] = run(match["cmd"])
    return text, results


def test_every_command_of_the_page_runs(page: tuple[str, dict[str, tuple[int, str, str]]]) -> None:
    text, results = page
    commands = documented_commands(text)
    assert len(commands) >= 10 and any("--parent-pose" in c for c in commands)
    failed = {c: err for c, (code, _, err) in results.items() if c in commands and code != 0}
    assert not failed, failed


def test_sample_outputs_are_what_the_commands_print(page: tuple[str, dict[str, tuple[int, str, str]]]) -> None:
    text, results = page
    blocks = list(OUTPUT_BLOCK.finditer(text))
    shown = {args[args.index("--to") + 1] for args in (argv(m["cmd"]) for m in blocks)}
    assert {"ublox", "novatel", "ros2-static-tf", "autoware"} <= shown
    if os.environ.get("MOUNTCAL_UPDATE_DOCS") == "1":
        updated = OUTPUT_BLOCK.sub(lambda m: m.group(1) + results[m["cmd"]][1] + m.group(4), text)
        DOC.write_text(updated, encoding="utf-8")
        text = updated
    stale = [m["cmd"] for m in OUTPUT_BLOCK.finditer(text) if not same_text(m["body"], results[m["cmd"]][1])]
    assert not stale, f"docs/exporters.md shows what these no longer print (MOUNTCAL_UPDATE_DOCS=1 rewrites): {stale}"


def test_the_table_of_formats_is_the_registry_s() -> None:
    """The formats, their suffixes and descriptions on the page are made from the exporters' declarations."""
    from mountcal.outputs.exporters import markdown_table

    text = DOC.read_text(encoding="utf-8")
    match = FORMATS_BLOCK.search(text)
    assert match, "docs/exporters.md: no <!-- formats: generated --> block"
    if os.environ.get("MOUNTCAL_UPDATE_DOCS") == "1":
        text = FORMATS_BLOCK.sub(lambda m: m.group(1) + markdown_table() + m.group(3), text)
        DOC.write_text(text, encoding="utf-8")
        match = FORMATS_BLOCK.search(text)
        assert match
    assert match["body"] == markdown_table(), (
        "docs/exporters.md: the table of formats (MOUNTCAL_UPDATE_DOCS=1 rewrites)"
    )
