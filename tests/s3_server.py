"""A real S3-compatible server for the fleet's tests: moto's standalone server on 127.0.0.1 (as s3fs's own tests
run it), with a folder uploaded to a bucket, and the AWS variables a user sets pointing at it while it runs."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pandas as pd
import pytest


@contextlib.contextmanager
def s3_server(folder: Path, bucket: str, prefix: str = "LOG") -> Iterator[tuple[dict[str, str], Any]]:
    """The server with ``folder`` uploaded to ``s3://<bucket>/<prefix>``: the environment it set, and an s3fs
    filesystem on it. Each module uses its own bucket: moto keeps one store per process."""
    pytest.importorskip("s3fs")
    server_module = pytest.importorskip("moto.server")
    server = server_module.ThreadedMotoServer(ip_address="127.0.0.1", port=0, verbose=False)
    server.start()
    host, port = server.get_host_and_port()
    env = {
        "AWS_ENDPOINT_URL": f"http://{host}:{port}",
        "AWS_ACCESS_KEY_ID": "testing",
        "AWS_SECRET_ACCESS_KEY": "testing",
        "AWS_DEFAULT_REGION": "us-east-1",
    }
    saved = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    import s3fs

    try:
        fs = s3fs.S3FileSystem(endpoint_url=env["AWS_ENDPOINT_URL"])
        fs.mkdir(bucket)
        fs.put(str(folder), f"{bucket}/{prefix}", recursive=True)
        yield env, fs
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        server.stop()
        s3fs.S3FileSystem.clear_instance_cache()  # fsspec keys filesystems by arguments, not the environment


def comparable(frame: pd.DataFrame, prefix: str) -> pd.DataFrame:
    """A fleet table with the storage's names mapped away (``prefix``: the URL or folder its logs were listed
    under) and what differs by design (timings, content keys) dropped: the same fleet from a bucket and from disk
    compare equal."""
    out = frame.drop(columns=[c for c in ("elapsed_s", "content_hash") if c in frame]).copy()
    for column in ("log", "first_log", "last_log", "since_log", "disagreeing_logs"):
        if column in out:
            out[column] = out[column].map(
                lambda v: [x.replace(prefix, "") for x in v] if not isinstance(v, str) else v.replace(prefix, "")
            )
    return out
