"""How a message names an option: the Python parameter for a library user, the flag for a CLI user.

Library messages (errors, notes, status lines) say :func:`option` ``("protocol")`` instead of
spelling a flag: a Python caller of ``calibrate_log`` reads ``protocol=``, and the CLI, which runs
its commands inside :func:`as_flags`, makes the same message read ``--protocol``. :data:`OPTIONS`
is the one table of both spellings; a test keeps every flag in it equal to the parsers.
Imports nothing numerical (the CLI's parser imports this module).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar

# key -> (Python spelling, CLI flag). A nested parameter is spelled with its options class.
OPTIONS: dict[str, tuple[str, str]] = {
    "accept_unconfident": ("accept_unconfident", "--accept-unconfident"),
    "allow_truncated": ("LogOptions.allow_truncated", "--allow-truncated"),
    "axes": ("LogOptions.axes", "--axes"),
    "child": ("Frames.child", "--child"),
    "chunk": ("chunk_samples", "--chunk"),
    "columns": ("LogOptions.columns", "--columns"),
    "dbc": ("LogOptions.dbc", "--dbc"),
    "field": ("LogOptions.field", "--field"),
    "figures": ("image_format", "--figures"),
    "format": ("fmt", "--format"),
    "gravity": ("Options.gravity_mps2", "--gravity"),
    "heading_unit": ("heading_unit", "--heading-unit"),
    "headings": ("headings", "--headings"),
    "level_only": ("level_only", "--level-only"),
    "mapping": ("LogOptions.mapping", "--mapping"),
    "max_acc_std": ("StopDetection.max_acc_std_mps2", "--max-acc-std"),
    "max_gyro_rate": ("StopDetection.max_gyro_rad_s", "--max-gyro-rate"),
    "max_gyro_std": ("StopDetection.max_gyro_std_rad_s", "--max-gyro-std"),
    "max_heading_wander": ("StopDetection.max_heading_wander_deg", "--max-heading-wander"),
    "max_speed": ("StopDetection.max_speed_mps", "--max-speed"),
    "max_yaw_sigma": ("Options.max_yaw_sigma_deg", "--max-yaw-sigma"),
    "method": ("Options.method", "--method"),
    "use": ("use", "--use"),
    "min_stop": ("StopDetection.min_duration_s", "--min-stop-s"),
    "model": ("Options.model", "--model"),
    "output": ("output", "-o"),
    "noise": ("Noise.sample_sigma_mps2", "--noise"),
    "parent": ("Frames.parent", "--parent"),
    "parent_pose": ("Frames.parent_pose", "--parent-pose"),
    "protocol": ("protocol", "--protocol"),
    "require_confident": ("require_confident", "--require-confident"),
    "sensor_spec": ("Options.spec", "--sensor-spec"),
    "slope_reference": ("Options.slope_reference", "--slope-reference"),
    "still_window": ("StopDetection.window_s", "--still-window-s"),
    "stops": ("table", "--stops"),
    "timeline": ("timeline", "--report"),
    "topic": ("LogOptions.topic", "--topic"),
    "triad": ("Options.triad", "--triad"),
    "trim": ("StopDetection.trim_s", "--trim-s"),
    "unit": ("unit", "--unit"),
    "uphill_azimuth": ("uphill_azimuth_deg", "--uphill-azimuth-deg"),
    "yaw_undetermined": ("yaw", "--yaw-undetermined"),
    "workers": ("FleetOptions.workers", "--workers"),
    "scheduler": ("FleetOptions.scheduler", "--scheduler"),
}

_FLAGS: ContextVar[bool] = ContextVar("mountcal_option_flags", default=False)


def option(key: str, value: str | float | bool | None = None) -> str:
    """The option ``key`` of :data:`OPTIONS` (with ``value``, if given) as the reader will type it.

    ``option("unit", "g")`` is ``unit='g'`` in Python and ``--unit g`` on the command line;
    ``option("level_only", True)`` is ``level_only=True`` and ``--level-only``.
    """
    python, flag = OPTIONS[key]
    if _FLAGS.get():
        return flag if value is None or value is True else f"{flag} {value}"
    return f"{python}=" if value is None else f"{python}={value!r}"


def flags_on() -> bool:
    """Whether :func:`option` spells flags here (the fleet passes it on to its worker processes)."""
    return _FLAGS.get()


@contextmanager
def as_flags() -> Iterator[None]:
    """Within this block, :func:`option` spells options as the CLI's flags."""
    token = _FLAGS.set(True)
    try:
        yield
    finally:
        _FLAGS.reset(token)


__all__ = ["OPTIONS", "as_flags", "flags_on", "option"]
