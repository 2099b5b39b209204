"""Deprecated import path (one release): moved to navarena.render_episodes (pipeline/ holds the orchestration only)."""
import warnings

from navarena.render_episodes import *  # noqa: F401,F403

warnings.warn("pipeline.render_episodes moved to navarena.render_episodes; this alias goes in the next release",
              DeprecationWarning, stacklevel=2)
