"""Structured config of the whole pipeline: one dataclass per stage (defaults live there, not in
YAML), registered in Hydra's ConfigStore as the schema that conf/config.yaml extends."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from hydra.core.config_store import ConfigStore

from navcore.gaussians.content import ContentConfig
from navcore.gaussians.floor import AlignConfig
from navcore.gaussians.validate import ValidationLimits
from navcore.nav.embodiment import Embodiment
from navcore.voxels.field import VoxelizeConfig
from pipeline.graph import DEFAULT_STAGES
from pipeline.release.config import ReleaseConfig
from stages.costmap.build import CostmapConfig
from stages.episodes.config import EpisodesConfig, PlannerConfig, TaskConfig
from stages.evaluate.config import EvaluateConfig
from stages.export.stage import ExportConfig
from stages.goal_images.stage import GoalImagesConfig
from stages.screen.config import ScreenConfig
from stages.semantics.config import SemanticsConfig
from stages.synthesize.generate import SyntheticConfig

CONF_DIR = Path(__file__).resolve().parent.parent / "conf"


@dataclass
class ScenesConfig:
    """Which scenes this run covers."""

    catalog: str = "catalogs/synthetic.yaml"
    """Catalog file, relative to the project root or absolute."""
    shard: int = 0
    """This run's shard index k (0-based)."""
    num_shards: int = 1
    """Number of shards n; shard k takes every n-th scene in scene-id order."""
    ids: list[str] | None = None
    """Only these scene ids or names (null = all)."""
    limit: int | None = None
    """At most this many scenes of the shard (null = all)."""
    count: int | None = None
    """Override the number of generated scenes of a synthetic catalog (null = the catalog's)."""
    num_gaussians: int | None = None
    """Override the Gaussians per generated synthetic scene (null = the catalog's)."""


@dataclass
class JobqueueConfig:
    """Batch jobs that host Dask workers (executor.kind = slurm or pbs, via dask-jobqueue)."""

    jobs: int = 4
    """Worker jobs to start."""
    cores: int = 8
    """Cores per job."""
    memory: str = "32GB"
    """Memory per job."""
    processes: int = 2
    """Worker processes per job (the cores are shared among them)."""
    walltime: str = "04:00:00"
    """Wall time per job."""
    queue: str | None = None
    """Partition / queue."""
    account: str | None = None
    """Accounting string."""
    job_extra_directives: list[str] = field(default_factory=list)
    """Extra #SBATCH / #PBS lines, e.g. ['--constraint=skylake']."""
    log_directory: str | None = None
    """Where the worker jobs write their logs."""
    gpus_per_job: int = 0
    """GPUs per worker job: > 0 requests them (SLURM --gres=gpu:N), starts one worker process per
    GPU (overriding processes) and pins each worker to its own GPU; GPU stages go to these
    workers only."""


@dataclass
class ExecutorConfig:
    """Where the tasks run."""

    kind: str = "local"
    """'local' (a distributed LocalCluster), 'address' (connect to executor.address), 'slurm' or
    'pbs' (workers in batch jobs, executor.jobqueue) or 'sync' (in this process, one task after
    another: debugging and tests)."""
    n_workers: int = 2
    """LocalCluster worker processes."""
    threads_per_worker: int = 1
    """Threads per worker (the numba kernels use their own threads)."""
    processes: bool = True
    """Workers are processes (true) or threads (false)."""
    memory_limit: str = "auto"
    """Per-worker memory limit of the LocalCluster."""
    allowed_failures: int = 5
    """Worker deaths a task survives (Dask reruns it elsewhere) before its scene fails: a death counts
    against every task the worker held, queued ones too, so a preemptible cluster needs a few."""
    address: str | None = None
    """tcp://host:port of an existing scheduler; setting it implies kind=address."""
    dashboard: bool = True
    """Start the Dask dashboard of a LocalCluster."""
    gpus: int | None = None
    """GPU workers of a local run, one per GPU, each pinned to its GPU (CUDA_VISIBLE_DEVICES):
    None = one per GPU the machine has (nvidia-smi, or CUDA_VISIBLE_DEVICES when set), 0 = none.
    With GPU workers the stages that declare a GPU go to them only, the others to the n_workers
    CPU workers (which see no GPU). kind=address: the number of workers started with
    `--resources GPU=1` (0 sends every task anywhere)."""
    jobqueue: JobqueueConfig = field(default_factory=JobqueueConfig)


