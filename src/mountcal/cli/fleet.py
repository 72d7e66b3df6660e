"""``mountcal fleet INPUTS… -o fleet.parquet``: calibrate many logs of many vehicles, resumably."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path
from typing import Any

from mountcal.cli.options import (
    add_command,
    add_fit_options,
    add_log_options,
    detection,
    fit_options,
    log_options,
    print_json,
    progress_wanted,
    require,
)
from mountcal.cli.results import say
from mountcal.core.atomic import Terminated
from mountcal.core.ranges import Number
from mountcal.core.terminal import safe

log = logging.getLogger("mountcal")


def add_parser(sub: Any) -> None:
    p = add_command(
        sub,
        "fleet",
        "calibrate many logs of many vehicles: consensus per vehicle, remounts",
        json_help="the run's summary (logs, vehicles, failures, outputs) as JSON on stdout",
        inputs=(
            "INPUTS",
            "folders of logs, globs, manifest CSVs or storage URLs (s3://bucket/LOG); see --layout",
        ),
        reads={"what": "a folder, log, manifest or URL", "folders": True, "globs": True},
        output="per-log Parquet table (vehicles go to <stem>_vehicles)",
        output_required=True,
        writes={"what": "the fleet table", "writes": _writes},
    )
    p.add_argument(
        "--workers", type=Number("workers"), default=None, help="local worker processes (default: all cores)"
    )
    p.add_argument("--scheduler", default=None, help="run on this Dask scheduler, tcp://HOST:PORT")
    p.add_argument(
        "--layout",
        choices=("auto", "canedge", "folders", "manifest"),
        default="auto",
        help="how folders map to vehicles and logs: canedge (<device>/<session>/<split>.MF4, a session's splits "
        "joined), folders (each file a log of its parent folder's vehicle), manifest (CSVs only); "
        "default: inferred from the names",
    )
    p.add_argument(
        "--storage-option",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="an fsspec option for storage URLs, e.g. endpoint_url=http://HOST:9000 (repeatable; "
        "credentials also come from the AWS variables and profiles)",
    )
    p.add_argument("--retry-failed", action="store_true", help="recalculate logs an earlier run recorded as failed")
    p.add_argument(
        "--floor-deg",
        type=Number("floor_deg"),
        default=0.0,
        help="mounting scatter between logs added to each log's σ (deg)",
    )
    p.add_argument(
        "--require-confident", action="store_true", help="refuse (write no table) if a log's result is not confident"
    )
    add_log_options(p, repeat_dbc=False, protocol=False)
    g = p.add_argument_group("fit of every log (a manifest's cells take precedence)")
    add_fit_options(g, headings_help="beta_deg of stop tables: from uphill (default), relative, or none")
    p.set_defaults(run=run, protocol=None)


def _writes(value: str, _: argparse.Namespace) -> list[tuple[str, str]]:
    """The per-log table and the per-vehicle table beside it (the part files' folder is checked by its store)."""
    from mountcal.fleet import outputs_of

    table, vehicles = outputs_of(value)[:2]
    return [(str(table), ""), (str(vehicles), f"{value}, writing")]


def run(args: argparse.Namespace) -> int:
    from mountcal.fleet import FleetOptions, JobDefaults, collect_jobs, outputs_of, run_fleet, summary_lines
    from mountcal.fleet.storage import parse_storage_options

    if args.scheduler is not None:
        require("distributed", "fleet", "fleet --scheduler")  # before any log is read or hashed
    defaults = JobDefaults(
        log=log_options(args),
        detection=detection(args),
        uphill_azimuth_deg=args.uphill_azimuth_deg,
        options=fit_options(args),
        headings=args.headings,
        use=args.use,
    )
    ours: list[Path] = []
    discarded: dict[str, int] = {}
    jobs = collect_jobs(
        args.input,
        defaults,
        exclude=outputs_of(args.output),
        set_aside=ours,
        layout=args.layout,
        storage_options=parse_storage_options(args.storage_option),
        discarded=discarded,
    )
    if ours:
        listed = ", ".join(map(str, ours[:5])) + (" …" if len(ours) > 5 else "")
        log.info("%s", safe(f"set aside {len(ours)} file(s) mountcal wrote (fleet tables, rotated logs): {listed}"))
    for reason, n in discarded.items():
        log.warning("%s", safe(f"set aside {n} {reason}"))
    options = FleetOptions(
        workers=args.workers,
        scheduler=args.scheduler,
        retry_failed=args.retry_failed,
        progress=progress_wanted(args),
        floor_deg=args.floor_deg,
        require_confident=args.require_confident,
    )
    try:
        result = run_fleet(jobs, args.output, options, set_aside=discarded)
    except KeyboardInterrupt as err:  # Ctrl-C, or SIGTERM/SIGHUP (Terminated): the workers are stopped
        how = f"terminated by {err}" if isinstance(err, Terminated) else "interrupted"
        log.error(
            "%s; the logs finished so far are kept in %s: run the same command again to resume",
            how,
            outputs_of(args.output)[2],
        )
        return 128 + err.signum if isinstance(err, Terminated) else 130
    if result.not_confident:
        listed = ", ".join(result.not_confident[:5]) + (" …" if len(result.not_confident) > 5 else "")
        log.warning(
            "%s",
            safe(
                f"{len(result.not_confident)} log(s) not confident (flag not_confident; recorded "
                f"in the tables' metadata, mountcal.not_confident_logs): {listed}"
            ),
        )
    first, *rest = summary_lines(result)
    confident = f"; {len(result.not_confident)} not confident" if result.not_confident else ""
    details = [
        line.strip()
        for line in rest
        if not line.startswith("wrote ") and not line.startswith("  set aside: ")  # said as "wrote", as a warning
    ]
    say(safe(first.replace("mountcal fleet — ", "fleet: ", 1) + confident), [safe(line) for line in details])
    log.info("%s", safe(rest[-1]))  # what was written
    if args.json:
        status = result.logs["status"].value_counts().to_dict()
        print_json(
            {
                "output": str(result.output),
                "vehicles_output": str(result.vehicles_path),
                "logs": len(result.logs),
                "status": {str(k): int(v) for k, v in status.items()},
                "vehicles": len(result.vehicles),
                "layout": result.layout,
                "sessions": result.sessions,
                "splits": result.splits,
                "vehicles_not_confident": [
                    str(row.vehicle_id) for row in result.vehicles.itertuples() if not row.latest_confident
                ],
                "computed": result.computed,
                "reused": result.reused,
                "engine": result.engine,
                "engine_notes": list(result.engine_notes),
                "elapsed_s": result.elapsed_s,
                "discarded": result.discarded,
                "not_confident": list(result.not_confident),
            }
        )
    return 0
