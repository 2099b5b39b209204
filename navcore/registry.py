"""One registry mechanism for every pluggable implementation: agents, segmenters, planners,
metrics and file formats.

A registry maps a key to a lazy ``"package.module:attr"`` entry, imported on first use only, so
listing what exists never imports torch, sam3 or OMPL. A spec that is not a key may itself be a
``"module:attr"`` path (a user's own agent or segmenter), resolved the same way.
"""
from __future__ import annotations

import importlib
from typing import Any, Iterator, Mapping


def load_entry(spec: str) -> Any:
    """The object named by ``"package.module:attr"`` (``attr`` may be dotted)."""
    mod, _, attr = spec.partition(":")
    if not mod or not attr:
        raise ValueError(f"{spec!r} is not a 'package.module:attr' path")
    obj: Any = importlib.import_module(mod)
    for part in attr.split("."):
        obj = getattr(obj, part)
    return obj


class Registry(Mapping[str, Any]):
    """key -> lazily imported object (class or function).

    Args:
        kind: what the registry holds, for error messages ("agent", "metric", ...).
        entries: key -> "package.module:attr", in the order listings show them.
    """

    def __init__(self, kind: str, entries: Mapping[str, str]):
        self.kind = kind
        self.entries = dict(entries)
        self._loaded: dict[str, Any] = {}

    def __getitem__(self, key: str) -> Any:
        if key not in self.entries:
            raise KeyError(key)
        if key not in self._loaded:
            self._loaded[key] = load_entry(self.entries[key])
        return self._loaded[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self.entries)

    def __len__(self) -> int:
        return len(self.entries)

    def get_class(self, spec: str) -> Any:
        """The object of a key, or of a "package.module:attr" path given instead of a key."""
        if spec in self.entries:
            return self[spec]
        if ":" in spec:
            return load_entry(spec)
        raise ValueError(f"unknown {self.kind} {spec!r}; registered: {', '.join(self.entries)} (or module:Class)")

    def make(self, spec: str, **kwargs) -> Any:
        """An instance (or call result) of a key or a "package.module:attr" path."""
        return self.get_class(spec)(**kwargs)