@dataclass
class IngestConfig:
    """Scene ingest."""

    limits: ValidationLimits = field(default_factory=ValidationLimits)
    scale: float = 1.0
    """Multiplies positions and Gaussian sizes on read: the source's units -> metres (e.g. 0.01
    for centimetres). The run summary warns when a scene's measures look implausible for metres."""
    content: ContentConfig = field(default_factory=ContentConfig)
    """How the scene's content is told from floaters (kept out of voxelization and maps)."""
    lod_level: int | None = None
    """Level of detail of streamed SOG scenes (lod-meta.json; 0 = finest); null = the finest level
    whose files are all present."""
    store: str = "auto"
    """The canonical store: reference (the source's path and a checksum; the Gaussians are read
    from the source by every stage: no second copy), copy (a compressed Zarr copy: for sources on
    slow or remote storage) or auto (reference: the 1.5 M SOG room decodes in 1.6 s)."""


@dataclass
class AssetConfig:
    """NavArena V1 asset export."""

    write_compressed_splat: bool = False
    """Also write compressed.splat (optional in V1; 32 bytes a Gaussian, 0.47x an SH-0 INRIA PLY: a
    second copy of the aligned model, so off by default)."""
    source: str = "reference"
    """How the asset carries the original scene: reference (no second copy: source.ply is a hard
    link to the original when it is a local INRIA binary PLY; any other format's file(s) are hard
    linked under source/ with their own names and files.source_ply is null; a symbolic link where a
    hard link cannot be made), convert (source.ply in the INRIA layout whatever the format, for
    strict V1 readers: a compressed source's PLY is ~10x its bytes) or none."""
    aligned_format: str = "auto"
    """File of the aligned model: ply (aligned.ply, INRIA binary: what the V1 asset requires; 248
    bytes a Gaussian at SH degree 3), spz (aligned.spz, Niantic SPZ v4: 8-bit quantised attributes,
    24-bit positions at 1/4096 m, ZSTD streams; 10.8x smaller than the PLY for the real fungi room)
    or auto (spz when the original is compressed: SPZ, SOG, .splat, SuperSplat PLY; ply otherwise,
    so a PLY dataset's assets are strict V1). The manifest's files.aligned names it either way;
    files.aligned_ply is null for spz, and NavArena's tools load either. source: no file at all,
    the asset's link to the original (asset.source=reference) plus the manifest's
    aligned_from_source (how ingest read it, a checksum) and extrinsic matrix give the same
    Gaussians to the bit (navcore.io.asset_files.load_aligned): the smallest asset (a twentieth of
    its source on the real SOG room, with voxels and maps: docs/scale.md), read only by NavArena's
    tools; not with export.formats habitat, whose episodes name an aligned
    file."""
    labels: str = "model_predicted"
    """labels.json from: model_predicted (the semantics stage's instances) | ground_truth (synthetic
    scenes) | none."""


