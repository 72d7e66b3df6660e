"""Whether background threads may help: the one rule the readers and writers follow."""

from __future__ import annotations

import os


def helpers_allowed() -> bool:
    """Whether a reader or writer may put work (decompression, encoding) on a background thread.

    Not on a single core, and not in a process told to use one thread (``OMP_NUM_THREADS=1``, which
    BLAS and Arrow honour too): fleet workers, mountcal's and Dask's, run that way, one process per
    core, and a helper thread there would only take the core of another worker.
    """
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return cores > 1 and os.environ.get("OMP_NUM_THREADS", "").strip() != "1"


__all__ = ["helpers_allowed"]
