"""Shared test fixtures: where the real recordings live (a skip when they are absent), the schema check
of every calibration result a test writes, and the command line's refusal of bad input."""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

import pytest
from hypothesis import settings

# Property tests are deterministic: a CI failure can be reproduced, and no run passes by luck.
settings.register_profile("mountcal", derandomize=True, max_examples=60, deadline=None)
settings.load_profile("mountcal")

pytest_plugins = ["pytester"]  # a test runs a session with this conftest to check its schema fixture

REPO = Path(__file__).resolve().parents[1]
# beside the checkout, or where MOUNTCAL_REAL_DATA says (a worktree lives elsewhere)
REAL_DATA = Path(os.environ.get("MOUNTCAL_REAL_DATA", REPO / ".." / "shared" / "data" / "real")).resolve()


Refused = Callable[[list[str], Path], str]  # the type of the ``refused`` fixture


@pytest.fixture
def refused(capsys: pytest.CaptureFixture[str]) -> Refused:
    """Run the command line on ``argv`` expecting bad input refused: exit 2, a message and no traceback,
    no ``output`` written. Returns the message (stderr)."""
    from mountcal.cli import main

    def run(argv: list[str], output: Path) -> str:
        capsys.readouterr()
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert "Traceback" not in err and not output.exists()
        return err

    return run


@pytest.fixture(scope="session")
def result(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A calibration result made as a user makes one (``simulate``, then ``calibrate``); tests only read it.
    A module that needs another result defines its own ``result``."""
    from mountcal.cli import main

    folder = tmp_path_factory.mktemp("result")
    stops, path = folder / "s.csv", folder / "r.json"
    assert main(["simulate", "-q", "-o", str(stops)]) == 0
    assert main(["calibrate", "-q", str(stops), "-o", str(path)]) == 0
    return path


@pytest.fixture
def real_data() -> Path:
    """The folder of real recordings beside the checkout; the test is skipped where it is absent."""
    if not REAL_DATA.is_dir():
        pytest.skip(f"real recordings not found at {REAL_DATA}")
    return REAL_DATA


# --- every result a test writes follows the published schema ----------------------------------------

RESULT_FORMAT = '"mountcal.calibration"'
MAX_SCANNED_BYTES = 50 << 20  # a result is kilobytes; bigger JSON files are logs or data, not results


def schema_problems(paths: Iterable[Path]) -> list[str]:
    """The files among ``paths`` (and the JSON files under any folder among them) that are a mountcal
    calibration result not valid against the published schema, each with the first error."""
    import jsonschema

    from mountcal.core.result_file import schema

    validator = jsonschema.Draft202012Validator(schema())
    problems: list[str] = []
    for path in paths:
        for file in sorted(path.rglob("*.json")) if path.is_dir() else [path]:
            if not file.is_file() or file.stat().st_size > MAX_SCANNED_BYTES:
                continue
            text = file.read_text(encoding="utf-8", errors="replace")
            if RESULT_FORMAT not in text:
                continue
            try:
                doc = json.loads(text)
            except ValueError as err:
                problems.append(f"{file}: not JSON ({err})")
                continue
            if not isinstance(doc, dict) or doc.get("format") != "mountcal.calibration":
                continue
            error = jsonschema.exceptions.best_match(validator.iter_errors(doc))
            if error is not None:
                where = "/".join(map(str, error.absolute_path)) or "(top)"
                problems.append(f"{file}: {where}: {error.message}")
    return problems


@pytest.fixture
def result_files() -> list[Path]:
    """Paths (files or folders) whose calibration results are checked against the schema after the test,
    besides the test's ``tmp_path``: append to it."""
    return []


@pytest.fixture
def check_results() -> Callable[[Iterable[Path]], list[str]]:
    """The check the autouse fixture runs (for a test of the check itself)."""
    return schema_problems


@pytest.fixture(autouse=True)
def _results_follow_the_schema(request: pytest.FixtureRequest) -> Iterator[None]:
    """After each test, every calibration result it wrote under ``tmp_path`` (or registered in
    ``result_files``) must validate against the published JSON Schema.

    A test that writes invalid results on purpose (tampering) says so with
    ``@pytest.mark.invalid_results``.
    """
    # Taken before the test (the test uses them anyway): by its end they may be torn down.
    paths = [request.getfixturevalue("tmp_path")] if "tmp_path" in request.fixturenames else []
    registered: list[Path] = request.getfixturevalue("result_files") if "result_files" in request.fixturenames else []
    yield
    if request.node.get_closest_marker("invalid_results"):
        return
    paths += registered
    problems = schema_problems(paths)
    if problems:
        pytest.fail("results not valid against the published schema:\n" + "\n".join(problems), pytrace=False)


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "invalid_results: the test writes invalid results on purpose (not checked)")
