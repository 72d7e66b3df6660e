"""The notebooks as stored: clean, and guarded where they need the real recordings.

Running them top to bottom is nbmake's job: ``python -m pytest --nbmake notebooks/``.
"""

from __future__ import annotations

import re
from pathlib import Path

import nbformat
import pytest

NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"
EXPECTED = ("01_quick_start", "02_closing_the_loop_real_data", "03_drive_log", "04_fleet")
NEEDS_REAL_DATA = ("02_closing_the_loop_real_data", "03_drive_log")


def test_the_tutorial_notebooks_are_there() -> None:
    assert sorted(p.stem for p in NOTEBOOKS.glob("*.ipynb")) == sorted(EXPECTED)


@pytest.mark.parametrize("name", EXPECTED)
def test_notebook_is_stored_without_outputs(name: str) -> None:
    nb = nbformat.read(NOTEBOOKS / f"{name}.ipynb", as_version=4)
    nbformat.validate(nb)
    assert nb.metadata["kernelspec"]["name"] == "python3"
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert code, "a notebook without code teaches nothing"
    assert all(c.outputs == [] and c.execution_count is None for c in code), "clear the outputs before committing"
    assert not any(c.cell_type == "code" and "plt.show" in c.source for c in nb.cells)  # figures are Figure values


@pytest.mark.parametrize("name", NEEDS_REAL_DATA)
def test_real_data_notebooks_skip_where_the_recordings_are_absent(name: str) -> None:
    nb = nbformat.read(NOTEBOOKS / f"{name}.ipynb", as_version=4)
    sources = [c.source for c in nb.cells if c.cell_type == "code"]
    finder = next(i for i, s in enumerate(sources) if "REAL = find_real_data()" in s)
    assert "../../shared/data/real" in sources[finder] and "../shared/data/real" in sources[finder]
    using = [s for s in sources[finder + 1 :] if "REAL" in s or "CANEDGE" in s or "SEGMENT" in s]
    assert using, "the notebook should read the real recordings"
    for source in using:  # every cell that touches them is guarded
        assert "is None" in source or "is not None" in source or "if REAL" in source, source[:200]


@pytest.mark.parametrize("name", EXPECTED)
def test_notebook_uses_the_public_api_and_carries_no_work_markers(name: str) -> None:
    nb = nbformat.read(NOTEBOOKS / f"{name}.ipynb", as_version=4)
    assert not any("▶ ISSUE" in c.source for c in nb.cells), "a leftover work marker"
    code = "\n".join(c.source for c in nb.cells if c.cell_type == "code")
    modules = re.findall(r"^\s*(?:from|import)\s+(mountcal[\w.]*)", code, re.M)
    assert modules, "the notebook should use mountcal"
    for module in modules:  # no private module, no command-line internals
        assert not any(part.startswith("_") for part in module.split(".")) and not module.startswith("mountcal.cli")
    assert not re.search(r"\bmountcal\.\w*\._|\bmountcal\._", code)
