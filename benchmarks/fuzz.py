"""Fuzzing `mountcal calibrate`: correct, or a clear refusal — never a traceback, never a confident wrong answer.

Each case is an input a user can write: a stop table with any subset of the optional columns, in
m/s² or g, 3–200 stops, headings none / relative / uphill, any mounting in SO(3), stop noise
0.1–20 mg, slope 0.5–30°, now and then a slope reference (right, off, or no slope at all) — or a
parking log the simulator writes with random parameters. Every case runs the real CLI in-process
and is classified:

- ``ok``: exit 0 and a result that is valid JSON with finite numbers, loads back, and is right
  (when marked confident: tilt within 10°, yaw within 5σ);
- ``refused``: non-zero exit with a message (a ``MountcalError``);
- ``traceback``, ``nonfinite``, ``invalid``, ``wrong_confident``: the failures counted.

    python benchmarks/fuzz.py --stops 2000 --logs 100 --seed 1

A log-byte mutation suite plugs in as ``benchmarks/fuzz_mutations.py`` exposing
``run(count: int, seed: int, report: Report) -> None`` (``--mutations N``); it is imported when present.
tests/test_properties.py draws the same stop-table cases with hypothesis (the CI profile).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import json
import math
import tempfile
import time
import traceback
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from mountcal.cli import main as cli_main
from mountcal.core.conventions import G_N, normal_gravity
from mountcal.core.result import Calibration
from mountcal.simulate.stops import simulate_stops
from mountcal.stops.table import ALT, BETA, COUNT, LAT, LON, OPTIONAL, SITE, STD, TEMPERATURE

FAILURES = ("traceback", "nonfinite", "invalid", "wrong_confident", "crash", "hang", "over_memory")
MAX_TILT_ERROR_DEG = 10.0
MAX_YAW_ERROR_SIGMA = 5.0
HEADINGS = ("uphill", "relative", "none")
DBC = Path(__file__).resolve().parents[1] / "data" / "imu_mm5_10.dbc"  # the CAN logs' layout (Bosch MM5.10)


@dataclass(frozen=True)
class StopCase:
    """One stop table a user could write, and how it is passed to the CLI."""

    n: int
    columns: tuple[str, ...]  # the optional columns kept (a subset of stoptable.OPTIONAL)
    unit: str  # "mps2" or "g"
    headings: str  # the --headings flag
    quat_xyzw: tuple[float, float, float, float]  # the true mounting (normalised on use)
    noise_mg: float
    slope_deg: float
    even_headings: bool  # β evenly spread, else drawn at random
    heading_offset_deg: float  # added to β with --headings relative
    seed: int
    model: str = "auto"  # the --model flag
    method: str = "full"  # the --method flag
    parquet: bool = False  # the table as Parquet (columns shuffled, an unknown column added), else CSV
    slope_reference: tuple[float, float] | None = None  # --slope-reference DEG SIGMA_DEG (right, off, or no slope)


MODELS = (
    "auto",
    "rotation,slope",
    "rotation,slope,bias",
    "rotation,slope,gravity",
    "rotation,slope,bias,temperature",
    "rotation,slope,site_slope",
    "rotation,slope,scale",
    "rotation,slope,bias,gravity,scale",
)


@dataclass
class Report:
    """Counts per outcome and the first few examples of each failure."""

    counts: Counter[str] = field(default_factory=Counter)
    examples: dict[str, list[str]] = field(default_factory=dict)

    def add(self, kind: str, detail: str = "") -> None:
        self.counts[kind] += 1
        if kind in FAILURES and len(self.examples.setdefault(kind, [])) < 5:
            self.examples[kind].append(detail)

    @property
    def failures(self) -> int:
        return sum(self.counts[k] for k in FAILURES)

    def text(self) -> str:
        lines = [", ".join(f"{k}: {v}" for k, v in sorted(self.counts.items()))]
        for kind, items in self.examples.items():
            lines += [f"{kind}:"] + [f"  {d}" for d in items]
        return "\n".join(lines)


def random_stop_case(rng: np.random.Generator) -> StopCase:
    keep = tuple(c for c in OPTIONAL if rng.random() < 0.5)
    return StopCase(
        n=int(rng.choice([3, 4, 5, 6, 8, 12, 20, 50, 200], p=[0.1, 0.1, 0.1, 0.1, 0.1, 0.2, 0.15, 0.1, 0.05])),
        columns=keep,
        unit=str(rng.choice(["mps2", "g"])),
        headings=str(rng.choice(HEADINGS)),
        quat_xyzw=tuple(float(v) for v in Rotation.random(random_state=rng.integers(2**31)).as_quat()),  # type: ignore[arg-type]
        noise_mg=float(np.exp(rng.uniform(np.log(0.1), np.log(20.0)))),
        slope_deg=float(rng.uniform(0.5, 30.0)),
        even_headings=bool(rng.random() < 0.6),
        heading_offset_deg=float(rng.uniform(-180.0, 180.0)),
        seed=int(rng.integers(2**31)),
        model=str(rng.choice(MODELS)) if rng.random() < 0.3 else "auto",
        method="paper" if rng.random() < 0.15 else "full",
        parquet=bool(rng.random() < 0.2),
        slope_reference=_slope_reference(rng) if rng.random() < 0.2 else None,
    )


def _slope_reference(rng: np.random.Generator) -> tuple[float, float]:
    """A reference as a user may give it: an offset from the true slope (applied in write_stop_case), and its σ —
    now and then one that is no slope or no σ."""
    if rng.random() < 0.15:
        return float(rng.choice([-1.0, 90.0, 1e9, np.nan])), float(rng.choice([0.0, -0.1, 0.05, np.inf]))
    return float(rng.choice([0.0, 0.0, 0.3, -2.0])), float(rng.choice([0.01, 0.05, 0.5]))


def write_stop_case(case: StopCase, folder: Path) -> tuple[Path, list[str], Rotation]:
    """The stop table file, the CLI arguments that read it, and the true mounting."""
    rng = np.random.default_rng(case.seed)
    rot = Rotation.from_quat(case.quat_xyzw)
    if case.even_headings:
        beta = np.linspace(0.0, 360.0, case.n, endpoint=False) + rng.uniform(0, 360)
    else:
        beta = rng.uniform(0.0, 360.0, case.n)
    lat, alt = float(rng.uniform(-80, 80)), float(rng.uniform(-50, 3000))
    g = normal_gravity(lat, alt if ALT in case.columns else 0.0) if LAT in case.columns else G_N
    table, _ = simulate_stops(
        rot_vs=rot,
        slope_deg=case.slope_deg,
        beta_deg=beta % 360.0,
        noise_g=case.noise_mg * 1e-3,
        g_mps2=g,
        seed=rng,
        samples_per_stop=int(rng.integers(2, 2000)),
    )
    df = table.to_frame()
    df[BETA] = (beta + (case.heading_offset_deg if case.headings == "relative" else 0.0)) % 360.0
    df[TEMPERATURE] = rng.uniform(-10, 45, case.n)
    df[SITE] = rng.choice(["A", "B", "C"], case.n)
    df[LAT], df[LON], df[ALT] = lat, float(rng.uniform(-180, 180)), alt
    df[COUNT] = rng.integers(1, 5000, case.n)
    df[list(STD)] = df[list(STD)].to_numpy() * np.sqrt(df[COUNT].to_numpy())[:, None]  # sample spread for that n
    df = df[[c for c in df.columns if c in ("ax", "ay", "az") or c in case.columns]]
    if case.unit == "g":
        cols = [c for c in ("ax", "ay", "az", *STD) if c in df.columns]
        df[cols] = df[cols] / G_N
    if case.parquet:
        df = df.assign(comment="fuzz")[list(rng.permutation([*df.columns, "comment"]))]
        path = folder / f"stops_{case.seed}.parquet"
        df.to_parquet(path, index=False)
    else:
        path = folder / f"stops_{case.seed}.csv"
        df.to_csv(path, index=False, float_format="%.15g")
    args = [str(path), "--unit", case.unit, "--headings", case.headings, "--model", case.model, "--method", case.method]
    if case.slope_reference is not None:
        offset, sigma = case.slope_reference
        measured = case.slope_deg + offset if abs(offset) < 10 else offset  # beyond ±10: the value itself
        args += ["--slope-reference", f"{measured:.6g}", f"{sigma:g}"]
    return path, args, rot


def run_cli(args: list[str]) -> tuple[int | None, str]:
    """Run the CLI in-process; (exit code, stderr), or (None, the traceback) when it raised."""
    err = io.StringIO()
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
            code = cli_main(args)
    except SystemExit as exc:  # argparse
        return int(exc.code or 0), err.getvalue()
    except Exception:
        return None, traceback.format_exc()
    return code, err.getvalue()


def judge(code: int | None, message: str, out: Path, truth: Rotation | None, headings: str) -> tuple[str, str]:
    """Classify one run (see the module doc); ``truth`` None skips the accuracy check."""
    if code is None:
        return "traceback", message.strip().splitlines()[-1] + " | " + " / ".join(message.splitlines()[-6:-1])
    if code != 0:
        if out.exists():
            return "invalid", f"exit {code} but {out.name} was written"
        if not message.strip() or "Traceback" in message:
            return "traceback", f"exit {code} without a clear message: {message[-300:]!r}"
        return "refused", message.strip().splitlines()[-1]
    problem = check_document(out)
    if problem is not None:
        return problem
    doc = json.loads(out.read_text(encoding="utf-8"))
    if truth is not None and doc["confident"]:
        wrong = wrong_answer(doc, truth, headings)
        if wrong:
            return "wrong_confident", wrong
    return "ok", ""


def check_document(out: Path) -> tuple[str, str] | None:
    """None when the written result is finite JSON that loads back and is internally consistent."""
    if not out.exists():
        return "invalid", "exit 0 but no result written"

    def refuse(token: str) -> None:
        raise ValueError(token)

    try:
        doc = json.loads(out.read_text(encoding="utf-8"), parse_constant=refuse)
    except ValueError as err:
        return "nonfinite", f"{out.name}: {err}"
    bad = list(_nonfinite(doc))
    if bad:
        return "nonfinite", ", ".join(bad[:5])
    try:
        cal = Calibration.from_dict(doc, where=str(out))
    except Exception as err:
        return "invalid", f"does not load back: {err}"
    q = np.asarray(doc["rotation"]["quaternion_xyzw"])
    sigmas = [cal.roll_sigma_deg, cal.pitch_sigma_deg, cal.yaw_sigma_deg, cal.slope_sigma_deg]
    if abs(np.linalg.norm(q) - 1) > 1e-9 or any(s is not None and s < 0 for s in sigmas):
        return "invalid", "quaternion not unit, or a negative σ"
    if (cal.yaw_deg is None) != (cal.yaw_sigma_deg is None) or (cal.yaw_deg is None and not cal.yaw_reason):
        return "invalid", "yaw and its σ disagree, or an undetermined yaw without a reason"
    if cal.roll_sigma_deg is None or cal.pitch_sigma_deg is None:
        return "invalid", "an angle without σ"
    for d in doc.get("diagnostics", []):
        if d.get("statistic") is None and not d.get("reason"):
            return "invalid", f"diagnostic {d.get('test')} null without a reason"
    return None


def _nonfinite(value: Any, path: str = "") -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        yield path or "<root>"
    elif isinstance(value, dict):
        for k, v in value.items():
            yield from _nonfinite(v, f"{path}.{k}")
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _nonfinite(v, f"{path}[{i}]")


def wrong_answer(doc: dict[str, Any], truth: Rotation, headings: str) -> str | None:
    """Why a confident result is wrong: tilt more than 10° off, or (yaw determined) yaw more than 5σ off."""
    est = Rotation.from_quat(doc["rotation"]["quaternion_xyzw"])
    up_true, up_est = truth.inv().apply([0, 0, 1.0]), est.inv().apply([0, 0, 1.0])
    tilt = float(np.degrees(np.arccos(np.clip(up_true @ up_est, -1.0, 1.0))))
    if tilt > MAX_TILT_ERROR_DEG:
        return f"tilt {tilt:.1f}° off while confident (σ roll {doc['uncertainty']['roll_deg']:.3g}°)"
    if doc["yaw"]["determined"] and headings == "uphill":
        about_z = float(np.degrees((est * truth.inv()).as_rotvec()[2]))
        sigma = doc["uncertainty"]["rotation_about_vehicle_xyz_deg"][2] or doc["uncertainty"]["yaw_deg"]
        if abs(about_z) > MAX_YAW_ERROR_SIGMA * sigma:
            return f"yaw {about_z:.2f}° off = {abs(about_z) / sigma:.1f}σ while confident"
    return None


def run_stop_case(case: StopCase, folder: Path) -> tuple[str, str]:
    _, args, truth = write_stop_case(case, folder)
    out = folder / f"result_{case.seed}.json"
    code, message = run_cli(["calibrate", *args, "-o", str(out)])
    kind, detail = judge(code, message, out, truth, case.headings)
    return kind, f"{case} → {detail}" if detail else ""


def run_stops(count: int, seed: int, report: Report) -> None:
    rng = np.random.default_rng(seed)
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(count):
            report.add(*run_stop_case(random_stop_case(rng), Path(tmp)))


def run_logs(count: int, seed: int, report: Report) -> None:
    """Parking logs written by `mountcal simulate --log` with random parameters, then calibrated."""
    rng = np.random.default_rng(seed)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for i in range(count):
            roll, pitch, yaw = (
                float(v) for v in Rotation.random(random_state=rng.integers(2**31)).as_euler("xyz", degrees=True)
            )
            slope = float(rng.uniform(0.5, 30.0))
            suffix = str(rng.choice([".mcap", ".blf", ".asc"]))
            dbc = [] if suffix == ".mcap" else ["--dbc", str(DBC)]
            log, protocol, out = folder / f"log{i}{suffix}", folder / f"protocol{i}.csv", folder / f"log{i}.json"
            make = ["simulate", "--roll", f"{roll}", "--pitch", f"{pitch}", "--yaw", f"{yaw}", "--slope", f"{slope}"]
            make += ["--seed", str(int(rng.integers(2**31))), "--log", str(log), "--protocol", str(protocol), *dbc]
            code, message = run_cli(make)
            if code != 0:
                report.add("traceback" if code is None else "invalid", f"simulate {make}: {message[-300:]}")
                continue
            with_protocol = bool(rng.random() < 0.7)
            args = ["calibrate", str(log), "-o", str(out), *dbc] + (
                ["--protocol", str(protocol)] if with_protocol else []
            )
            code, message = run_cli(args)
            truth = Rotation.from_euler("xyz", [roll, pitch, yaw], degrees=True)
            kind, detail = judge(code, message, out, truth, "uphill" if with_protocol else "none")
            report.add(
                kind, f"{args} (roll {roll:.1f}, pitch {pitch:.1f}, yaw {yaw:.1f}, slope {slope:.1f}) → {detail}"
            )
            for p in (log, protocol, out):
                p.unlink(missing_ok=True)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stops", type=int, default=200, help="stop-table cases")
    parser.add_argument("--logs", type=int, default=10, help="simulated-log cases")
    parser.add_argument("--mutations", type=int, default=0, help="log-byte mutation cases (fuzz_mutations.py)")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    report = Report()
    suites = [("stop tables", args.stops, run_stops), ("simulated logs", args.logs, run_logs)]
    if args.mutations:
        try:
            mutations = importlib.import_module("fuzz_mutations")
        except ModuleNotFoundError:
            parser.error("--mutations needs benchmarks/fuzz_mutations.py")

        def run_mutations(count: int, seed: int, report: Report) -> None:
            """fuzz_mutations.run (each command in its own bounded process), its counts folded in."""
            got = mutations.run(count, seed, lambda line: print(f"  {line}", flush=True))
            for failure in got["failures"]:
                for problem in failure["problems"]:  # traceback, crash, hang, memory
                    report.add({"memory": "over_memory"}.get(problem, problem), f"{failure}"[:300])
            clean = got["commands"] - len(got["failures"])
            report.counts["mutated-log commands without failure"] += clean

        suites.append(("log mutations", args.mutations, run_mutations))
    for name, count, run in suites:
        t0 = time.perf_counter()
        before = Counter(report.counts)
        run(count, args.seed, report)
        got = report.counts - before
        print(f"{name}: {count} cases in {time.perf_counter() - t0:.0f} s — {dict(sorted(got.items()))}", flush=True)
    print(report.text())
    print(f"failures: {report.failures}")
    return 1 if report.failures else 0


if __name__ == "__main__":
    raise SystemExit(main())
