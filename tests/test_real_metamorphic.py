"""Metamorphic relations on the real recordings: a copy of the data with one convention changed.

Each real recording mountcal answers (the comma2k19 RAV4 minute and CANedge drive 165 with ``calibrate``; the
robot_localization bag and its ROS 2 MCAP with ``rotate``; imucal's Ferraris session with ``triad``) is copied
into ``tmp_path`` with one convention changed — the axes permuted or mirrored, the accelerations in g, the speed
in km/h, the heading in radians or counter-clockwise, the time in ms, the gyro in deg/s, the data exported to CSV
and Parquet, a file under another suffix — and run through the command line again. Not covered: the CANedge boat
and desk logs, which ``calibrate`` refuses (one orientation, no drive), and the IMU-TK session (MATLAB files,
not a format mountcal reads).

- **Stated** (the copy says what changed: ``--axes``, ``--unit g``, a column map's unit, ``--heading-unit``,
  a suffix that names the content): the answer is the same — every angle within a tenth of its σ, the same
  confident flag.
- **Not stated**: refused, the message naming the fix; or the same answer with the convention inferred and said;
  or, where the docs say the data cannot tell, not confident with the reason. Never a confident different answer,
  never a file written from a misread log.

The originals in ../shared/data/real are only read. (~20 s on an idle machine: the shortest recordings; drive 165
is read from its MF4 splits once and exported to Parquet for the copies.)
"""

from __future__ import annotations

import contextlib
import io
import json
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from tests.conftest import REAL_DATA

from mountcal.cli import main
from mountcal.io.logs import read_log
from mountcal.io.reader import LogOptions
from mountcal.io.samples import Samples

pytestmark = pytest.mark.real_data

COMMA = "comma2k19/rav4_2018-08-02--08-34-47_seg40"
CAR = "canedge/3BA199E2_car_DK_2021-07-26/00000165"
DBC = "canedge/dbc/gnss.dbc"
ROBOT_BAG = "robot_localization/test1.bag"
ROBOT_MCAP = "robot_localization/test1_ros2_mcap/test1_ros2_mcap.mcap"
G_N = 9.80665
FRACTION = 0.1  # of σ: how far a stated change may move an angle (they move by rounding only)
ANGLES = ("roll", "pitch", "yaw")
ACC, GYRO = ["ax", "ay", "az"], ["gx", "gy", "gz"]
AXES_RIGHT = ["--axes", "x,y,z"]  # states that a table's axes are right-handed as logged


def table(samples: Samples) -> pd.DataFrame:
    """A sample table of everything ``samples`` hold, as pandas writes one: the IMU's rows and each channel's rows
    at its own times (the other columns empty), in time order — nothing resampled."""
    imu = pd.DataFrame({"t_s": samples.t_s, **dict(zip(ACC, samples.acc_s.T, strict=True))})
    if samples.gyro_s is not None:
        imu = imu.assign(**dict(zip(GYRO, samples.gyro_s.T, strict=True)))
    parts = [imu, *(pd.DataFrame({"t_s": ch.t_s, name: ch.value}) for name, ch in samples.channels.items())]
    return pd.concat(parts, ignore_index=True).sort_values("t_s", kind="stable").reset_index(drop=True)


def write(df: pd.DataFrame, path: Path) -> Path:
    if path.suffix == ".csv":
        df.to_csv(path, index=False)
    else:
        df.to_parquet(path)
    return path


class Run:
    """One ``mountcal calibrate`` on the command line: its exit code, stderr and result."""

    def __init__(self, argv: list[str], out: Path) -> None:
        err = io.StringIO()
        with contextlib.redirect_stderr(err):
            self.code = main(["calibrate", *[str(a) for a in argv], "-o", str(out)])
        self.err = err.getvalue()
        assert "Traceback" not in self.err
        self.result = json.loads(out.read_text()) if self.code == 0 else None
        assert (self.code == 0) == out.exists(), "a refusal must not leave a result behind"

    @property
    def confident(self) -> bool:
        assert self.result is not None, self.err
        return bool(self.result["confident"])

    def angle(self, name: str) -> tuple[float | None, float | None]:
        assert self.result is not None, self.err
        return self.result["mounting"][f"{name}_deg"], self.result["uncertainty"][f"{name}_deg"]

    def check(self, name: str) -> dict[str, object] | None:
        assert self.result is not None, self.err
        return next((c for c in self.result["checks"] if c["name"] == name), None)


Calibrate = Callable[[list[object], str], Run]


