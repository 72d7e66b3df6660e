"""The README reads in two minutes and links every page; the Python tour (docs/python.md) runs as written."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def test_the_readme_is_short_and_links_the_docs_a_user_needs() -> None:
    text = (REPO / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 130
    linked = set(re.findall(r"\]\((docs/[\w.-]+\.md)", text))
    assert all((REPO / page).is_file() for page in linked), linked
    # the pages a user reads are in the README's table; the rest (generated figures, per-format speeds, a
    # generated analysis) are linked or named (as a benchmark's output) on one of those
    pages = {f"docs/{p.name}" for p in (REPO / "docs").glob("*.md")}
    reached = set(linked)
    for page in linked:
        reached |= {f"docs/{n}" for n in re.findall(r"([\w-]+\.md)\b", (REPO / page).read_text(encoding="utf-8"))}
    assert pages <= reached, sorted(pages - reached)
    assert {p for p in pages if not re.search(r"-results\.md$|^docs/performance-|^docs/real-data-car", p)} <= linked
    # the two quick-start commands: one sets up and runs the sample, one sets up and runs the tests (.ci/run)
    for marker, tail in (("quickstart-demo", "mountcal calibrate data/parking.mcap"), ("quickstart-tests", "pytest")):
        block = re.search(rf"<!-- {marker} -->\n```sh\n(.*?)\n```", text, re.S)
        assert block is not None and "\n" not in block[1] and "pip install" in block[1] and tail in block[1], marker


def test_the_python_tour_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    text = (REPO / "docs" / "python.md").read_text(encoding="utf-8")
    block = re.search(r"<!-- readme-python[^>]*-->\n```python\n(.*?)```", text, re.S)
    assert block is not None, "docs/python.md has no marked Python section"
    code = block.group(1)
    for name in re.findall(r'"(data/[^"]+)"', code):  # the sample data it reads, copied beside its output
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_bytes((REPO / name).read_bytes())
    monkeypatch.chdir(tmp_path)
    namespace: dict[str, object] = {}
    exec(compile(code, "docs/python.md", "exec"), namespace)
    cal, done = namespace["cal"], namespace["done"]
    assert abs(cal.roll_deg - 5.0) < 0.1 and abs(done.calibration.yaw_deg - 7.0) < 0.2  # type: ignore[attr-defined]
    assert len(namespace["df_v"]) == len(namespace["acc_v"]) > 0  # type: ignore[arg-type]
    assert os.path.getsize(tmp_path / "result.json") > 0


def test_the_quick_start_prints_the_answer_first(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The quick start's command, run as written: its first line of output is the answer, as the README shows."""
    from mountcal.cli import main

    text = (REPO / "README.md").read_text(encoding="utf-8")
    demo = re.search(r"<!-- quickstart-demo -->\n```sh\n(.*?)\n```", text, re.S)
    assert demo is not None, "the README has no marked quick-start command"
    argv = demo.group(1).split("bin/mountcal ", 1)[1].split()
    blocks = re.finditer(r"(?ms)^```(\w*)\n(.*?)^```", text[demo.end() :])
    shown = next(b.group(2).splitlines() for b in blocks if b.group(1) in ("", "text"))  # its output, shown
    assert argv[0] == "calibrate"
    for name in argv:
        if name.startswith("data/"):
            (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
            (tmp_path / name).write_bytes((REPO / name).read_bytes())
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 0
    out, err = capsys.readouterr()
    assert out == ""  # the result went to -o's file; the summary to stderr
    first = err.splitlines()[0]
    assert first == shown[0]
    assert re.fullmatch(
        r"roll 5\.\d{3} ± 0\.\d{3}°  pitch 6\.\d{3} ± .*  yaw 6\.9\d{2} ± .*  slope .*  confident", first
    )
