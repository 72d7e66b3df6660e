"""Shared test fixtures: where the real recordings live, and a skip when they are absent."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import settings

# Property tests are deterministic: a CI failure can be reproduced, and no run passes by luck.
settings.register_profile("mountcal", derandomize=True, max_examples=60, deadline=None)
settings.load_profile("mountcal")

REPO = Path(__file__).resolve().parents[1]
# MOUNTCAL_REAL_DATA points elsewhere (a worktree not beside ../shared)
REAL_DATA = Path(os.environ.get("MOUNTCAL_REAL_DATA", REPO / ".." / "shared" / "data" / "real")).resolve()


@pytest.fixture
def real_data() -> Path:
    """The folder of real recordings beside the checkout; the test is skipped where it is absent."""
    if not REAL_DATA.is_dir():
        pytest.skip(f"real recordings not found at {REAL_DATA}")
    return REAL_DATA
