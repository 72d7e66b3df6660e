"""What one log's calibration needs: the files and every setting (:class:`LogJob`).

Apart from :mod:`mountcal.calibration.pipeline`, which runs it: the fleet command builds and hashes
thousands of jobs and never fits one itself, so it does not import the fit and the estimators.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from mountcal.calibration.options import BASE, DEFAULT_USE, Options, Use, check_use
from mountcal.core.errors import InputError
from mountcal.core.option_names import option
from mountcal.estimate.driving_options import DrivingOptions
from mountcal.io.reader import LogOptions
from mountcal.stops.detect import StopDetection


@dataclass(frozen=True)
class LogJob:
    """Everything needed to calibrate one log (one file or several splits).

    ``use`` is ``"auto"`` (whatever the log supports), ``"stops"`` or ``"driving"`` (insist on one
    source; fail with the reason when the log does not support it); ``driving`` holds the gates of
    yaw from driving.
    """

    paths: tuple[str, ...]
    log: LogOptions = field(default_factory=LogOptions)
    detection: StopDetection = field(default_factory=StopDetection)
    protocol: str | None = None
    uphill_azimuth_deg: float | None = None
    options: Options = field(default_factory=Options)
    use: Use = DEFAULT_USE
    driving: DrivingOptions | None = None

    def __post_init__(self) -> None:
        """``use`` checked once, here, and against the model: driving estimates the rotation only, so a
        model naming an effect (``bias``, …) is refused with ``use="driving"`` (with ``"auto"``, a
        result from driving alone says the model was not applied: :func:`_driving_alone`)."""
        check_use(self.use)
        beyond = not_from_driving(self.options)
        if self.use == "driving" and beyond:
            raise InputError(
                f"{option('model', self.options.model)} with {option('use', 'driving')}",
                "a model that driving estimates: auto or rotation,slope (driving measures the rotation only)",
                f"the term(s) {', '.join(beyond)}, which only parked stops measure",
                f"Calibrate from parked stops ({option('use', 'stops')} or auto), or drop {', '.join(beyond)} "
                f"from {option('model')}.",
            )


def not_from_driving(options: Options) -> tuple[str, ...]:
    """The terms of ``options.model`` beyond the base ones: none of them is estimated from driving."""
    return () if options.terms is None else tuple(t for t in options.terms if t not in BASE)
