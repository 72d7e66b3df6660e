"""An output's suffix means its format: the one check, :func:`check_output_suffix`.

Each output declares the suffixes of the formats it writes (``rotate -o``: ``.parquet .pq .csv
.mcap``). A name ending in the suffix of another data format is refused before anything is
written — ``rotate -o out.blf`` would hold Parquet under a BLF name, which the next tool then
misreads. A name without a suffix, or with one that names no data format (``.out``, ``.v2``), is
written in the declared format (the first one unless the writer is told another).

Called by the writers that pick a format from the name (:func:`mountcal.apply.rotate_log.rotate_log`,
:func:`mountcal.stops.table.write_stop_table`, :meth:`mountcal.core.result.Calibration.save`, ...) and,
before any work, by the command line from each output option's declared suffixes.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from mountcal.core.errors import InputError

# suffixes that say what a file holds: the formats of logs, tables, documents and archives
DATA_SUFFIXES: dict[str, str] = {
    ".json": "JSON",
    ".jsonl": "JSON lines",
    ".ndjson": "JSON lines",
    ".csv": "CSV",
    ".tsv": "TSV",
    ".parquet": "Parquet",
    ".pq": "Parquet",
    ".feather": "Feather",
    ".arrow": "Arrow",
    ".xlsx": "Excel",
    ".h5": "HDF5",
    ".hdf5": "HDF5",
    ".npy": "NumPy",
    ".npz": "NumPy",
    ".mcap": "MCAP",
    ".bag": "ROS bag",
    ".db3": "ROS 2 bag",
    ".blf": "BLF",
    ".asc": "ASC",
    ".log": "candump log",
    ".trc": "TRC",
    ".mf4": "MF4",
    ".mdf": "MDF",
    ".dbc": "DBC",
    ".toml": "TOML",
    ".yaml": "YAML",
    ".yml": "YAML",
    ".xml": "XML",
    ".xacro": "Xacro",
    ".sh": "shell script",
    ".urdf": "URDF",
    ".ubx": "UBX",
    ".html": "HTML",
    ".htm": "HTML",
    ".pdf": "PDF",
    ".png": "PNG",
    ".svg": "SVG",
    ".zip": "ZIP",
    ".gz": "gzip",
    ".bz2": "bzip2",
    ".xz": "xz",
    ".zst": "Zstandard",
    ".txt": "plain text",
}


def check_output_suffix(option: str, path: str | os.PathLike[str], suffixes: Sequence[str]) -> str:
    """The suffix of the format ``path`` will be written in: its own when ``option`` writes it, the
    first of ``suffixes`` when the name says no format.

    Parameters
    ----------
    option : str
        The option in messages (``"rotate -o"``).
    path : path
        The output's name.
    suffixes : sequence of str
        The suffixes of the formats the option writes, lower case with the dot, the default first.

    Raises
    ------
    InputError
        The name ends in the suffix of another data format.
    """
    suffix = Path(path).suffix.lower()
    if suffix in suffixes:
        return suffix
    if suffix not in DATA_SUFFIXES:
        return suffixes[0]
    writes = ", ".join(dict.fromkeys(f"{DATA_SUFFIXES.get(s, s)} ({s})" for s in suffixes))
    raise InputError(
        f"{option} {path}",
        f"a name ending in the suffix of what it writes: {writes}",
        f"a name ending in {suffix}, which says {DATA_SUFFIXES[suffix]}",
        f"Name the output {Path(path).with_suffix(suffixes[0]).name} (mountcal does not write {DATA_SUFFIXES[suffix]} "
        "there; a file named for one format and holding another is misread by the next tool).",
    )


__all__ = ["DATA_SUFFIXES", "check_output_suffix"]
