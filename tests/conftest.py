import os
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("NUMBA_NUM_THREADS", "2")
# the real 3DGS samples live beside the project (../shared/data/real), never in it;
# NAVARENA_REAL_DATA points elsewhere
REAL_DIR = Path(os.environ.get("NAVARENA_REAL_DATA") or Path(__file__).resolve().parents[2] / "shared" / "data" / "real")
# the real trained indoor scenes (SOG, SPZ) beside them; NAVARENA_REAL_INDOOR_DATA points elsewhere
REAL_INDOOR_DIR = Path(os.environ.get("NAVARENA_REAL_INDOOR_DATA") or REAL_DIR.parent / "real_indoor")
PROJECT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def small_scene():
    from stages.synthetic.generate import SyntheticConfig, generate_scene

    return generate_scene(1, SyntheticConfig(num_gaussians=150_000))


@pytest.fixture
def rng():
    return np.random.default_rng(0)
