"""Fixtures shared by the test modules (they never import each other)."""
import os
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("NUMBA_NUM_THREADS", "2")
# make test runs two xdist workers on two cores, each with numba's and torch's OpenMP threads. Those
# threads busy-wait between parallel regions (libgomp's default), taking the cores the other worker
# computes on: with another process busy, the CPU renderer took 11.6 ms a 64x48 frame and a small
# network's forward pass 3.4 ms, against 6.8 and 1.0 ms with passive waiting (the default policy is
# faster on an idle machine, so this is for the workers only). Set before numba or torch starts OpenMP;
# the tests' subprocesses inherit it.
if int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")) > 1:
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
_PROJECT = Path(__file__).resolve().parents[1]
# the real 3DGS samples live beside the project (../shared/data/real), never in it;
# NAVARENA_REAL_DATA points elsewhere
_REAL_DIR = Path(os.environ.get("NAVARENA_REAL_DATA") or _PROJECT.parent / "shared" / "data" / "real")
# the real trained indoor scenes (SOG, SPZ) beside them; NAVARENA_REAL_INDOOR_DATA points elsewhere
_REAL_INDOOR_DIR = Path(os.environ.get("NAVARENA_REAL_INDOOR_DATA") or _REAL_DIR.parent / "real_indoor")
# real labelled indoor scans (SceneSplat-style .npy folders with dataset label ids) beside them
_REAL_LABELLED_DIR = Path(os.environ.get("NAVARENA_REAL_LABELLED_DATA") or _REAL_DIR.parent / "real_labelled")
GRID_RES, GRID_RADIUS = 0.05, 0.1
"""Cell size and robot radius of the hand-made grid costmaps."""


@pytest.fixture(scope="session")
def project_root() -> Path:
    return _PROJECT


@pytest.fixture(scope="session")
def real_dir() -> Path:
    return _REAL_DIR


@pytest.fixture(scope="session")
def real_indoor_dir() -> Path:
    return _REAL_INDOOR_DIR


@pytest.fixture(scope="session")
def scannet_scan() -> Path:
    """The real ScanNet scene0000_02 scan (NYU40 labels; ../shared/data/real_labelled), or skip."""
    p = _REAL_LABELLED_DIR / "scannet_scene0000_02"
    if not (p / "segment.npy").is_file():
        pytest.skip(f"real labelled data not present ({p}; see ../shared/data/real_labelled/README.md)")
    return p


@pytest.fixture(scope="session")
def torchvision_shim():
    """torchvision's Python part next to the CPU torch (scripts/torchvision_fix.py, which make setup
    installs as a start-up hook; with a matching torchvision this does nothing)."""
    from navarena_torchvision_fix import apply

    apply()


@pytest.fixture(scope="session")
def small_scene():
    from stages.synthesize.generate import SyntheticConfig, generate_scene

    return generate_scene(1, SyntheticConfig(num_gaussians=150_000))


@pytest.fixture
def rng():
    return np.random.default_rng(0)


NO_HELD_OUT = ("episodes.scene_splits.val_unseen=0", "episodes.scene_splits.test=0")
"""Overrides that hold no scene out of training (Hydra merges dicts: `scene_splits={}` keeps the defaults)."""
SMALL_SCENE = ("scenes.count=1", "scenes.num_gaussians=30000", "synthetic.layout.rooms_max=2",
               "synthetic.layout.room_size_max_m=4.4")
"""One generated scene of two rooms of at most 4.4 m and 30 k Gaussians: every stage's features at
a third of the time of 60 k Gaussians in the default layout (the costmap's fine pass, the screening
views and the episodes scale with the floor area; rendering and lifting with the Gaussians)."""


@pytest.fixture(scope="session")
def small_scene_overrides():
    """The overrides of the tests' generated scene (SMALL_SCENE, nothing held out)."""
    return [*SMALL_SCENE, *NO_HELD_OUT]


@pytest.fixture(scope="session")
def make_cfg():
    """cfg(root, *overrides): the pipeline config of one small synthetic scene, run in-process."""
    from hydra import compose, initialize_config_dir

    from pipeline.config import CONF_DIR, register_configs

    register_configs()

    def make(root, *overrides):
        with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
            # no scene held out (the default holds out 10 %: synth_0000, the only scene here, is val_unseen)
            return compose("config", overrides=[f"data_root={root}", "executor=sync", *SMALL_SCENE, *NO_HELD_OUT,
                                                *overrides])
    return make


@pytest.fixture(scope="session")
def grid_costmap():
    """costmap(free): a Costmap from a free-space grid (GRID_RES cells, radius GRID_RADIUS, margin 0):
    clearance = distance to the nearest occupied cell, components by size."""
    from scipy import ndimage

    from navcore.nav.costmap import Costmap

    def make(free: np.ndarray) -> Costmap:
        clearance = (ndimage.distance_transform_edt(free) * GRID_RES).astype(np.float32)
        valid = clearance >= GRID_RADIUS
        lab, n = ndimage.label(valid, structure=np.ones((3, 3)))
        sizes = ndimage.sum(valid, lab, range(1, n + 1))
        order = np.argsort(-sizes) + 1
        comp = np.zeros_like(lab)
        for new, old in enumerate(order, 1):
            comp[lab == old] = new
        return Costmap(clearance, (0.0, 0.0), GRID_RES, GRID_RADIUS, 0.0, comp.astype(np.int32))
    return make


