"""Which stop table a result was fitted to: sums that identify it (:func:`fingerprint`), compared when a
result is applied or reported with its table (:func:`same_stops`)."""

from __future__ import annotations

import numpy as np

from mountcal.core.conventions import G_N
from mountcal.core.result import StopsFingerprint
from mountcal.io.input_conventions import Headings as Headings  # one definition, imported from here by many
from mountcal.stops.table import StopTable


def fingerprint(table: StopTable) -> StopsFingerprint:
    """Order-sensitive sums of the stop means and headings: they identify the table a result was
    fitted to. Not a file hash: a log's stop table never was a file, and CSV, Parquet or a
    rewrite of the same stops must match; :func:`same_stops` compares them to 1e-9 relative."""
    n = len(table)
    rank = np.arange(1, n + 1, dtype=float)[:, None] / max(n, 1)
    acc, ranked = table.acc_s.sum(axis=0), (rank * table.acc_s).sum(axis=0)
    return StopsFingerprint(
        n=n,
        acc_sum_mps2=(float(acc[0]), float(acc[1]), float(acc[2])),
        acc_ranked_sum_mps2=(float(ranked[0]), float(ranked[1]), float(ranked[2])),
        beta_ranked_sum_deg=None if table.beta_rad is None else float((rank[:, 0] * np.degrees(table.beta_rad)).sum()),
    )


def same_stops(stored: StopsFingerprint, table: StopTable) -> bool:
    """Whether ``table`` is the table of the :func:`fingerprint` ``stored`` (1e-9 relative)."""
    now = fingerprint(table)
    if stored.n != now.n or (stored.beta_ranked_sum_deg is None) != (now.beta_ranked_sum_deg is None):
        return False
    atol = 1e-9 * max(now.n, 1)
    beta_ok = (
        now.beta_ranked_sum_deg is None
        or stored.beta_ranked_sum_deg is None
        or abs(now.beta_ranked_sum_deg - stored.beta_ranked_sum_deg) <= 360.0 * atol
    )
    return beta_ok and all(
        np.allclose(stored_sum, now_sum, rtol=0, atol=G_N * atol)
        for stored_sum, now_sum in (
            (stored.acc_sum_mps2, now.acc_sum_mps2),
            (stored.acc_ranked_sum_mps2, now.acc_ranked_sum_mps2),
        )
    )


__all__ = ["fingerprint", "same_stops"]