@pytest.fixture
def calibrate(real_data: Path, tmp_path: Path) -> Calibrate:
    """``mountcal calibrate`` on the arguments, its result written in ``tmp_path`` (skipped without the recordings)."""

    def run(argv: list[object], name: str) -> Run:
        return Run([str(a) for a in argv], tmp_path / f"{name}.json")

    return run


def _real() -> Path:
    """The recordings, for the module's fixtures (``real_data`` is per test): skipped where they are absent."""
    if not REAL_DATA.is_dir():
        pytest.skip(f"real recordings not found at {REAL_DATA}")
    return REAL_DATA


def same_answer(run: Run, base: Run) -> None:
    """Every angle within a fraction of its σ of the original's (or undetermined in both), the same flag."""
    for name in ANGLES:
        (value, sigma), (was, was_sigma) = run.angle(name), base.angle(name)
        assert (value is None) == (was is None), (name, value, was, run.err)
        if value is not None and was is not None:
            assert sigma is not None and was_sigma is not None
            diff = (value - was + 180.0) % 360.0 - 180.0
            assert abs(diff) <= FRACTION * was_sigma, (name, value, was, was_sigma)
            assert sigma == pytest.approx(was_sigma, rel=FRACTION), (name, sigma, was_sigma)
    assert run.confident == base.confident, run.err


def refused_naming(run: Run, *fix: str) -> None:
    assert run.code == 2, f"expected a refusal, got exit {run.code}: {run.err[:400]}"
    for text in fix:
        assert text in run.err, (text, run.err)


# --------------------------------------------------------------------------- comma2k19: a highway minute


@pytest.fixture(scope="module")
def comma(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, pd.DataFrame]:
    """The segment folder, a folder for its copies, and its samples as a table (pandas' export)."""
    folder = tmp_path_factory.mktemp("comma")
    segment = _real() / COMMA
    return segment, folder, table(read_log(segment))


@pytest.fixture(scope="module")
def comma_base(comma: tuple[Path, Path, pd.DataFrame]) -> Run:
    base = Run([comma[0]], comma[1] / "base.json")
    assert base.code == 0 and base.confident and base.angle("yaw")[0] is not None, base.err
    return base


def _turned(df: pd.DataFrame) -> pd.DataFrame:
    """Device axes turned 90° about z (device x = sensor y, device y = −sensor x): read back with --axes -y,x,z."""
    out = df.copy()
    out["ax"], out["ay"], out["gx"], out["gy"] = df["ay"], -df["ax"], df["gy"], -df["gx"]
    return out


def _negated(df: pd.DataFrame, axis: str) -> pd.DataFrame:
    """One axis reversed in accelerometer and gyro (a mirror image; a DBC sign)."""
    out = df.copy()
    out[f"a{axis}"], out[f"g{axis}"] = -df[f"a{axis}"], -df[f"g{axis}"]
    return out


def _in_g(df: pd.DataFrame) -> pd.DataFrame:
    out = df.copy()
    out[ACC] = df[ACC] / G_N
    return out


NATIVE = {"time": "t_s", **{c: c for c in ACC + GYRO}, "speed": "speed_mps", "heading": "heading_deg"}
NATIVE |= {"latitude": "lat_deg", "longitude": "lon_deg", "altitude": "alt_m"}


def _columns(df: pd.DataFrame, **roles: str) -> str:
    """A column map of every column of an exported table (a map names all it reads), the roles given replaced."""
    return ",".join(f"{role}={roles.get(role, column)}" for role, column in NATIVE.items() if column in df.columns)


COMMA_COLUMNS = pd.DataFrame(columns=["t_s", *ACC, *GYRO, "speed_mps", "lat_deg", "lon_deg", "alt_m"])  # its export

# Stated: (name, how the copy is made, its file name, the arguments that state it)
COMMA_STATED: list[tuple[str, Callable[[pd.DataFrame], pd.DataFrame], str, list[str]]] = [
    ("exported to CSV", lambda d: d, "c.csv", AXES_RIGHT),
    ("exported to Parquet", lambda d: d, "c.parquet", AXES_RIGHT),
    ("Parquet under its other suffix .pq", lambda d: d, "c.pq", AXES_RIGHT),
    ("axes turned 90° about z, --axes -y,x,z", _turned, "turned.parquet", ["--axes", "-y,x,z"]),
    ("y reversed (left-handed), --axes x,-y,z", lambda d: _negated(d, "y"), "mirror_y.parquet", ["--axes", "x,-y,z"]),
    ("accelerations in g, --unit g", _in_g, "g.parquet", ["--unit", "g", *AXES_RIGHT]),
    (
        "accelerations in g, a column map's unit",
        _in_g,
        "g_map.csv",
        ["--columns", _columns(COMMA_COLUMNS, ax="ax:g", ay="ay:g", az="az:g"), *AXES_RIGHT],
    ),
    (
        "speed in km/h, a column map's unit",
        lambda d: d.assign(speed_mps=d["speed_mps"] * 3.6).rename(columns={"speed_mps": "v_kmh"}),
        "kmh.parquet",
        ["--columns", _columns(COMMA_COLUMNS, speed="v_kmh:km/h"), *AXES_RIGHT],
    ),
    (
        "time in ms, a column map's unit",
        lambda d: d.assign(t_s=d["t_s"] * 1000.0).rename(columns={"t_s": "t"}),
        "ms.csv",
        ["--columns", _columns(COMMA_COLUMNS, time="t:ms"), *AXES_RIGHT],
    ),
]