@pytest.fixture(scope="session")
def room_with_door(grid_costmap):
    """4 m x 3 m room (walls one cell thick), a wall at x = 2 m with a door for y in [2.0, 2.8]."""
    free = np.ones((60, 80), bool)
    free[[0, -1], :] = free[:, [0, -1]] = False
    free[:, 40] = False
    free[40:56, 40] = True
    return grid_costmap(free)


@pytest.fixture(scope="session")
def ctx(room_with_door):
    """The evaluation SceneContext of room_with_door (no renderer)."""
    from navcore.eval.env import SceneContext
    from navcore.nav.embodiment import Embodiment
    from navcore.nav.geodesic import NavGraph

    cm = room_with_door
    return SceneContext(cm, NavGraph(cm, ~cm.occupancy), Embodiment(radius=cm.radius))


@pytest.fixture(scope="session")
def make_episode():
    """episode(start, goal, radius, geodesic, max_steps, **kw): a hand-made evaluation Episode."""
    import itertools

    from navcore.eval.episode import Episode

    ids = itertools.count()

    def make(start=(1.0, 0.5, 0.0), goal=(3.0, 0.5), radius=0.5, geodesic=2.0, max_steps=50, **kw):
        g = np.array(goal, float)
        # an id of its own for each episode (SceneContext caches distance fields by goal set, not by id)
        return Episode(kw.pop("episode_id", f"e{next(ids)}"), kw.pop("task", "pointnav"), start, g, g[None], radius,
                       geodesic, max_steps, goal_sources=g[None], **kw)
    return make


@pytest.fixture(scope="session")
def episode_run(tmp_path_factory, make_cfg):
    """The default graph through export on one generated scene: (root, overrides, summary)."""
    from pipeline.executor import execute

    root = tmp_path_factory.mktemp("episodes")
    over = ["stages=[export]", "task.pointnav.episodes_per_scene=30", "task.imagenav.episodes_per_scene=20",
            "task.objectnav.episodes_per_scene=20", "episodes.splits.train=0.75", "+episodes.splits.val_seen=0.25",
            "export.chunk_size=8"]
    summary = execute(make_cfg(root, *over))
    assert not summary["failures"], summary["failures"]
    return root, over, summary


@pytest.fixture(scope="session")
def copy_data_root():
    """copy(src, dest, *leave_out): a copy of a finished data root at dest (a data root holds no
    absolute path of its own: every marker and manifest is relative to it), less its run summaries,
    its locks and the entries matching the leave_out patterns (shutil.ignore_patterns)."""
    import shutil

    def copy(src: Path, dest: Path, *leave_out: str) -> None:
        shutil.copytree(src, dest, dirs_exist_ok=True, ignore=shutil.ignore_patterns("_runs", "_locks", *leave_out))
    return copy


SHARED_RUN_MODULES = sorted(p.stem for p in Path(__file__).parent.glob("test_*.py")
                            if "episode_run" in p.read_text(encoding="utf-8"))
"""The test modules using the session's episode_run data root: make test's --dist loadfile sends
them to one worker, which builds that root once for all of them (pytest_xdist_make_scheduler)."""


LONGEST_FIRST = ("test_docs_run", "episode_run")
"""The longest units of work, started first, one on each worker: the docs runner (10-12 minutes on a
2-core VM) and the episode_run modules. xdist's default order (the units with the most tests
first) started the docs runner last, which then ran alone at the end."""


def _unit(nodeid: str) -> str:
    stem = Path(nodeid.split("::", 1)[0]).stem
    return "episode_run" if stem in SHARED_RUN_MODULES else stem


def pytest_collection_modifyitems(config, items):
    """LONGEST_FIRST's units first, the others in file order (a stable sort): with --dist loadfile
    the scheduler below hands the units out in this order."""
    rank = {u: i for i, u in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(_unit(item.nodeid), len(rank)))


def pytest_xdist_make_scheduler(config, log):
    """--dist loadfile, except that the modules using `episode_run` are one unit of work, so that
    its pipeline run is made once rather than once on each worker (xdist's loadgroup cannot do
    this under pytest 9: its group suffix on the node ids no longer takes), and the units are handed
    out in the collection's order (pytest_collection_modifyitems), not by their number of tests."""
    if config.getvalue("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    config.option.loadscopereorder = False

    class LoadFileSharingTheEpisodeRun(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return _unit(nodeid)

    return LoadFileSharingTheEpisodeRun(config, log)


def pytest_sessionstart(session):
    """With several xdist workers (make test), compile the CPU kernels once before they start
    (pipeline.kernels, when their caches are missing or older than the sources): otherwise each
    worker and its Dask workers compile the same kernels at the same time on a fresh checkout."""
    import subprocess
    import sys

    cfg = session.config
    if hasattr(cfg, "workerinput") or not (getattr(cfg.option, "numprocesses", None) or 0) > 1:
        return
    # a failure here is not the session's: the tests that run those stages report it themselves
    if subprocess.run([sys.executable, "-m", "pipeline.kernels", "--if-stale"], cwd=_PROJECT).returncode:
        print("pipeline.kernels failed (above); the workers compile the kernels themselves")
