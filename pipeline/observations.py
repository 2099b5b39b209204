"""Deprecated import path (one release): moved to navarena.observations (pipeline/ holds the orchestration only)."""
import warnings

from navarena.observations import *  # noqa: F401,F403

warnings.warn("pipeline.observations moved to navarena.observations; this alias goes in the next release",
              DeprecationWarning, stacklevel=2)
