"""Config of the semantics stage (section `semantics`)."""
from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Optional

from navcore.labels.shipped import CleaningConfig
from navcore.nav.tasks import OBJECTNAV_CATEGORIES
from stages.semantics.detector import DetectorConfig
from stages.semantics.lifting import LiftingConfig
from stages.semantics.open_vocab import OpenVocabConfig
from stages.semantics.segmenters import CORRUPTION_LEVELS, Corruption


@dataclass
class OracleConfig:
    """The `oracle` segmenter: ground-truth masks of synthetic scenes, corrupted (segmenters.Corruption).

    `level` picks a preset (none | moderate | heavy, CORRUPTION_LEVELS); a rate set here overrides
    the preset's, e.g. semantics.oracle.miss_rate=0.25."""

    level: str = "moderate"
    """Corruption preset: none | moderate | heavy (segmenters.CORRUPTION_LEVELS)."""
    bleed_px: Optional[int] = None
    """Boundary bleeding: each mask dilated or eroded (sign at random) by up to this many pixels (null: the preset's)."""
    miss_rate: Optional[float] = None
    """Probability that an object is not detected in a frame (null: the preset's)."""
    confusion_rate: Optional[float] = None
    """Probability that a detected object is reported under another category (null: the preset's)."""
    fp_blobs: Optional[float] = None
    """Mean number (Poisson) of false-positive blobs per frame, under a random category (null: the preset's)."""
    fp_radius_px: Optional[int] = None
    """Radius of a false-positive disc, pixels (drawn in [r / 2, r]; null: the preset's)."""
    min_weight: float = 0.5
    """A pixel belongs to the instance whose composited label weight is largest, if at least this."""

    def corruption(self) -> Corruption:
        if self.level not in CORRUPTION_LEVELS:
            raise ValueError(f"semantics.oracle.level={self.level!r}; choose one of {sorted(CORRUPTION_LEVELS)}")
        base = CORRUPTION_LEVELS[self.level]
        return Corruption(**{f.name: getattr(self, f.name) if getattr(self, f.name) is not None
                             else getattr(base, f.name) for f in fields(Corruption)})


@dataclass
class Sam3Config:
    """The `sam3` segmenter (optional extra: pip install -e '.[sam3]'; weights: docs/tasks.md)."""

    checkpoint: Optional[str] = None
    """Local path of sam3.pt (never downloaded at run time)."""
    bpe_path: Optional[str] = None
    """CLIP BPE vocabulary (bpe_simple_vocab_16e6.txt.gz); default: next to the checkpoint."""
    device: str = "cuda"
    """Torch device the model runs on."""
    confidence: float = 0.5
    """Detections whose score (presence x box probability) is below this are dropped."""
    resolution: int = 1008
    """Input resolution of the model (frames are resized to it)."""
    batch: int = 8
    """Frames per forward pass of the image encoder."""


@dataclass
class CoverageConfig:
    """Free-space views chosen for coverage (semantics.view_selection=coverage): from the candidate
    lattice (spacing, yaw step), greedily the views that see the most of the scene's surfaces not
    yet seen `k` times from distinct directions (stages/semantics/poses.py, coverage_poses)."""

    k: int = 4
    """Sightings wanted of each surface voxel, from distinct directions; at least the lifting's
    min_support (3), or a voxel seen fewer times cannot be lifted. On 4 generated scenes (oracle,
    moderate corruption, lattice 1 m / 45 deg) k 2 kept 224 views and found 73 % of the objects,
    k 3 358 views and 90 %, k 4 463 views and 100 % (the default 1.5 m / 60 deg lattice: 1,284
    views, 100 %); docs/benchmarks/bench_semantics_views.md."""
    sectors: int = 8
    """Directions a voxel's sightings are told apart by: its bearing from the camera, in this many sectors."""
    max_range: float = 4.0
    """Metres: a voxel farther from the camera is not counted as seen (a detector needs objects near)."""
    cell: float = 0.2
    """Surface voxel side, metres."""
    z_min: float = 0.1
    """Surfaces from this height above the floor, metres."""
    z_max: float = 2.5
    """Surfaces up to this height, metres (goal objects stand below it)."""
    min_gain: float = 0.0005
    """Stop when the best next view adds fewer than this share of the wanted sightings (k x voxels)."""


