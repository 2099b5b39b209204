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


def remove_stale_temporaries(final: Path) -> list[Path]:
    """Remove the ``.tmp-`` / ``.old-`` siblings of ``final`` left by dead writers on this host."""
    removed = []
    for p in final.parent.glob(f".tmp-{final.name}-*"):
        parts = p.name[len(f".tmp-{final.name}-"):].split("-")
        if len(parts) >= 3 and parts[0] == HOST and parts[1].isdigit() and not _alive(int(parts[1])):
            shutil.rmtree(p, ignore_errors=True)
            removed.append(p)
    for p in final.parent.glob(f".old-{final.name}-*"):
        pid = p.name.rsplit("-", 1)[-1]
        if pid.isdigit() and not _alive(int(pid)):
            shutil.rmtree(p, ignore_errors=True) if p.is_dir() else p.unlink(missing_ok=True)
            removed.append(p)
    return removed


def sweep_stale_temporaries(root: Path) -> list[Path]:
    """Remove every ``.tmp-*`` / ``.old-*`` under ``root`` left by a dead writer on this host (a
    killed run's partial outputs whose final name was never written again)."""
    removed = []
    for dirpath, dirnames, filenames in os.walk(root):
        for name in [d for d in dirnames if d.startswith((".tmp-", ".old-"))] + \
                [f for f in filenames if f.startswith((".tmp-", ".old-"))]:
            p = Path(dirpath) / name
            if name.startswith(".tmp-"):
                parts = name.split("-")
                # .tmp-{final name}-{host}-{pid}-{random}: the final name may hold '-'
                host_pid = [(parts[i], parts[i + 1]) for i in range(2, len(parts) - 1) if parts[i] == HOST]
                dead = bool(host_pid) and host_pid[-1][1].isdigit() and not _alive(int(host_pid[-1][1]))
            else:
                pid = name.rsplit("-", 1)[-1]
                dead = pid.isdigit() and not _alive(int(pid))
            if dead:
                shutil.rmtree(p, ignore_errors=True) if p.is_dir() else p.unlink(missing_ok=True)
                removed.append(p)
        dirnames[:] = [d for d in dirnames if not d.startswith((".tmp-", ".old-"))]
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
