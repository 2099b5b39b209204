"""Atomic outputs: write into a temporary sibling, then rename into place.

A killed run leaves at most a ``.tmp-*`` sibling, never a half-written file or folder under
the final name, so a rerun never trusts partial output; the next write of the same output on the
same host removes the leftovers of writers that are no longer alive (the temporary's name carries
the writer's host and process id; a live writer's temporary is never touched).
"""
from __future__ import annotations

import contextlib
import os
import shutil
import socket
import tempfile
from pathlib import Path

HOST = socket.gethostname().replace("-", "_")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


TEMP_PREFIXES = (".tmp-", ".old-")
"""Names of atomic writes in progress: ``.tmp-{final name}-{host}-{pid}-{random}`` (the new
output) and ``.old-{final name}-{pid}`` (a folder being replaced)."""


def _dead_writers(name: str, final: str | None = None) -> bool:
    """Whether a temporary's writer was on this host and is gone. ``final``: the final name when
    known (else the host is looked for in the name, which may itself hold '-')."""
    if name.startswith(".tmp-"):
        if final is not None:
            parts = name[len(f".tmp-{final}-"):].split("-")
            host_pid = [(parts[0], parts[1])] if len(parts) >= 3 else []
        else:
            parts = name.split("-")
            host_pid = [(parts[i], parts[i + 1]) for i in range(2, len(parts) - 1) if parts[i] == HOST][-1:]
        return bool(host_pid) and host_pid[0][0] == HOST and host_pid[0][1].isdigit() and \
            not _alive(int(host_pid[0][1]))
    pid = name.rsplit("-", 1)[-1]
    return name.startswith(".old-") and pid.isdigit() and not _alive(int(pid))


def _remove(p: Path) -> None:
    shutil.rmtree(p, ignore_errors=True) if p.is_dir() else p.unlink(missing_ok=True)


def remove_stale_temporaries(final: Path) -> list[Path]:
    """Remove the ``.tmp-`` / ``.old-`` siblings of ``final`` left by dead writers on this host."""
    removed = []
    for prefix in TEMP_PREFIXES:
        for p in final.parent.glob(f"{prefix}{final.name}-*"):
            if _dead_writers(p.name, final.name):
                _remove(p)
                removed.append(p)
    return removed


def sweep_stale_temporaries(root: Path) -> list[Path]:
    """Remove every ``.tmp-*`` / ``.old-*`` under ``root`` left by a dead writer on this host (a
    killed run's partial outputs whose final name was never written again)."""
    removed = []
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            if name.startswith(TEMP_PREFIXES) and _dead_writers(name):
                _remove(Path(dirpath) / name)
                removed.append(Path(dirpath) / name)
        dirnames[:] = [d for d in dirnames if not d.startswith(TEMP_PREFIXES)]
    return removed


@contextlib.contextmanager
def atomic_path(final: str | Path):
    """Yield a temporary path beside ``final``; on success move it to ``final`` (replacing a
    previous file or folder), on error remove it.

    Works for files and folders (a Zarr store, an asset directory): the caller creates
    whatever it wants at the yielded path.
    """
    final = Path(final)
    final.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(final)
    tmp_dir = Path(tempfile.mkdtemp(prefix=f".tmp-{final.name}-{HOST}-{os.getpid()}-", dir=final.parent))
    tmp = tmp_dir / final.name
    try:
        yield tmp
        if not tmp.exists():
            raise FileNotFoundError(f"atomic write of {final} produced nothing at {tmp}")
        if final.is_dir() and not final.is_symlink():
            old = final.with_name(f".old-{final.name}-{os.getpid()}")
            os.replace(final, old)
            os.replace(tmp, final)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, final)
    finally:
        shutil.rmtree(tmp_dir, ignore_errors=True)


def write_text_atomic(path: str | Path, text: str) -> None:
    """Write a small text file atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)
