"""Configuration of scene and region screening (section `screen`): the quality layer's cues
(`screen.layer`, the stage `screen`) and what the episodes stage does with them."""
from __future__ import annotations

from dataclasses import dataclass, field

from stages.screen.quality import QualityConfig


@dataclass
class ScreenConfig:
    """Scene and region screening."""

    layer: QualityConfig = field(default_factory=QualityConfig)
    """The reconstruction-quality layer (stage `screen`; only this subsection is its config)."""
    avoid: bool = True
    """Episodes keep out of flagged cells: starts, goals, ObjectNav view points and every pose of
    the expert trajectory (rejections counted by reason); ImageNav goal views mostly blur are
    redrawn."""
    margin_m: float = 0.1
    """Episodes keep this far from flagged cells, metres."""
    goal_view_blur_max: float = 0.5
    """ImageNav: a goal view with more than this share of blur or hole pixels is never produced."""
    warn_below: float = 0.9
    """A scene whose quality score (the share of its valid cells not flagged) is below this gets
    the verdict warn ..."""
    reject_below: float = 0.5
    """... and below this reject."""
    reject: bool = False
    """Rejected scenes get no episodes (false: every scene is kept, the verdict is reported)."""
