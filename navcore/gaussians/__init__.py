"""The canonical in-memory 3DGS scene, its file formats and its Zarr store."""
from navcore.gaussians.errors import SceneFormatError
from navcore.gaussians.model import SH_C0, GaussianScene, quat_to_rotmat, rotmat_to_quat

__all__ = ["GaussianScene", "SH_C0", "quat_to_rotmat", "rotmat_to_quat", "SceneFormatError"]
