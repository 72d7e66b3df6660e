"""Tables from anywhere: a column map with units, the known exports recognised and stated, gravity-free
acceleration refused for calibration, and imucal's annotated session read against imucal's own annotation.

The metamorphic checks write one recording in other conventions (column names, time and acceleration
units, delimiters, a phone app's layout) and require the same samples and the same answer back.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mountcal import calibrate_log, read_log
from mountcal.cli import main
from mountcal.core.errors import InputError
from mountcal.io.reader import LogOptions
from mountcal.io.samples import Samples
from mountcal.io.table.layout import parse_columns

REPO = Path(__file__).resolve().parents[2]
G_N = 9.80665
IMUCAL_ANNOTATED = (
    "time=samples:s/204.8,ax=acc_x:g/2048,ay=acc_y:g/2048,az=acc_z:g/2048,"
    "gx=gyr_x:deg/s/16.4,gy=gyr_y:deg/s/16.4,gz=gyr_z:deg/s/16.4"
)
IMUCAL_EXAMPLE = "time=n_samples:s/102.4,ax=acc_x,ay=acc_y,az=acc_z,gx=gyr_x:deg/s,gy=gyr_y:deg/s,gz=gyr_z:deg/s"
STATIC = ("x_p", "x_a", "y_p", "y_a", "z_p", "z_a")
ROTATIONS = ("x_rot", "y_rot", "z_rot")


def _stops(tmp_path: Path, path: Path, *args: str) -> pd.DataFrame:
    out = tmp_path / "stops.csv"
    assert main(["stops", str(path), "-o", str(out), *args]) == 0
    table = pd.read_csv(out)
    return table.assign(t_end_s=table["t_s"] + table["duration_s"])


# --------------------------------------------------------------------------- imucal's sessions (real data)


@pytest.mark.real_data
def test_imucals_annotated_session_gives_the_still_periods_of_its_annotation(real_data: Path, tmp_path: Path) -> None:
    """imucal's annotated session (raw BMI160 counts at 204.8 Hz, as imucal's own tests read it) with a column
    map: one still period per static part of the annotation, each inside it, its ends within half a
    detection window (1 s) of the part's ends (measured: 0.98–1.02 s; 0 at the file's start); no still
    period in a rotation."""
    path = real_data / "imucal-ferraris" / "annotated_session.csv"
    stops = _stops(tmp_path, path, "--columns", IMUCAL_ANNOTATED, "--trim-s", "0", "--min-stop-s", "1")
    parts = pd.read_csv(path).groupby("part")["samples"].agg(["min", "max"]) / 204.8
    assert len(stops) == len(STATIC)
    for name in STATIC:
        start, end = parts.loc[name]
        inside = stops[(stops.t_s >= start - 1e-9) & (stops.t_end_s <= end + 1 / 204.8 + 1e-9)]
        assert len(inside) == 1, name
        slack = 1.0 + 2.0 / 40 + 1 / 204.8  # half the 2 s window, one block of the moving statistics, one sample
        assert inside.t_s.iloc[0] - start <= slack and end - inside.t_end_s.iloc[0] <= slack, name
    for name in ROTATIONS:
        start, end = parts.loc[name]
        assert not ((stops.t_s < end) & (stops.t_end_s > start)).any(), name


@pytest.mark.real_data
def test_imucals_example_session_holds_each_annotated_region_in_one_still_period(
    real_data: Path, tmp_path: Path
) -> None:
    """The example session (m/s², deg/s, 102.4 Hz) against its section list: each static section lies in
    one still period (which the annotator cut shorter at both ends: measured 0.18–1.16 s), no rotation
    section is still."""
    folder = real_data / "imucal-ferraris"
    stops = _stops(
        tmp_path,
        folder / "example_ferraris_session.csv",
        "--columns",
        IMUCAL_EXAMPLE,
        "--trim-s",
        "0",
        "--min-stop-s",
        "3",
    )
    regions = json.loads((folder / "example_ferraris_session_list.json").read_text())
    for name in STATIC:
        start, end = regions[name]["start"] / 102.4, regions[name]["end"] / 102.4
        holding = stops[(stops.t_s <= start) & (stops.t_end_s >= end)]
        assert len(holding) == 1, name
        assert start - holding.t_s.iloc[0] < 1.5 and holding.t_end_s.iloc[0] - end < 1.5, name  # seconds
    for name in ROTATIONS:
        start, end = regions[name]["start"] / 102.4, regions[name]["end"] / 102.4
        assert not ((stops.t_s < end) & (stops.t_end_s > start)).any(), name


@pytest.mark.real_data
def test_an_imucal_session_without_its_rate_is_refused_with_the_map_that_reads_it(
    real_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = real_data / "imucal-ferraris" / "example_ferraris_session.csv"
    assert main(["stops", str(path), "-o", str(tmp_path / "s.csv")]) == 2
    err = capsys.readouterr().err
    assert "an imucal session" in err and f"--columns {IMUCAL_EXAMPLE}" in err
    raw = real_data / "imucal-ferraris" / "annotated_session.csv"  # counts read as m/s²: the unit that fits is named
    assert (
        main(["stops", str(raw), "-o", str(tmp_path / "s.csv"), "--columns", IMUCAL_ANNOTATED.replace(":g/2048", "")])
        == 2
    )
    err = capsys.readouterr().err
    assert "ax=acc_x:g/2048,ay=acc_y:g/2048,az=acc_z:g/2048" in err and not (tmp_path / "s.csv").exists()


@pytest.mark.real_data
def test_a_mapping_toml_reads_as_the_column_map(real_data: Path, tmp_path: Path) -> None:
    path = real_data / "imucal-ferraris" / "annotated_session.csv"
    toml = tmp_path / "imucal.toml"
    toml.write_text("[columns]\n" + "".join(f'{k} = "{v}"\n' for k, v in parse_columns(IMUCAL_ANNOTATED)))
    a = read_log(path, LogOptions(mapping=str(toml)))
    b = read_log(path, LogOptions(columns=parse_columns(IMUCAL_ANNOTATED)))
    np.testing.assert_array_equal(a.acc_s, b.acc_s)
    np.testing.assert_array_equal(a.t_s, b.t_s)
    assert a.gyro_s is not None and np.abs(a.gyro_s).max() > 3.0  # 360° turns, in rad/s


# --------------------------------------------------------------------------- one recording, many conventions


@pytest.fixture(scope="module")
def parking() -> Samples:
    return read_log(REPO / "data" / "parking.mcap")


def _answer(path: Path, **log: object) -> tuple[float, ...]:
    done = calibrate_log(path, log=LogOptions(**log), protocol=REPO / "data" / "parking_protocol.csv")  # type: ignore[arg-type]
    c = done.calibration
    return (c.roll_deg, c.pitch_deg, c.yaw_deg, c.roll_sigma_deg, c.pitch_sigma_deg)


def _native(parking: Samples, path: Path) -> Path:
    frame = pd.DataFrame(
        {"t_s": parking.t_s, **{k: parking.acc_s[:, i] for i, k in enumerate(("ax", "ay", "az"))}}
        | {k: parking.gyro_s[:, i] for i, k in enumerate(("gx", "gy", "gz"))}  # type: ignore[index]
    )
    frame.to_csv(path, index=False, float_format="%.17g")
    return path


def test_units_and_names_in_a_column_map_give_the_same_answer(parking: Samples, tmp_path: Path) -> None:
    """The same samples in ms and g under other names (and in ns, mg, ISO time; ';' and decimal commas)
    read through a column map: the native table's samples (to rounding) and its answer (to 1e-9°)."""
    want = _answer(_native(parking, tmp_path / "native.csv"))
    acc, gyro = parking.acc_s, parking.gyro_s
    assert gyro is not None
    t_ns = np.round(parking.t_s * 1e9).astype(np.int64)
    variants = {
        "ms_g.csv": (
            pd.DataFrame(
                {"ts": parking.t_s * 1e3, "acc_x": acc[:, 0] / G_N, "acc_y": acc[:, 1] / G_N, "acc_z": acc[:, 2] / G_N}
                | {f"w{c}": np.degrees(gyro[:, i]) for i, c in enumerate("xyz")}
            ),
            "time=ts:ms,ax=acc_x:g,ay=acc_y:g,az=acc_z:g,gx=wx:deg/s,gy=wy:deg/s,gz=wz:deg/s",
            {},
        ),
        "ns_mg.csv": (
            pd.DataFrame(
                {"stamp": t_ns, "X": acc[:, 0] / G_N * 1e3, "Y": acc[:, 1] / G_N * 1e3, "Z": acc[:, 2] / G_N * 1e3}
                | {f"g{c}": gyro[:, i] for i, c in enumerate("xyz")}
            ),
            "time=stamp:ns,ax=X:mg,ay=Y:mg,az=Z:mg,gx=gx,gy=gy,gz=gz",
            {},
        ),
        "iso_semicolon.csv": (
            pd.DataFrame(
                {"when": pd.to_datetime(t_ns, utc=True).strftime("%Y-%m-%dT%H:%M:%S.%fZ")}
                | {f"a{c}": acc[:, i] for i, c in enumerate("xyz")}
                | {f"r{c}": gyro[:, i] for i, c in enumerate("xyz")}
            ),
            "time=when:iso,ax=ax,ay=ay,az=az,gx=rx,gy=ry,gz=rz",
            {"sep": ";", "decimal": ","},
        ),
    }
    for name, (frame, columns, csv_args) in variants.items():
        path = tmp_path / name
        frame.to_csv(path, index=False, float_format="%.17g", **csv_args)  # type: ignore[arg-type]
        got = read_log(path, LogOptions(columns=parse_columns(columns)))
        np.testing.assert_allclose(got.acc_s, acc, rtol=1e-12, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(got.t_s, parking.t_s, rtol=0, atol=2e-6, err_msg=name)  # ms and µs text
        got_answer = _answer(path, columns=parse_columns(columns))
        assert got_answer[:3] == pytest.approx(want[:3], abs=1e-9), name  # the angles
        assert got_answer[3:] == pytest.approx(want[3:], rel=1e-6), name  # σ: float times re-rounded to ns move it


def test_unit_g_applies_to_a_sample_table(parking: Samples, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    native = _native(parking, tmp_path / "native.csv")
    in_g = tmp_path / "in_g.csv"
    frame = pd.read_csv(native)
    frame[["ax", "ay", "az"]] /= G_N
    frame.to_csv(in_g, index=False, float_format="%.17g")
    protocol = str(REPO / "data" / "parking_protocol.csv")
    results = {}
    for name, extra in (("native", []), ("g", ["--unit", "g"])):
        out = tmp_path / f"{name}.json"
        src = native if name == "native" else in_g
        assert main(["calibrate", str(src), "--protocol", protocol, "-o", str(out), *extra]) == 0
        results[name] = json.loads(out.read_text())["mounting"]
    for key in ("roll_deg", "pitch_deg", "yaw_deg"):
        assert results["g"][key] == pytest.approx(results["native"][key], abs=1e-9)
    assert main(["calibrate", str(in_g), "--protocol", protocol]) == 2  # without it: refused, naming the fix
    assert "ax=ax:g,ay=ay:g,az=az:g" in capsys.readouterr().err


# --------------------------------------------------------------------------- phone apps' exports

PHONE_T = np.arange(0, 120, 0.01)


def _phone(rng: np.random.Generator) -> dict[str, np.ndarray]:
    """A phone lying flat (+z up), still: specific force (0, 0, g) plus noise; the gravity-free version too."""
    n = PHONE_T.size
    lin = rng.normal(0, 0.02, (n, 3))
    return {"total": lin + np.array([0.0, 0.0, G_N]), "linear": lin, "gyro": rng.normal(0, 0.001, (n, 3))}


def _write_exports(tmp_path: Path) -> dict[str, Path]:
    """Files laid out as the apps export them (column names from the apps' own definitions and exports)."""
    d = _phone(np.random.default_rng(1))
    out: dict[str, Path] = {}
    phyphox = {"Time (s)": PHONE_T} | {f"Acceleration {c} (m/s^2)": d["total"][:, i] for i, c in enumerate("xyz")}
    phyphox |= {"Absolute acceleration (m/s^2)": np.linalg.norm(d["total"], axis=1)}
    out["phyphox"] = tmp_path / "Raw Data.csv"
    pd.DataFrame(phyphox).to_csv(out["phyphox"], index=False)
    linear = {"Time (s)": PHONE_T} | {
        f"Linear Acceleration {c} (m/s^2)": d["linear"][:, i] for i, c in enumerate("xyz")
    }
    (tmp_path / "linear").mkdir()
    out["phyphox_linear"] = tmp_path / "linear" / "Raw Data.csv"
    pd.DataFrame(linear).to_csv(out["phyphox_linear"], index=False)
    ns = 1_716_979_893_874_983_200 + np.round(PHONE_T * 1e9).astype(np.int64)
    for name, key in (("TotalAcceleration", "total"), ("Accelerometer", "linear"), ("Gyroscope", "gyro")):
        frame = pd.DataFrame(
            {"time": ns, "seconds_elapsed": PHONE_T} | {c: d[key][:, i] for i, c in reversed(list(enumerate("xyz")))}
        )
        assert list(frame.columns) == ["time", "seconds_elapsed", "z", "y", "x"]  # Sensor Logger's order
        out[name] = tmp_path / f"{name}.csv"
        frame.to_csv(out[name], index=False)
    gforce = {"time": PHONE_T} | {f"gF{c}": d["total"][:, i] / G_N for i, c in enumerate("xyz")}
    gforce |= {"TgF": np.linalg.norm(d["total"], axis=1) / G_N}
    out["ptss"] = tmp_path / "ptss_gforce.csv"
    pd.DataFrame(gforce).to_csv(out["ptss"], index=False)
    lin_ptss = (
        {"time": PHONE_T}
        | {f"a{c}": d["linear"][:, i] for i, c in enumerate("xyz")}
        | {"aT": np.linalg.norm(d["linear"], axis=1)}
    )
    out["ptss_linear"] = tmp_path / "ptss_linear.csv"
    pd.DataFrame(lin_ptss).to_csv(out["ptss_linear"], index=False)
    return out


@pytest.fixture
def exports(tmp_path: Path) -> dict[str, Path]:
    return _write_exports(tmp_path)


@pytest.mark.parametrize(
    ("name", "said"),
    [("phyphox", "phyphox"), ("TotalAcceleration", "Sensor Logger"), ("ptss", "Physics Toolbox")],
)
def test_phone_exports_with_gravity_are_recognised_and_stated(exports: dict[str, Path], name: str, said: str) -> None:
    got = read_log(exports[name])
    assert len(got) == PHONE_T.size and not got.gravity_free
    np.testing.assert_allclose(np.median(got.acc_s, axis=0), [0.0, 0.0, G_N], atol=0.01)  # x, y, z in their places
    assert any(said in note for note in got.notes)
    if name == "TotalAcceleration":
        assert got.t_s[0] == pytest.approx(1_716_979_893.874983, abs=1e-6)  # epoch ns, exactly
        np.testing.assert_allclose(np.diff(got.t_s), 0.01, atol=1e-6)


@pytest.mark.parametrize("name", ["phyphox_linear", "Accelerometer", "ptss_linear"])
def test_gravity_free_acceleration_reads_but_is_refused_for_calibration(
    exports: dict[str, Path], name: str, capsys: pytest.CaptureFixture[str]
) -> None:
    got = read_log(exports[name])
    assert got.gravity_free
    assert main(["calibrate", str(exports[name])]) == 2
    err = capsys.readouterr().err
    assert "without gravity" in err and "Traceback" not in err
    assert main(["inspect", str(exports[name])]) == 0  # listing it is fine


def test_a_column_named_as_gravity_free_or_measuring_none_is_refused_for_calibration(tmp_path: Path) -> None:
    d = _phone(np.random.default_rng(2))
    path = tmp_path / "log.csv"
    pd.DataFrame({"t": PHONE_T} | {f"lin_acc_{c}": d["linear"][:, i] for i, c in enumerate("xyz")}).to_csv(
        path, index=False
    )
    by_name = "time=t,ax=lin_acc_x,ay=lin_acc_y,az=lin_acc_z"
    with pytest.raises(InputError, match="named as an acceleration with gravity removed"):
        calibrate_log(path, log=LogOptions(columns=parse_columns(by_name)))
    renamed = tmp_path / "renamed.csv"
    pd.read_csv(path).rename(columns=lambda c: c.replace("lin_", "")).to_csv(renamed, index=False)
    with pytest.raises(InputError, match=r"median magnitude is 0\.03"):  # the content tells it too
        calibrate_log(renamed, log=LogOptions(columns=parse_columns(by_name.replace("lin_", ""))))


def test_a_gyro_only_export_is_refused_naming_the_file_to_read(
    exports: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["calibrate", str(exports["Gyroscope"])]) == 2
    err = capsys.readouterr().err
    assert "Sensor Logger Gyroscope.csv" in err and f"its folder {exports['Gyroscope'].resolve().parent}" not in err
    assert "the zip Sensor Logger exported, or the folder it unzips to" in err  # no Metadata.csv beside it


# --------------------------------------------------------------------------- refusals


def test_column_map_mistakes_are_refused_with_what_to_do(
    parking: Samples, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    native = _native(parking, tmp_path / "native.csv")
    toml = tmp_path / "m.toml"
    toml.write_text('[columns]\ntime = "t_s"\nax = "ax"\nay = "ay"\naz = "az"\n')
    cases = [
        (["--columns", "time=t_s,ax=ax,ay=ay"], "no az"),
        (["--columns", "time=t_s,ax=ax,ay=ay,az=nope"], "a column 'nope' (for az)"),
        (["--columns", "time=t_s,ax=ax:furlong,ay=ay,az=az"], "'furlong'"),
        (["--columns", "time=t_s,ax=ax,ay=ay,az=az,bx=gx"], "unknown 'bx'"),
        (["--columns", "time=t_s,ax=ax,ay=ay,az=az,gx=gx"], "gx, gy and gz together"),
        (["--columns", "t_s", "--mapping", str(toml)], "ROLE=COLUMN"),
        (["--columns", "time=t_s,ax=ax,ay=ay,az=az", "--mapping", str(toml)], "Give the map once"),
        (["--columns", "time=t_s:ms,ax=ax:g,ay=ay:g,az=az:g", "--unit", "g"], "the acceleration unit given once"),
    ]
    for extra, words in cases:
        assert main(["calibrate", str(native), *extra]) == 2, extra
        err = capsys.readouterr().err
        assert words in err and "Traceback" not in err, (extra, err)
    mcap = str(REPO / "data" / "parking.mcap")
    assert main(["calibrate", mcap, "--columns", "time=t_s,ax=ax,ay=ay,az=az"]) == 2
    assert "does not apply" in capsys.readouterr().err
    assert main(["calibrate", mcap, "--unit", "g"]) == 2  # silently ignored before
    assert "does not apply" in capsys.readouterr().err
