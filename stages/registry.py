"""Implementations chosen by a key in config (habitat-lab's registry habit), or by "module:Class"."""
from __future__ import annotations

import importlib


class Registry(dict):
    """key -> class; fill with the `register(key)` decorator, build with `make(spec, **kwargs)`."""

    def __init__(self, kind: str):
        super().__init__()
        self.kind = kind

    def register(self, key: str):
        def deco(cls):
            self[key] = cls
            return cls
        return deco

    def get_class(self, spec: str):
        """The class of a registry key or of an import path "package.module:Class"."""
        if ":" in spec:
            mod, cls = spec.split(":", 1)
            return getattr(importlib.import_module(mod), cls)
        if spec not in self:
            raise ValueError(f"unknown {self.kind} {spec!r}; registered: {', '.join(sorted(self))} (or module:Class)")
        return self[spec]

    def make(self, spec: str, **kwargs):
        """An instance from a registry key or an import path "package.module:Class"."""
        return self.get_class(spec)(**kwargs)