@pytest.mark.parametrize(("name", "make", "file", "args"), COMMA_STATED, ids=[c[0] for c in COMMA_STATED])
def test_comma2k19_a_stated_convention_gives_the_same_answer(
    comma: tuple[Path, Path, pd.DataFrame],
    comma_base: Run,
    calibrate: Calibrate,
    name: str,
    make: Callable[[pd.DataFrame], pd.DataFrame],
    file: str,
    args: list[str],
) -> None:
    _, folder, df = comma
    path = write(make(df), folder / file)
    same_answer(calibrate([path, *args], "copy"), comma_base)


def test_comma2k19_exported_without_its_axes_is_answered_alike_but_not_confident(
    comma: tuple[Path, Path, pd.DataFrame], comma_base: Run, calibrate: Calibrate
) -> None:
    """The export drops what the segment's reader stated (the phone's axes, x,-y,-z onto a right-handed frame);
    a highway minute turns too little for the handedness checks, so the axes as logged are an assumption."""
    _, folder, df = comma
    run = calibrate([write(df, folder / "plain.parquet")], "plain")
    for name in ANGLES:
        assert run.angle(name) == comma_base.angle(name)
    check = run.check("axes")
    assert not run.confident and check is not None and check["passed"] is False
    assert "--axes x,y,z" in str(check["reason"]) and "no handedness check could test it" in str(check["reason"])


@pytest.mark.parametrize("axis", ["x", "y"])
def test_comma2k19_mirrored_without_axes_is_not_a_confident_answer(
    comma: tuple[Path, Path, pd.DataFrame], calibrate: Calibrate, axis: str
) -> None:
    """A reversed axis the minute's few turns cannot show: before, a confident answer with roll (y) or pitch (x)
    reversed — pitch −3.18 ± 0.52° for the truth's +4.14°. Now the assumption is named and the answer not confident."""
    _, folder, df = comma
    run = calibrate([write(_negated(df, axis), folder / f"mirror_{axis}_unstated.parquet")], f"mirror_{axis}")
    assert run.code == 0 and not run.confident
    check = run.check("axes")
    assert check is not None and check["passed"] is False and "--axes" in str(check["reason"])


def test_comma2k19_speed_in_kmh_unlabelled_gives_the_same_angles_and_names_the_unit(
    comma: tuple[Path, Path, pd.DataFrame], comma_base: Run, calibrate: Calibrate
) -> None:
    """The speed's scale does not move the angles: the grade from the altitude reads the distance driven in the
    unit the drive found. Before, the distance was 3.6 times too long: pitch 3.78 ± 0.13° for 4.14 ± 0.44°."""
    _, folder, df = comma
    path = write(df.assign(speed_mps=df["speed_mps"] * 3.6), folder / "kmh_unlabelled.parquet")
    run = calibrate([path, *AXES_RIGHT], "kmh_unlabelled")
    same_answer(run, comma_base)
    assert any("a speed logged in km/h and read as m/s" in n for n in run.result["notes"])  # type: ignore[index]


def test_comma2k19_unstated_units_and_suffixes_are_refused_naming_the_fix(
    comma: tuple[Path, Path, pd.DataFrame], calibrate: Calibrate
) -> None:
    _, folder, df = comma
    refused_naming(calibrate([write(_in_g(df), folder / "g_unlabelled.parquet")], "g"), "ax=ax:g,ay=ay:g,az=az:g")
    ms = write(df.assign(t_s=df["t_s"] * 1000.0), folder / "ms_unlabelled.parquet")
    refused_naming(calibrate([ms], "ms"), "time=t_s:ms")
    named_ms = write(df.rename(columns={"t_s": "t_ms"}).assign(t_ms=df["t_s"] * 1000.0), folder / "t_ms.csv")
    refused_naming(calibrate([named_ms], "t_ms"), "time=t_ms:ms")  # a name states a unit only in a column map
    parquet = write(df, folder / "content.parquet")
    shutil.copy(parquet, folder / "parquet_named.csv")
    refused_naming(calibrate([folder / "parquet_named.csv"], "pq_csv"), "parquet_named.parquet")
    csv = write(df, folder / "content.csv")
    for suffix in (".parquet", ".mcap", ".mf4"):
        shutil.copy(csv, folder / f"csv_named{suffix}")
        refused_naming(calibrate([folder / f"csv_named{suffix}"], f"csv{suffix}"), "csv_named.csv")