@dataclass
class NavArenaConfig:
    stages: list[str] = field(default_factory=lambda: list(DEFAULT_STAGES))
    """Stages to run (their missing or stale upstream stages run too); evaluate is not a default."""
    force: bool = False
    """Recompute the selected stages even when their markers are current; also lets the run recompute
    outputs of stages it does not name whose settings changed (without it such a run is refused,
    naming the keys that differ: pipeline.config_guard)."""
    data_root: str = "data"
    """Root of the data layout."""
    allow_failures: bool = False
    """Exit with status 0 even when some (stage, scene) failed. By default a run whose tasks failed
    (or that refused to overwrite outputs, see `force`) exits with status 1 after completing
    everything else; the run summary lists the failures either way."""
    verify: str = "size"
    """How a finished (stage, scene) is checked before it counts as done, its outputs against its
    marker's manifest and the outside files it was made from (a real scene's source, its label
    files) against the marker's record: size (every output present with its recorded size; every
    source with its recorded size and mtime, hashed only when those differ: a stat each), checksum
    (every output and source hashed: reads everything), none. A mismatch recomputes the stage for
    that scene (a changed source: that scene's stages from the one that reads it on)."""
    synthetic: SyntheticConfig = field(default_factory=SyntheticConfig)
    ingest: IngestConfig = field(default_factory=IngestConfig)
    voxelize: VoxelizeConfig = field(default_factory=VoxelizeConfig)
    align: AlignConfig = field(default_factory=AlignConfig)
    costmap: CostmapConfig = field(default_factory=CostmapConfig)
    screen: ScreenConfig = field(default_factory=ScreenConfig)
    """Scene and region screening: the quality layer (stage `screen`, `screen.layer`), the verdict
    and what episodes avoid."""
    semantics: SemanticsConfig = field(default_factory=SemanticsConfig)
    """ObjectNav goal candidates lifted from multi-view masks (stage `semantics`)."""
    asset: AssetConfig = field(default_factory=AssetConfig)
    episodes: EpisodesConfig = field(default_factory=EpisodesConfig)
    task: dict[str, TaskConfig] = field(default_factory=dict)
    """Tasks to generate, by name (config group `task`, several at once: task=[pointnav,objectnav])."""
    planner: PlannerConfig = field(default_factory=PlannerConfig)
    """Expert planner (config group `planner`)."""
    goal_images: GoalImagesConfig = field(default_factory=GoalImagesConfig)
    export: ExportConfig = field(default_factory=ExportConfig)
    evaluate: EvaluateConfig = field(default_factory=EvaluateConfig)
    """Closed-loop evaluation (stage `evaluate`, not in the default stages: stages=[evaluate])."""
    release: ReleaseConfig = field(default_factory=ReleaseConfig)
    """The release folder users download (`navarena release`, not a stage: it reads a finished root)."""
    embodiment: Embodiment = field(default_factory=Embodiment)
    scenes: ScenesConfig = field(default_factory=ScenesConfig)
    executor: ExecutorConfig = field(default_factory=ExecutorConfig)


def register_configs() -> None:
    cs = ConfigStore.instance()
    cs.store(name="navarena_schema", node=NavArenaConfig)


def unknown_keys_message(unknown: list[str]) -> str:
    return (f"unknown configuration key(s): {'; '.join(unknown)}. Every key: docs/configuration.md "
            f"(navarena run --cfg job prints the resolved config)")


def unknown_override_keys(overrides: list[str]) -> list[str]:
    """The keys of plain `key=value` command-line overrides that the schema does not know, with
    suggestions (see unknown_keys); checked before Hydra, whose own refusal names no close key.
    Group choices (`scenes=real_indoor`), `+`/`~` forms (checked after composition) and hydra.*
    keys pass."""
    tree: dict = {}
    for o in overrides:
        key, sep, _ = o.partition("=")
        if not sep or o.startswith(("-", "+", "~")) or key.startswith("hydra.") or "/" in key or "@" in key:
            continue
        node = tree
        parts = key.split(".")
        for part in parts[:-1]:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                break
        else:
            node.setdefault(parts[-1], None)
    return unknown_keys(tree)


def unknown_keys(cfg) -> list[str]:
    """Keys of a composed config that the schema does not know (`+evaluate.agnet=oracle` adds one
    Hydra accepts), each with the closest known key as a suggestion: ["evaluate.agnet (did you mean
    evaluate.agent?)"]. Free dicts of the schema (task names, goal maps, splits, ...) take any key."""
    import dataclasses
    import difflib
    import typing

    from omegaconf import OmegaConf

    data = OmegaConf.to_container(cfg, resolve=False) if not isinstance(cfg, dict) else cfg
    out: list[str] = []

    def walk(d: dict, cls: type, prefix: str) -> None:
        hints = typing.get_type_hints(cls)
        names = [f.name for f in dataclasses.fields(cls)]
        for k, v in d.items():
            if k not in names:
                near = difflib.get_close_matches(str(k), names, n=1, cutoff=0.6)
                out.append(f"{prefix}{k}" + (f" (did you mean {prefix}{near[0]}?)" if near else ""))
                continue
            tp = hints.get(k)
            if dataclasses.is_dataclass(tp) and isinstance(v, dict):
                walk(v, tp, f"{prefix}{k}.")
            elif typing.get_origin(tp) is dict and isinstance(v, dict):
                args = typing.get_args(tp)
                if len(args) == 2 and dataclasses.is_dataclass(args[1]):
                    for name, sub in v.items():
                        if isinstance(sub, dict):
                            walk(sub, args[1], f"{prefix}{k}.{name}.")

    walk(data, NavArenaConfig, "")
    return out
