"""The two real multi-position sessions in ../shared/data/real, as mountcal inputs (for tests and benchmarks).

- IMU-TK's Xsens session (imu_tk-xsens/xsens_acc.mat, xsens_gyro.mat: "t x y z" raw counts, 100 Hz,
  hand-held in many static orientations): written as a sample table (``t_s, ax…, gx…``) that
  ``mountcal triad`` reads as a log and finds the stops of. Counts become m/s² by one nominal
  sensitivity (the median |counts − 32768| is taken as the test app's 9.81744 m/s²; the README
  says the initial scale is unknown) and the gyro by the test app's 1/6258 rad/s per count; what
  remains of bias, scale and cross-axis is the triad's to find.
- imucal's Ferraris session (imucal-ferraris/example_ferraris_session.csv, m/s², 102.4 Hz): the six
  static faces of its section list, one stop each (mean, sample spread, count).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

REAL = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "real"
XSENS = REAL / "imu_tk-xsens"
FERRARIS = REAL / "imucal-ferraris"
XSENS_G = 9.81744  # the IMU-TK test app's gravity
FACES = ("x_p", "x_a", "y_p", "y_a", "z_p", "z_a")


def xsens_samples(out: Path) -> Path:
    """The Xsens session as a sample table (Parquet) at ``out``."""
    acc = np.loadtxt(XSENS / "xsens_acc.mat")
    gyr = np.loadtxt(XSENS / "xsens_gyro.mat")
    counts = acc[:, 1:] - 32768.0
    per_g = float(np.median(np.linalg.norm(counts, axis=1)))
    frame = pd.DataFrame(counts * (XSENS_G / per_g), columns=["ax", "ay", "az"])
    frame.insert(0, "t_s", acc[:, 0])
    frame[["gx", "gy", "gz"]] = (gyr[:, 1:] - 32768.0) / 6258.0
    frame.to_parquet(out, index=False)
    return out


def ferraris_stops(out: Path) -> Path:
    """The six faces of imucal's session as a stop table (CSV) at ``out``."""
    data = pd.read_csv(FERRARIS / "example_ferraris_session.csv")
    regions = json.loads((FERRARIS / "example_ferraris_session_list.json").read_text(encoding="utf-8"))
    rows = []
    for face in FACES:
        part = data.loc[regions[face]["start"] : regions[face]["end"], ["acc_x", "acc_y", "acc_z"]].to_numpy()
        mean, sd = part.mean(axis=0), part.std(axis=0, ddof=1)
        rows.append(
            {"ax": mean[0], "ay": mean[1], "az": mean[2], "sx": sd[0], "sy": sd[1], "sz": sd[2], "n": len(part)}
        )
    pd.DataFrame(rows).to_csv(out, index=False, float_format="%.15g")
    return out


def imucal_json(out: Path) -> Path:
    """imucal's own FerrarisCalibration of the session, written by imucal (a test extra)."""
    from imucal import FerrarisCalibration, ferraris_regions_from_section_list

    data = pd.read_csv(FERRARIS / "example_ferraris_session.csv").set_index("n_samples")
    sections = pd.read_json(FERRARIS / "example_ferraris_session_list.json").T
    regions = ferraris_regions_from_section_list(data, sections)
    info = FerrarisCalibration().compute(regions, sampling_rate_hz=102.4, from_acc_unit="m/s^2", from_gyr_unit="deg/s")
    info.to_json_file(out)
    return out