def test_comma2k19_gyro_in_degrees_labelled_radians_is_refused_naming_the_unit(
    comma: tuple[Path, Path, pd.DataFrame], calibrate: Calibrate
) -> None:
    """No stop to show the gyro at rest, no turn beyond 3 rad/s read: before, refused for too little straight driving
    (the gyro's straightness gate took every interval for a turn). The gyro turns gravity 15 times further than the
    accelerometer sees it turn; as deg/s, as far."""
    _, folder, df = comma
    dps = df.copy()
    dps[GYRO] = np.degrees(df[GYRO])
    refused_naming(calibrate([write(dps, folder / "deg_s.parquet")], "dps"), "deg/s")


# --------------------------------------------------------------------------- CANedge car, drive 165


@pytest.fixture(scope="module")
def car(tmp_path_factory: pytest.TempPathFactory) -> tuple[list[object], Path, pd.DataFrame]:
    """Drive 165's MF4 splits with their DBC arguments, a folder for the copies, and its samples as a table."""
    real = _real()
    files = sorted(str(p) for p in (real / CAR).glob("*.MF4"))
    args: list[object] = [*files, "--dbc", real / DBC, "--channel", "2"]
    samples = read_log(files, LogOptions(dbc=str(real / DBC), channel=2))
    return args, tmp_path_factory.mktemp("car"), table(samples)


@pytest.fixture(scope="module")
def car_base(car: tuple[list[object], Path, pd.DataFrame]) -> Run:
    base = Run(car[0], car[1] / "car.json")
    assert base.code == 0 and base.check("handedness_turns") is not None, base.err
    return base


CAR_STATED: list[tuple[str, Callable[[pd.DataFrame], pd.DataFrame], list[str]]] = [
    ("exported to Parquet", lambda d: d, []),
    (
        "heading in radians, --heading-unit rad",
        lambda d: d.assign(heading_deg=np.radians(d["heading_deg"])),
        ["--heading-unit", "rad"],
    ),
    ("y reversed (left-handed), --axes x,-y,z", lambda d: _negated(d, "y"), ["--axes", "x,-y,z"]),
    # relative headings (no uphill azimuth): a common offset is what they leave open, so it changes nothing
    ("headings half a turn off, relative", lambda d: d.assign(heading_deg=(d["heading_deg"] + 180.0) % 360.0), []),
]


def test_canedge_car_stated_conventions_give_the_same_answer(
    car: tuple[list[object], Path, pd.DataFrame], car_base: Run, calibrate: Calibrate
) -> None:
    _, folder, df = car
    for i, (name, make, args) in enumerate(CAR_STATED):
        run = calibrate([write(make(df), folder / f"stated{i}.parquet"), *args], f"stated{i}")
        assert run.code == 0, (name, run.err)
        same_answer(run, car_base)


def test_canedge_car_unstated_conventions_are_refused_naming_the_fix(
    car: tuple[list[object], Path, pd.DataFrame], calibrate: Calibrate
) -> None:
    _, folder, df = car
    rad = write(df.assign(heading_deg=np.radians(df["heading_deg"])), folder / "rad.parquet")
    refused_naming(calibrate([rad], "rad"), "--heading-unit rad")
    ccw = write(df.assign(heading_deg=(360.0 - df["heading_deg"]) % 360.0), folder / "ccw.parquet")
    refused_naming(calibrate([ccw], "ccw"), "90° − yaw")  # an ENU-like heading: its conversion named
    refused_naming(calibrate([write(_negated(df, "y"), folder / "mirror.parquet")], "mirror"), "--axes")
    dps = df.copy()
    dps[GYRO] = np.degrees(df[GYRO])
    refused_naming(calibrate([write(dps, folder / "dps.parquet")], "dps"), "deg/s")


# --------------------------------------------------------------------------- robot_localization: rotate


