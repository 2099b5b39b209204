"""Per-task locks: two runs on one data root (two shards sharing a scene by mistake, the same run
started twice, a resubmitted job overlapping its predecessor) never write one output at the same
time. A task takes `_locks/{stage}/{key}.lock` (fcntl.flock, exclusive) before it looks at its
marker; a second run's task waits for the first to finish and then finds the marker current
(cached). The lock is the kernel's: a killed holder releases it, nothing stale remains. On a
shared filesystem flock must work across hosts (NFSv4, Lustre mounted with -o flock, GPFS); where
it does not, shards (disjoint by construction) remain safe, identical concurrent runs are not."""
from __future__ import annotations

import contextlib
import fcntl
import os
import time
from pathlib import Path

from navcore.io.atomic import HOST


@contextlib.contextmanager
def locked(path: Path):
    """Hold an exclusive lock on `path` (created if missing); yields the seconds spent waiting."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    t0 = time.perf_counter()
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            fcntl.flock(fd, fcntl.LOCK_EX)  # another run holds it: wait for it
        waited = time.perf_counter() - t0
        os.ftruncate(fd, 0)
        os.write(fd, f"{HOST} {os.getpid()}\n".encode())
        yield waited
    finally:
        os.close(fd)  # releases the lock


@contextlib.contextmanager
def try_locked(path: Path):
    """Hold the lock of `path` if nobody does; yields whether it was taken (never waits)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            yield False
            return
        yield True
    finally:
        os.close(fd)
