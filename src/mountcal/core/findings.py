"""A residual test's finding: what it looks for, how big the structure is, and how improbable (in a
result's ``fit.findings``, the driving fit's consistency and the loop's model choice)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from mountcal.core.typed_json import to_plain

STRUCTURE_P = 1e-3  # a residual structure (or a fit χ²) this improbable under the model counts as unexplained


@dataclass(frozen=True)
class Finding:
    """One residual test: what it looks for, how big the structure is, and how improbable."""

    test: str
    what: str
    size: str
    statistic: float | None  # None (with ``reason``) when the test does not exist for these data
    dof: int | None  # None for a test that is no χ²-type statistic (a z-score against ``z_limit``)
    p_value: float | None
    log10_p: float | None
    reason: str | None = None
    z_limit: float | None = None  # a z-score test: beyond this many σ counts as structure

    @property
    def significant(self) -> bool:
        return self.p_value is not None and self.p_value < STRUCTURE_P

    def to_dict(self) -> dict[str, Any]:
        return dict(to_plain(self))


__all__ = ["STRUCTURE_P", "Finding"]
