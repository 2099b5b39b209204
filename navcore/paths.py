"""Paths read from files (a SOG meta.json's image names, an asset manifest's file names, a map's
image): they must stay inside the folder they are meant to point into, so that a shared scene,
catalog or release folder cannot make NavArena read (or write) elsewhere."""
from __future__ import annotations

from pathlib import Path


class PathEscapeError(ValueError):
    """A name read from a file points outside the folder it must stay in."""


def contained(folder: str | Path, name: str, where: str) -> Path:
    """folder / name, refused (PathEscapeError naming `where`) when the name is absolute or resolves,
    links followed, outside `folder`."""
    if not isinstance(name, str) or not name:
        raise PathEscapeError(f"{where}: {name!r} is not a file name")
    folder = Path(folder)
    p = folder / name
    if Path(name).is_absolute() or not p.resolve().is_relative_to(folder.resolve()):
        raise PathEscapeError(f"{where}: the name {name!r} points outside {folder} (an absolute path, '..' or a link "
                              "leading out); names in this file must stay inside its folder")
    return p


def usable_path(p: str, where: str) -> str:
    """A path a catalog names, refused when no file system could hold it (a NUL, a name over 255
    bytes, over 4,096 bytes in all) rather than failing later with an OSError."""
    if "\0" in p or len(p.encode()) > 4096 or any(len(c.encode()) > 255 for c in p.split("/")):
        raise ValueError(f"{where} is not a usable path (a NUL character, or a name too long): {p[:80]!r}")
    return p
