"""The task vocabulary: task types and the ObjectNav goal categories (the semantics stage finds
them, the episodes stage makes goals of them)."""
from __future__ import annotations

TASK_TYPES = ("pointnav", "imagenav", "objectnav")
OBJECTNAV_CATEGORIES = ["chair", "bed", "sofa", "toilet", "tv_monitor", "plant", "table", "cabinet"]
