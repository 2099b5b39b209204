"""The task vocabulary: task types and the ObjectNav goal categories (the semantics stage finds
them, the episodes stage makes goals of them; navcore.labels maps dataset classes onto them)."""
from __future__ import annotations

from navcore.labels import GOAL_CATEGORIES

TASK_TYPES = ("pointnav", "imagenav", "objectnav")
OBJECTNAV_CATEGORIES = list(GOAL_CATEGORIES)
