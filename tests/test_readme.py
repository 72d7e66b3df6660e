"""The README's Python section runs as written, from the repository root."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def test_the_readme_python_section_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    text = (REPO / "README.md").read_text(encoding="utf-8")
    block = re.search(r"<!-- readme-python[^>]*-->\n```python\n(.*?)```", text, re.S)
    assert block is not None, "the README has no marked Python section"
    code = block.group(1)
    for name in re.findall(r'"(data/[^"]+)"', code):  # the sample data it reads, copied beside its output
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_bytes((REPO / name).read_bytes())
    monkeypatch.chdir(tmp_path)
    namespace: dict[str, object] = {}
    exec(compile(code, "README.md", "exec"), namespace)
    cal, done = namespace["cal"], namespace["done"]
    assert abs(cal.roll_deg - 5.0) < 0.1 and abs(done.calibration.yaw_deg - 7.0) < 0.2  # type: ignore[attr-defined]
    assert len(namespace["df_v"]) == len(namespace["acc_v"]) > 0  # type: ignore[arg-type]
    assert os.path.getsize(tmp_path / "result.json") > 0
