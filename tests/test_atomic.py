"""Atomic output: the target appears complete or not at all, with the usual permissions."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from mountcal import atomic
from mountcal.atomic import atomic_output, atomic_path


class Boom(Exception):
    pass


@pytest.fixture(params=["o_tmpfile", "renamed temporary"])
def how(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    if request.param == "renamed temporary":  # a file system without O_TMPFILE
        monkeypatch.delattr(atomic.os, "O_TMPFILE")
    return str(request.param)


def test_output_appears_whole_and_replaces_an_old_file(tmp_path: Path, how: str) -> None:
    target = tmp_path / "out" / "data.bin"
    with atomic_output(target) as f:
        f.write(b"first")
        assert not target.exists()  # nothing under the name while writing
    with atomic_output(target) as f:
        f.write(b"second")
    assert target.read_bytes() == b"second"
    assert sorted(p.name for p in target.parent.iterdir()) == ["data.bin"]  # no temporary left
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(target.stat().st_mode) == 0o666 & ~umask


def test_an_error_leaves_the_old_file_and_no_temporary(tmp_path: Path, how: str) -> None:
    target = tmp_path / "data.bin"
    target.write_bytes(b"old")
    with pytest.raises(Boom), atomic_output(target) as f:
        f.write(b"half")
        raise Boom
    assert target.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["data.bin"]


@pytest.mark.parametrize("durable", [True, False])
def test_atomic_path_renames_on_success_and_cleans_up_on_error(tmp_path: Path, durable: bool) -> None:
    target = tmp_path / "table.csv"
    with atomic_path(target, durable=durable) as tmp:
        tmp.write_text("a,b\n1,2\n")
        assert tmp.parent == tmp_path and tmp.name.startswith(".table.csv.") and not target.exists()
    assert target.read_text() == "a,b\n1,2\n"
    with pytest.raises(Boom), atomic_path(target, durable=durable) as tmp:
        tmp.write_text("broken")
        raise Boom
    assert target.read_text() == "a,b\n1,2\n"
    assert [p.name for p in tmp_path.iterdir()] == ["table.csv"]
