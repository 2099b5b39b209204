"""2D navigation costmap from the aligned opacity field, and the query API every later stage uses."""
from stages.costmap.build import CostmapConfig, Embodiment, CostmapLayers, build_costmap
from stages.costmap.query import Costmap

__all__ = ["CostmapConfig", "Embodiment", "CostmapLayers", "build_costmap", "Costmap"]
