"""The canonical in-memory 3DGS scene, its file formats and its Zarr store."""
from stages.gaussians.model import GaussianScene, SH_C0, quat_to_rotmat, rotmat_to_quat
from stages.gaussians.errors import SceneFormatError

__all__ = ["GaussianScene", "SH_C0", "quat_to_rotmat", "rotmat_to_quat", "SceneFormatError"]
