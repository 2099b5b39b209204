"""Deprecated import path (one release): the catalog moved to navcore.io.catalog, beside the
dataset readers it hands out, so that tools reading a finished dataset need nothing of the
orchestration."""
import warnings

from navcore.io.catalog import *  # noqa: F401,F403
from navcore.io.catalog import LAYOUT_FILE, SAFE_COMPONENT, Catalog, SceneEntry, safe_component, scene_id_for  # noqa: F401

warnings.warn("pipeline.catalog moved to navcore.io.catalog; this alias goes in the next release",
              DeprecationWarning, stacklevel=2)