@dataclass
class SemanticsConfig:
    """Stage `semantics`: ObjectNav goal candidates lifted from multi-view masks (stages/semantics)."""

    enabled: bool = True
    """Off: the stage writes no instance table (ObjectNav then needs instance_source=ground_truth)."""
    shipped_labels: bool = True
    """Use the ground-truth labels a real scene ships (SceneSplat instance.npy / segment.npy in its
    .npy folder, or an InteriorGS / NavArena labels.json beside it) instead of a segmenter."""
    labels: CleaningConfig = field(default_factory=CleaningConfig)
    """Cleaning of shipped per-Gaussian labels (largest cluster, tiny / unobserved / below-floor drops)."""
    goal_map: dict[str, str] = field(default_factory=dict)
    """Extra lines of the goal mapping table for every scene (dataset class -> goal category, e.g.
    {'ottoman': 'sofa'}); a catalog entry's labels.goal_map adds its own."""
    segmenter: str = "oracle"
    """Registry key (oracle | sam3 | open_vocab) or "module:Class"."""
    categories: list[str] = field(default_factory=lambda: list(OBJECTNAV_CATEGORIES))
    """Categories to find (the instance table's category names)."""
    prompts: dict[str, str] = field(default_factory=dict)
    """Open-vocabulary prompt per category (default: the category, '_' read as a space)."""
    poses: str = "auto"
    """Covering poses: source (the scene's capture cameras) | free_space (on free costmap cells at the
    embodiment's camera height, all around) | auto (source when the scene has cameras)."""
    spacing: float = 1.5
    """free_space: one position per spacing x spacing metres of free space (1.5 m with 60 degree
    headings found every object that 1 m / 45 degrees found, from 0.38 x the views:
    docs/benchmarks/bench_semantics_views.md; 2 m split objects into several instances)."""
    yaw_step_deg: float = 60.0
    """free_space: headings every this many degrees (full circle)."""
    view_selection: str = "grid"
    """free_space views: grid (every candidate of the lattice) | coverage (the fewest candidates
    that see every surface k times from distinct directions: semantics.coverage). Coverage is not
    the default: on the labelled ScanNet room the shipped detector boxes its bed in 2 % of the
    lattice's views, and the 28-230 views that cover the room lifted 0-1 of the 2 instances the
    924 lattice views lift (docs/own-capture.md, "Views chosen for coverage"). With a segmenter that finds an object
    from most views it sees it from, coverage cuts the views 10-100x (the hall: 26,844 -> 248)."""
    coverage: CoverageConfig = field(default_factory=CoverageConfig)
    """view_selection=coverage's settings."""
    max_views: int = 0
    """Keep at most this many views (evenly spread over the list; 0 = all)."""
    width: int = 320
    """Render width of the views, pixels (source cameras keep their field of view)."""
    height: int = 240
    """Render height of the views, pixels."""
    renderer: str = "auto"
    """auto (gsplat on CUDA, else the CPU renderer) | cpu | gsplat."""
    batch: int = 16
    """Views per render call."""
    min_alpha: float = 0.5
    """Pixels whose accumulated opacity is below this have no valid depth."""
    seed: int = 0
    """Seed of the oracle's corruption (stream per scene)."""
    lifting: LiftingConfig = field(default_factory=LiftingConfig)
    oracle: OracleConfig = field(default_factory=OracleConfig)
    sam3: Sam3Config = field(default_factory=Sam3Config)
    open_vocab: OpenVocabConfig = field(default_factory=OpenVocabConfig)
    detector: DetectorConfig = field(default_factory=DetectorConfig)
    """The `detector` segmenter: the shipped COCO detector, masks from rendered depth."""

    def vocabulary(self, scene=None):
        """The goal vocabulary of a scene: these categories, `goal_map`, and the catalog entry's own
        labels.goal_map (which wins)."""
        from navcore.labels import GoalVocabulary

        entry = dict(scene.labels.goal_map) if scene is not None and getattr(scene, "labels", None) else {}
        return GoalVocabulary(tuple(self.categories), {**self.goal_map, **entry})

    def prompt(self, category: str) -> str:
        return self.prompts.get(category, category.replace("_", " "))
