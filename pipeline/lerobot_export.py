"""Deprecated import path (one release): moved to navarena.lerobot (pipeline/ holds the orchestration only)."""
import warnings

from navarena.lerobot import *  # noqa: F401,F403

warnings.warn("pipeline.lerobot_export moved to navarena.lerobot; this alias goes in the next release",
              DeprecationWarning, stacklevel=2)
