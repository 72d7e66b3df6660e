"""Mutation fuzzing of the log readers: real log bytes, damaged, through the commands that read them.

Each case takes a log — the sample logs in ``data/`` (``parking.mcap``, ``.blf``, ``.mf4``) and the
shared real recordings (CANedge MF4s, the robot_localization ROS 2 MCAP), which are only read —
applies one mutation to a copy in a temporary directory, and runs ``inspect``, ``stops`` and
``calibrate`` on it. Mutations:

- ``truncate``: cut the file at a random byte;
- ``flip``: flip 1 to 16 random bits;
- ``splice``: overwrite a random span with bytes from elsewhere in the same file;
- ``size``: set a size field of the format (an MCAP record length or chunk size, a BLF object or
  container size, an MDF block length or DZ block size) to a large or wrong value.

Every command runs in its own process, forked from this one once mountcal is imported (so a case
costs the command, not the imports), with a time bound and a memory bound. Counted:
tracebacks (stderr containing ``Traceback``), hangs (killed at the time bound), peak RSS above the
bound (the process's ``ru_maxrss`` from ``wait4``; it is also killed at twice the bound), crashes
(killed by a signal: a segfault in a native library), and the exit codes. Run from the repository root::

    PYTHONPATH=src python benchmarks/fuzz_mutations.py --count 300 --seed 1

``run(count, seed, report)`` is the entry point for ``benchmarks/fuzz.py``.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import shutil
import signal
import struct
import sys
import tempfile
import time
import traceback
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "data"
REAL = Path(os.environ.get("MOUNTCAL_REAL_DATA", "/work/shared/data/real"))
TIME_BOUND_S = 60.0
RSS_BOUND_MB = 1024.0  # docs/reliability.md: peak RSS on any input, output small


@dataclass(frozen=True)
class Source:
    path: Path
    args: tuple[str, ...]  # reader options: the DBC and channel of a CAN log, a topic


def sources() -> list[Source]:
    """The logs to mutate: the sample logs, and the real recordings where they are present."""
    dbc = str(DATA / "imu_mm5_10.dbc")
    protocol = ("--protocol", str(DATA / "parking_protocol.csv"))
    out = [
        Source(DATA / "parking.mcap", protocol),
        Source(DATA / "parking.blf", ("--dbc", dbc, *protocol)),
        Source(DATA / "parking.mf4", ("--dbc", dbc, *protocol)),
    ]
    gnss = str(REAL / "canedge" / "dbc" / "gnss.dbc")
    real = [
        (REAL / "canedge" / "2F6913DB_desk_static_2022-01-06" / "00000001.MF4", ("--dbc", gnss)),
        (REAL / "canedge" / "3BA199E2_car_DK_2021-07-26" / "00000164" / "00000005-60FEB5A8.MF4", ("--dbc", gnss)),
        (
            REAL / "canedge" / "truck_j1939_fw01.07_0bit-channels" / "00000001.MF4",
            ("--dbc", str(REAL / "canedge" / "dbc" / "CSS-Electronics-SAE-J1939-DEMO.dbc")),
        ),
        (REAL / "robot_localization" / "test1_ros2_mcap" / "test1_ros2_mcap.mcap", ("--topic", "/imu/data")),
    ]
    out += [Source(p, args) for p, args in real if p.is_file()]
    return out


# --------------------------------------------------------------------------- mutations


def _size_fields(data: bytes, suffix: str) -> list[tuple[int, str]]:
    """Offsets and struct formats of the size fields the format declares."""
    fields: list[tuple[int, str]] = []
    if suffix == ".mcap":
        pos = 8
        while pos + 9 <= len(data) and len(fields) < 10_000:
            opcode, length = struct.unpack_from("<BQ", data, pos)
            fields.append((pos + 1, "<Q"))
            if opcode == 0x06 and pos + 9 + 32 <= len(data):  # chunk: uncompressed size, records length
                fields.append((pos + 9 + 16, "<Q"))
                (name_len,) = struct.unpack_from("<I", data, pos + 9 + 28)
                fields.append((pos + 9 + 32 + name_len, "<Q"))
            pos += 9 + length
    elif suffix == ".blf":
        at = data.find(b"LOBJ")
        while at >= 0 and len(fields) < 10_000:
            fields.append((at + 8, "<L"))
            if struct.unpack_from("<L", data, at + 12)[0] == 10:  # a log container: uncompressed size
                fields.append((at + 24, "<L"))
            at = data.find(b"LOBJ", at + 4)
    else:  # MDF: every block's length; DZ blocks' original and compressed sizes
        at = data.find(b"##")
        while at >= 0 and len(fields) < 10_000:
            if data[at + 2 : at + 4].isalpha() and data[at + 2 : at + 4].isupper():
                fields.append((at + 8, "<Q"))
                if data[at + 2 : at + 4] == b"DZ":
                    fields += [(at + 32, "<Q"), (at + 40, "<Q")]
            at = data.find(b"##", at + 2)
    return [(o, f) for o, f in fields if o + struct.calcsize(f) <= len(data)]


def mutate(data: bytes, suffix: str, rng: random.Random) -> tuple[bytes, str]:
    """One mutation of ``data`` and its description."""
    kind = rng.choice(["truncate", "flip", "splice", "size", "size"])
    n = len(data)
    if kind == "truncate":
        cut = rng.choice([rng.randrange(n), n - rng.randrange(1, 64)])
        return data[:cut], f"truncate at {cut} of {n}"
    if kind == "flip":
        out = bytearray(data)
        flips = [rng.randrange(n * 8) for _ in range(rng.randint(1, 16))]
        for bit in flips:
            out[bit // 8] ^= 1 << (bit % 8)
        return bytes(out), f"flip bits {flips[:4]}{'...' if len(flips) > 4 else ''}"
    if kind == "splice":
        length = rng.randint(1, min(4096, n))
        src, dst = rng.randrange(n - length + 1), rng.randrange(n - length + 1)
        return data[:dst] + data[src : src + length] + data[dst + length :], f"splice {length} bytes {src}->{dst}"
    fields = _size_fields(data, suffix)
    if not fields:
        return data[: n // 2], "truncate at half (no size field found)"
    offset, fmt = rng.choice(fields)
    (old,) = struct.unpack_from(fmt, data, offset)
    top = 2 ** (8 * struct.calcsize(fmt)) - 1
    new = rng.choice([old * 2, old * 1000, old + 1, max(old - 1, 0), 2**31, 2**32 - 1, top, rng.randrange(top)])
    new = min(new, top)
    out = bytearray(data)
    struct.pack_into(fmt, out, offset, new)
    return bytes(out), f"size field at {offset}: {old} -> {new}"


# --------------------------------------------------------------------------- running a command


@dataclass(frozen=True)
class Outcome:
    code: int | None  # None: killed
    stderr: str
    seconds: float
    peak_mb: float
    killed: str  # "", "time" or "memory"


def _rss_mb(pid: int) -> float:
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return 0.0


def run_command(argv: list[str], workdir: Path) -> Outcome:
    """``mountcal ARGV`` in a forked process, bounded in time and memory."""
    from mountcal.cli import main

    err_path = workdir / "stderr.txt"
    start = time.monotonic()
    pid = os.fork()
    if pid == 0:  # the child: the command, its stderr to a file, never back into the parent's code
        code = 1
        try:
            fd = os.open(err_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
            os.dup2(fd, 2)
            out = os.open(os.devnull, os.O_WRONLY)
            os.dup2(out, 1)
            code = main(argv)
        except SystemExit as exit_:
            code = exit_.code if isinstance(exit_.code, int) else 1
        except BaseException:
            traceback.print_exc()
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(code)
    killed = ""
    while True:
        done, status, usage = os.wait4(pid, os.WNOHANG)
        if done:
            break
        elapsed = time.monotonic() - start
        if not killed and elapsed > TIME_BOUND_S:
            killed = "time"
        elif not killed and _rss_mb(pid) > 2 * RSS_BOUND_MB:
            killed = "memory"
        if killed:
            os.kill(pid, signal.SIGKILL)
            _, status, usage = os.wait4(pid, 0)
            break
        time.sleep(0.02)
    seconds = time.monotonic() - start
    stderr = err_path.read_text(errors="replace") if err_path.exists() else ""
    code = os.waitstatus_to_exitcode(status) if not killed else None
    return Outcome(code, stderr, seconds, usage.ru_maxrss / 1024, killed)


def _commands(log: Path, source: Source, out: Path) -> list[list[str]]:
    reader = list(source.args)
    inspect_args = [a for a in reader if a != "--protocol" and not a.endswith("protocol.csv")]
    return [
        ["inspect", str(log), *[a for a in inspect_args if a not in ("--topic", "/imu/data")]],
        ["stops", str(log), *reader, "-o", str(out / "stops.csv")],
        ["calibrate", str(log), *reader, "-o", str(out / "result.json")],
    ]


# --------------------------------------------------------------------------- the run


def run(count: int, seed: int, report: Callable[[str], None]) -> dict[str, object]:
    """Fuzz ``count`` mutated logs (3 commands each); the counts, bounds and failures.

    A failure is a traceback, a hang past ``TIME_BOUND_S`` or a peak RSS above ``RSS_BOUND_MB``;
    each is listed with the source, the mutation and the command, to reproduce it.
    """

    rng = random.Random(seed)
    pool = sources()
    originals = {s.path: s.path.read_bytes() for s in pool}
    counts: Counter[str] = Counter()
    codes: Counter[str] = Counter()
    failures: list[dict[str, object]] = []
    peak, slowest = 0.0, 0.0
    workdir = Path(tempfile.mkdtemp(prefix="mountcal-fuzz-"))
    try:
        for case in range(count):
            source = rng.choice(pool)
            data, mutation = mutate(originals[source.path], source.path.suffix.lower(), rng)
            log = workdir / f"case{source.path.suffix}"
            log.write_bytes(data)
            for argv in _commands(log, source, workdir):
                outcome = run_command(argv, workdir)
                counts["commands"] += 1
                codes[str(outcome.code) if outcome.code is not None else f"killed ({outcome.killed})"] += 1
                peak, slowest = max(peak, outcome.peak_mb), max(slowest, outcome.seconds)
                problems = [
                    name
                    for name, hit in (
                        ("traceback", "Traceback" in outcome.stderr),
                        ("crash", outcome.code is not None and outcome.code < 0),  # killed by a signal
                        ("hang", outcome.killed == "time"),
                        ("memory", outcome.killed == "memory" or outcome.peak_mb > RSS_BOUND_MB),
                    )
                    if hit
                ]
                for name in problems:
                    counts[name] += 1
                if problems:
                    failures.append(
                        {
                            "case": case,
                            "source": str(source.path),
                            "mutation": mutation,
                            "command": argv[0],
                            "problems": problems,
                            "seconds": round(outcome.seconds, 1),
                            "peak_mb": round(outcome.peak_mb),
                            "stderr": outcome.stderr[-1500:],
                        }
                    )
                    report(f"case {case} {source.path.name} [{mutation}] {argv[0]}: {', '.join(problems)}")
            counts["cases"] += 1
            if (case + 1) % 25 == 0:
                report(f"{case + 1}/{count} cases, {counts['traceback']} tracebacks, {counts['crash']} crashes, "
                       f"{counts['hang']} hangs, "
                       f"{counts['memory']} over memory, peak {peak:.0f} MB, slowest {slowest:.1f} s")  # fmt: skip
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    return {
        "cases": counts["cases"],
        "commands": counts["commands"],
        "tracebacks": counts["traceback"],
        "crashes": counts["crash"],
        "hangs": counts["hang"],
        "over_memory": counts["memory"],
        "exit_codes": dict(codes),
        "peak_rss_mb": round(peak),
        "slowest_s": round(slowest, 1),
        "time_bound_s": TIME_BOUND_S,
        "rss_bound_mb": RSS_BOUND_MB,
        "sources": [str(s.path) for s in pool],
        "failures": failures,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", type=int, default=100, help="mutated logs (3 commands each)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", type=Path, help="write the full result (with failures) here")
    args = parser.parse_args()
    result = run(args.count, args.seed, lambda line: print(line, flush=True))
    if args.json:
        args.json.write_text(json.dumps(result, indent=1))
    summary = {k: v for k, v in result.items() if k not in ("failures", "sources")}
    print(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
