"""Every command that reads headings takes the option that states their unit.

A protocol sheet's ``beta_deg`` (or a heading signal) in radians is refused naming ``--heading-unit rad``
(:func:`mountcal.stops.headings.headings_in_degrees`). ``mountcal live`` read its ``--plan`` sheet and its bus's
heading signal with that check but had no ``--heading-unit``: the refusal named an option the command then
refused as unrecognised, and a plan in radians could not be used at all. The option is declared once
(:func:`mountcal.cli.options.add_heading_unit_option`), and this walk keeps a new command from missing it.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pytest

from mountcal.cli import build_parser, main
from mountcal.cli.path_options import declared
from mountcal.core.errors import NotEnoughInformation

DBC = str(Path(__file__).resolve().parents[1] / "data" / "imu_mm5_10.dbc")


def _commands() -> list[tuple[str, argparse.ArgumentParser]]:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return list(sub.choices.items())


def _reads_headings(p: argparse.ArgumentParser) -> list[str]:
    """The options through which ``p``'s command reads headings: a protocol sheet, a heading signal's azimuth."""
    found = []
    for action in p._actions:
        spec = declared(action)
        if spec is not None and spec.role == "input" and spec.what == "a protocol sheet":
            found.append(action.option_strings[0])
        if "--uphill-azimuth-deg" in action.option_strings:
            found.append("--uphill-azimuth-deg")
    return found


def test_every_command_reading_headings_takes_heading_unit() -> None:
    missing = {}
    for name, p in _commands():
        reads = _reads_headings(p)
        flags = {f for a in p._actions for f in a.option_strings}
        if reads and "--heading-unit" not in flags:
            missing[name] = reads
    assert "live" in {n for n, p in _commands() if _reads_headings(p)}  # the walk sees live's --plan
    assert missing == {}


@pytest.fixture
def plan_in_radians(tmp_path: Path) -> Path:
    path = tmp_path / "plan.csv"
    beta = np.radians(np.arange(0.0, 360.0, 30.0))
    rows = [f"{60 * i},{60 * i + 40},{b:.17g}" for i, b in enumerate(beta)]
    path.write_text("t_start_s,t_end_s,beta_deg\n" + "\n".join(rows) + "\n", encoding="utf-8")
    return path


def _live(channel: str, prefix: Path, *extra: str) -> list[str]:
    return ["live", "--interface", "virtual", "--channel", channel, "--dbc", DBC, "--timeout", "0.3",
            "-o", str(prefix), *extra]  # fmt: skip


def test_live_refuses_a_plan_in_radians_naming_an_option_it_takes(
    plan_in_radians: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(_live("rad1", tmp_path / "s", "--plan", str(plan_in_radians)))
    err = capsys.readouterr().err
    assert code == 2 and "--heading-unit rad" in err
    # the option the refusal names is taken: the plan is read in radians and the session runs (to a silent bus)
    code = main(_live("rad2", tmp_path / "t", "--plan", str(plan_in_radians), "--heading-unit", "rad"))
    err = capsys.readouterr().err
    assert code == NotEnoughInformation.exit_code, err
    assert "bus silent" in err and "radians" not in err