def test_robot_bag_mcap_and_their_exports_rotate_to_the_same_samples(
    real_data: Path, result: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The ROS 1 bag, its ROS 2 MCAP, and the MCAP exported to CSV and Parquet: one rotated output; in g with the
    unit stated, the same. Left unstated (accelerations in g, time in ms, the gyro in deg/s; the bag and the MCAP
    each under the other's suffix), it is refused naming the fix and nothing is written."""
    mcap = real_data / ROBOT_MCAP
    df = table(read_log(mcap))
    inputs = {
        "mcap": mcap,
        "bag": real_data / ROBOT_BAG,
        "csv": write(df, tmp_path / "r.csv"),
        "parquet": write(df, tmp_path / "r.parquet"),
    }
    rotated = {}
    for name, path in inputs.items():
        out = tmp_path / f"{name}_v.parquet"
        assert main(["rotate", str(path), "--calibration", str(result), "-o", str(out)]) == 0, capsys.readouterr().err
        rotated[name] = pd.read_parquet(out)[["t_s", *ACC, *GYRO]].to_numpy()
    g = write(_in_g(df), tmp_path / "g.parquet")
    stated = tmp_path / "g_stated_v.parquet"
    in_g = _columns(df, ax="ax:g", ay="ay:g", az="az:g")
    assert main(["rotate", str(g), "--columns", in_g, "--calibration", str(result), "-o", str(stated)]) == 0
    rotated["g stated"] = pd.read_parquet(stated)[["t_s", *ACC, *GYRO]].to_numpy()
    for name in ("bag", "csv", "parquet"):
        np.testing.assert_array_equal(rotated[name], rotated["mcap"], err_msg=name)
    np.testing.assert_allclose(rotated["g stated"], rotated["mcap"], rtol=0, atol=1e-12)
    dps = df.copy()
    dps[GYRO] = np.degrees(df[GYRO])  # before, written as rad/s 57.3 times too large: exit 0
    unstated = {
        "g": (g, "ax=ax:g"),
        "ms": (write(df.assign(t_s=df["t_s"] * 1000.0), tmp_path / "ms.parquet"), ":ms"),
        "deg/s": (write(dps, tmp_path / "dps.parquet"), "gx=gx:deg/s"),
    }
    for wrong, right in (("mcap_named.bag", "mcap_named.mcap"), ("bag_named.mcap", "bag_named.bag")):
        source = inputs["mcap" if wrong.startswith("mcap") else "bag"]
        unstated[wrong] = (Path(shutil.copy(source, tmp_path / wrong)), right)  # a container under the other's name
    for bad, fix in unstated.values():
        out = tmp_path / f"{bad.stem}_v.parquet"
        capsys.readouterr()
        assert main(["rotate", str(bad), "--calibration", str(result), "-o", str(out)]) == 2
        err = capsys.readouterr().err
        assert fix in err and "Traceback" not in err and not out.exists()


# --------------------------------------------------------------------------- imucal's Ferraris session: triad

FERRARIS = "imucal-ferraris/example_ferraris_session.csv"
FERRARIS_MAP = "time=n_samples:s/102.4,ax=acc_x{a},ay=acc_y{a},az=acc_z{a},gx=gyr_x{g},gy=gyr_y{g},gz=gyr_z{g}"


def test_ferraris_session_in_g_stated_gives_the_same_triad_and_unstated_units_are_refused(
    real_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The session (m/s², deg/s, its time a sample count at 102.4 Hz) with its column map; the same session with the
    accelerations in g and the map saying so; and the map without a unit where one is needed."""
    from mountcal.estimate.triad import load

    session = real_data / FERRARIS
    in_g = pd.read_csv(session)
    in_g[["acc_x", "acc_y", "acc_z"]] /= G_N
    copy = write(in_g, tmp_path / "session_g.csv")
    fitted = []
    for path, unit in ((session, ""), (copy, ":g")):
        out = tmp_path / f"triad_{path.stem}.json"
        assert main(["triad", str(path), "--columns", FERRARIS_MAP.format(a=unit, g=":deg/s"), "-o", str(out)]) == 0
        fitted.append(load(out))
    np.testing.assert_allclose(fitted[1].bias_mps2, fitted[0].bias_mps2, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(fitted[1].matrix, fitted[0].matrix, rtol=1e-9, atol=1e-12)
    assert fitted[1].fitted == fitted[0].fitted
    unstated = [
        (copy, FERRARIS_MAP.format(a="", g=":deg/s"), "acc_x:g"),
        (session, FERRARIS_MAP.format(a="", g=""), "deg/s"),
    ]
    for path, columns, fix in unstated:
        out = tmp_path / "refused.json"
        capsys.readouterr()
        assert main(["triad", str(path), "--columns", columns, "-o", str(out)]) == 2
        err = capsys.readouterr().err
        assert fix in err and "Traceback" not in err and not out.exists()
