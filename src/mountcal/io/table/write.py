"""Samples to tables, streamed: one chunk per :meth:`write` call, so memory does not grow with the log.

- :class:`ParquetSamples`: ``pyarrow.parquet.ParquetWriter``, one row group per chunk; columns
  ``t_s, ax, ay, az`` (and ``gx, gy, gz``) in s, m/s², rad/s; the frame and the calibration in the
  file's key-value metadata.
- :class:`CsvSamples`: the same columns as CSV (pyarrow's writer: shortest round-trip decimal, so
  the numbers read back exactly), then a column ``frame`` holding the frame's word in every row (a CSV
  has no metadata; the table reader recognises it, :mod:`mountcal.io.frame`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import BinaryIO

import numpy as np
import pyarrow as pa
import pyarrow.csv as pa_csv
import pyarrow.parquet as pq

from mountcal.io.frame import FRAME_COLUMN
from mountcal.io.samples import FloatArray

ACC_COLUMNS = ("ax", "ay", "az")


GYRO_COLUMNS = ("gx", "gy", "gz")


def _table(t_s: FloatArray, acc: FloatArray, gyro: FloatArray | None, schema: pa.Schema) -> pa.Table:
    columns = [t_s, acc[:, 0], acc[:, 1], acc[:, 2]]
    if gyro is not None:
        columns += [gyro[:, 0], gyro[:, 1], gyro[:, 2]]
    return pa.Table.from_arrays([pa.array(np.ascontiguousarray(c, dtype=np.float64)) for c in columns], schema=schema)


def _schema(gyro: bool, metadata: Mapping[str, str], descriptions: Mapping[str, str] | None = None) -> pa.Schema:
    names = ["t_s", *ACC_COLUMNS, *(GYRO_COLUMNS if gyro else ())]
    said = descriptions or {}
    return pa.schema(
        [pa.field(n, pa.float64(), metadata={"description": said[n]} if n in said else None) for n in names],
        metadata=dict(metadata),
    )


class ParquetSamples:
    """Samples to a Parquet file, one row group per :meth:`write` call.

    Parameters
    ----------
    file : binary file
        Where to write (from :func:`mountcal.core.atomic.atomic_output`).
    gyro : bool
        Whether the rows carry ``gx, gy, gz``.
    metadata : mapping of str to str
        Stored in the file's key-value metadata (frame, conventions, calibration).
    descriptions : mapping of column name to str, optional
        Each column's meaning, stored in its field metadata under ``description``.
    """

    def __init__(
        self,
        file: BinaryIO,
        gyro: bool,
        metadata: Mapping[str, str],
        descriptions: Mapping[str, str] | None = None,
    ) -> None:
        self.schema = _schema(gyro, metadata, descriptions)
        self.gyro = gyro
        # Float columns: no dictionary (it only costs time), byte-stream split + zstd (fast, small).
        self._writer = pq.ParquetWriter(
            file, self.schema, compression="zstd", use_dictionary=False, use_byte_stream_split=True
        )

    def write(self, t_s: FloatArray, acc: FloatArray, gyro: FloatArray | None) -> None:
        """Append rows: ``t_s`` (m,) s, ``acc`` (m, 3) m/s², ``gyro`` (m, 3) rad/s."""
        self._writer.write_table(_table(t_s, acc, gyro if self.gyro else None, self.schema))

    def close(self) -> None:
        self._writer.close()


class CsvSamples:
    """Samples to a CSV file (header line, then rows), written chunk by chunk.

    Parameters
    ----------
    file : binary file
        Where to write.
    gyro : bool
        Whether the rows carry ``gx, gy, gz``.
    frame : str
        The word written in the last column, ``frame``, of every row (``vehicle``, ``levelled``): what
        the file's samples are in, where a Parquet file has its metadata.
    """

    def __init__(self, file: BinaryIO, gyro: bool, frame: str) -> None:
        self._numbers = _schema(gyro, {})
        self.schema = self._numbers.append(pa.field(FRAME_COLUMN, pa.string()))
        self.gyro = gyro
        self.frame = frame
        # Unquoted: the numbers never are, and the word needs no quotes (8 bytes a row, not 10).
        self._writer = pa_csv.CSVWriter(file, self.schema, write_options=pa_csv.WriteOptions(quoting_style="none"))

    def write(self, t_s: FloatArray, acc: FloatArray, gyro: FloatArray | None) -> None:
        """Append rows: ``t_s`` (m,) s, ``acc`` (m, 3) m/s², ``gyro`` (m, 3) rad/s."""
        rows = _table(t_s, acc, gyro if self.gyro else None, self._numbers)
        self._writer.write_table(rows.append_column(self.schema.field(FRAME_COLUMN), pa.repeat(self.frame, len(t_s))))

    def close(self) -> None:
        self._writer.close()


__all__ = ["ACC_COLUMNS", "GYRO_COLUMNS", "CsvSamples", "ParquetSamples"]
