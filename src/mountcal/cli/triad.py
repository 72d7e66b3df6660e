"""``mountcal triad``: a triad calibration (bias, scale, cross-axis ± covariance) from a multi-position session.

The session's stops point gravity along many sensor directions; :mod:`mountcal.estimate.sphere`
fits all three terms. With ``--imucal CAL.json`` the values are imucal's (its Ferraris JSON) and
the covariance is mountcal's fit on the same session, after checking the two agree. The result
is what ``mountcal calibrate --triad`` applies. Imports are deferred: building the parser stays light.
"""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mountcal.cli.options import add_command, print_json
from mountcal.errors import InputError
from mountcal.terminal import safe

if TYPE_CHECKING:
    from mountcal.calibrate import Options
    from mountcal.conventions import FloatArray

TABLE_SUFFIXES = (".csv", ".parquet", ".pq")
MIN_STOPS = 6  # six parameters (bias, scale): the six faces, with each stop's noise given
log = logging.getLogger("mountcal")
AGREE_SIGMA = 5.0  # imucal's values within this many σ of mountcal's fit of the same session


def add_parser(subparsers: Any) -> None:
    p = add_command(
        subparsers,
        "triad",
        "fit bias, scale and cross-axis from a multi-position session",
        json_help="write the triad JSON on stdout as well",
        inputs=("LOG_OR_STOPTABLE", "the session's log(s), or its stop table"),
        output="triad JSON to write (for calibrate --triad)",
        output_required=True,
    )
    p.add_argument("--unit", choices=("mps2", "g"), default="mps2", help="unit of ax, ay, az in a stop table")
    p.add_argument("--gravity", type=float, default=None, help="local gravity in m/s² (default 9.80665)")
    p.add_argument("--imucal", default=None, help="imucal's Ferraris calibration JSON made from this session")
    p.add_argument("--min-stop-s", type=float, default=3.0, help="shortest still period in a log (s; hand-held: short)")
    p.add_argument("--trim-s", type=float, default=0.5, help="cut from each end of a still period in a log (s)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from mountcal.conventions import G_N
    from mountcal.estimate import sphere
    from mountcal.paths import check_outputs
    from mountcal.triad import from_sphere

    check_outputs({"-o": args.output}, {f"input {i + 1}": p for i, p in enumerate(args.input)})
    acc, cov = session_stops(args.input, args.unit, args.min_stop_s, args.trim_s)
    g = G_N if args.gravity is None else float(args.gravity)
    source = " + ".join(str(Path(p)) for p in args.input)
    for _, why in sphere.loop(acc, g, cov):
        log.info("  %s", why)
    fit = fit_all(acc, g, cov, source)
    triad = from_sphere(fit, source)
    if args.imucal is not None:
        triad = with_imucal_values(triad, args.imucal)
    for line in describe(triad, fit):
        log.info("%s", line)
    triad.save(args.output)
    log.info("wrote %s", safe(args.output))
    if args.json:
        print_json(json.loads(Path(args.output).read_text(encoding="utf-8")))
    return 0


def fit_all(acc: FloatArray, g: float, cov: FloatArray | None, where: str) -> Any:
    """The sphere fit of bias, scale and cross-axis together, or of bias and scale when the stops see no
    cross-axis (the six faces alone: the couplings then keep the sensor spec's limits); refused below that."""
    from dataclasses import replace

    for terms in (sphere_terms(), sphere_terms()[:2]):
        fit, loose = _fit(acc, g, cov, terms)
        if not loose:  # a χ² beyond its dof (stops less still, or a model short of the sensor) widens the σ
            return replace(fit, cov=fit.cov * max(1.0, fit.chi2 / fit.dof)) if fit.dof > 0 else fit
    raise InputError(
        where,
        f"stops that separate bias and scale (at least {MIN_STOPS} in different orientations)",
        f"{acc.shape[0]} stops leaving {', '.join(loose)} undetermined",
        _TODO_POSITIONS,
    )


def sphere_terms() -> tuple[str, ...]:
    from mountcal.estimate import sphere

    return sphere.TERMS


def _fit(acc: FloatArray, g: float, cov: FloatArray | None, terms: tuple[str, ...]) -> tuple[Any, list[str]]:
    import numpy as np

    from mountcal.estimate import sphere

    n_par = 3 * len(terms)
    if acc.shape[0] < n_par + (0 if cov is not None else 3):  # an estimated noise needs residual dof
        return None, [f"{n_par} parameters from {acc.shape[0]} stops"]
    fit = sphere.fit(acc, g, terms, cov)
    sig = fit.sigma()
    kinds = np.repeat(terms, 3)
    loose = [n for n, s, t in zip(fit.names, sig, kinds, strict=True) if not s <= sphere.PLAUSIBLE[t]]
    return fit, loose


_TODO_POSITIONS = (
    "Hold the sensor still in many orientations (at least the six faces and some in between), e.g. "
    "the six-position test of imucal or IMU-TK's hand-held session."
)


def session_stops(
    paths: list[str], unit: str, min_stop_s: float = 3.0, trim_s: float = 0.5
) -> tuple[FloatArray, FloatArray | None]:
    """Stop means (n, 3) in m/s² and their covariances, from a stop table or from logs."""
    import numpy as np

    from mountcal.stoptable import read_stop_table

    if len(paths) == 1 and Path(paths[0]).suffix.lower() in TABLE_SUFFIXES and not _is_sample_table(paths[0]):
        table = read_stop_table(paths[0], unit=unit, headings="none")  # type: ignore[arg-type]
        return table.acc_s, table.cov_s
    from mountcal.io.logs import LogOptions, read_log
    from mountcal.stops import StopDetection, detect_stops

    stops = detect_stops(read_log(paths, LogOptions()), StopDetection(min_duration_s=min_stop_s, trim_s=trim_s))
    if not stops:
        raise InputError(" + ".join(paths), "a session with still periods", "no stop", _TODO_POSITIONS)
    return np.array([s.acc_mean_s for s in stops]), np.array([s.acc_cov_mean_s for s in stops])


def _is_sample_table(path: str) -> bool:
    """A table of samples (``t_s, ax, ay, az``: a log) rather than of stops."""
    import pandas as pd
    import pyarrow.parquet as pq

    try:
        if Path(path).suffix.lower() == ".csv":
            columns = list(pd.read_csv(path, nrows=0).columns)
        else:
            columns = list(pq.read_schema(path).names)
    except (OSError, ValueError, UnicodeDecodeError):
        return False  # the stop-table reader names what is wrong
    return "t_s" in columns


def with_imucal_values(triad: Any, path: str) -> Any:
    """imucal's bias and (symmetric part of the) scale/cross-axis matrix, with mountcal's covariance of the session.

    imucal corrects ``a = R_a⁻¹ K_a⁻¹ (raw − b_a)``: raw = K_a R_a a + b_a. The left polar
    decomposition K_a R_a = P U leaves P = I + E (symmetric) and a rotation U that the mounting
    rotation absorbs.
    """
    import numpy as np
    from scipy.linalg import polar

    from mountcal.result_file import read_json
    from mountcal.triad import NAMES, Triad

    doc = read_json(Path(path))
    todo = "Pass the JSON imucal's FerrarisCalibrationInfo.to_json_file wrote (acc in m/s², acc_unit 'm/s^2')."
    try:
        ok = isinstance(doc, dict) and doc.get("cal_type") == "Ferraris" and doc.get("acc_unit") == "m/s^2"
        k_a, r_a, b_a = (np.asarray(doc[k], dtype=float) for k in ("K_a", "R_a", "b_a"))
        ok = ok and k_a.shape == (3, 3) and r_a.shape == (3, 3) and b_a.shape == (3,)
        ok = ok and bool(np.all(np.isfinite(k_a)) and np.all(np.isfinite(r_a)) and np.all(np.isfinite(b_a)))
    except (KeyError, TypeError, ValueError):
        ok = False
    if not ok:
        raise InputError(path, "an imucal Ferraris calibration JSON with K_a, R_a, b_a", "other content", todo)
    _, p = polar(k_a @ r_a, side="left")
    e = p - np.eye(3)
    values = np.concatenate([b_a, np.diag(e), [e[0, 1], e[0, 2], e[1, 2]]])
    ours = np.concatenate([triad.bias_mps2, triad.scale_e])
    fitted = [NAMES.index(n) for n in triad.fitted]  # the couplings, when the session cannot see them, keep the spec
    z = np.abs(values - ours)[fitted] / np.sqrt(np.diag(triad.cov)[fitted])
    if np.max(z) > AGREE_SIGMA:
        raise InputError(
            path,
            f"values within {AGREE_SIGMA:g}σ of this session's fit",
            f"a difference of {np.max(z):.1f}σ",
            "Pass the session the imucal calibration was made from (its covariance comes from that session), with "
            "the gravity imucal used (--gravity 9.81 is its default).",
        )
    return Triad(values[:3], values[3:], triad.cov, f"imucal {path} (covariance from {triad.source})", triad.fitted)


def describe(triad: Any, fit: Any) -> list[str]:
    import numpy as np

    from mountcal.triad import NAMES

    sig = np.sqrt(np.diag(triad.cov))
    values = np.concatenate([triad.bias_mps2, triad.scale_e])
    rms = float(np.sqrt(np.mean(fit.residual_mps2**2)))
    birge = np.sqrt(max(1.0, fit.chi2 / fit.dof)) if fit.dof > 0 else 1.0
    lines = [
        f"mountcal triad — {len(fit.residual_mps2)} stops, |a| residual RMS {rms:.4g} m/s², "
        f"χ² = {fit.chi2:.1f} on {fit.dof} dof (σ widened ×{birge:.2f})"
    ]
    lines += [
        f"  {n:<9} {v:+.5f} ± {s:.5f}" if n in triad.fitted else f"  {n:<9} not seen by these stops: the spec's limit"
        for n, v, s in zip(NAMES, values, sig, strict=True)
    ]
    if fit.dof == 0:
        lines.append("  note: as many stops as parameters: the values fit exactly and nothing checks the model")
    lines.append("  (bias in m/s², scale and cross-axis as fractions; 1σ)")
    return lines


def sensor_options(options: Options, spec: str | None, triad: str | None) -> Options:
    """``options`` with the sensor's limits (``--sensor-spec``) and triad calibration (``--triad``) read in."""
    from dataclasses import replace

    from mountcal.sensor_spec import read_spec
    from mountcal.triad import load

    if spec is not None:
        options = replace(options, spec=read_spec(spec))
    if triad is not None:
        options = replace(options, triad=load(triad))
    return options
