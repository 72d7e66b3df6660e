"""Pictures of a calibration: matplotlib figures for notebooks and a self-contained HTML report.

- :func:`render` — the HTML report of a result (figures inline, no external assets, no scripts).
- :mod:`mountcal.outputs.report.figures` — the figures, each a :class:`matplotlib.figure.Figure` made
  without pyplot (Agg/SVG rendering, no display): :func:`log_over_time`, :func:`stops_3d`,
  :func:`residual_vs_heading`, :func:`residual_trends`, :func:`uncertainty_vs_crb`, :func:`angles`,
  :func:`angles_over_time`.
- :func:`timeline_of` — the log over time (:class:`Timeline`) of ``calibrate_log``'s result, for
  ``render(..., timeline=)`` and :func:`log_over_time`.

Needs matplotlib (the ``report`` extra).
"""

from mountcal.outputs.report.figures import (
    angles,
    angles_over_time,
    log_over_time,
    residual_trends,
    residual_vs_heading,
    stops_3d,
    uncertainty_vs_crb,
)
from mountcal.outputs.report.html import render
from mountcal.outputs.report.timeline import Timeline, timeline_of

__all__ = [
    "Timeline",
    "angles",
    "angles_over_time",
    "log_over_time",
    "render",
    "residual_trends",
    "residual_vs_heading",
    "stops_3d",
    "timeline_of",
    "uncertainty_vs_crb",
]
