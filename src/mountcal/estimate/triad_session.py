"""The still periods of a triad session: one home for the defaults of ``mountcal triad --min-stop-s/--trim-s``
and of :func:`mountcal.estimate.triad.session_stops` (issue 24).

A pose held by hand lasts seconds and settles quickly, unlike a parked vehicle's stop (whose defaults are
:class:`~mountcal.stops.detect.StopDetection`'s). Light (no numerical library at import): the CLI builds its
parser with it.
"""

from __future__ import annotations

MIN_STOP_S = 3.0  # shortest still period in a log (s)
TRIM_S = 0.5  # cut from each end of a still period (s)

__all__ = ["MIN_STOP_S", "TRIM_S"]
