"""2D navigation costmap from the aligned opacity field (its query API: navcore.nav.costmap)."""
from stages.costmap.build import CostmapConfig, CostmapLayers, build_costmap

__all__ = ["CostmapConfig", "CostmapLayers", "build_costmap"]
