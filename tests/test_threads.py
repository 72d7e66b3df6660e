"""The rule for background threads: none in a process limited to one thread."""

from __future__ import annotations

import os

import pytest

from mountcal.core.threads import helpers_allowed


def test_no_helpers_in_a_one_thread_process(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    assert not helpers_allowed()


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="one core: never any helper")
@pytest.mark.parametrize("value", [None, "2", ""])
def test_helpers_on_several_cores(monkeypatch: pytest.MonkeyPatch, value: str | None) -> None:
    if value is None:
        monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    else:
        monkeypatch.setenv("OMP_NUM_THREADS", value)
    assert helpers_allowed()


def test_no_helpers_on_one_core(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0})
    assert not helpers_allowed()
