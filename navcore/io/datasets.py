"""Typed datasets: the one place where stored files are opened (Kedro's habit).

The catalog maps a logical name (``costmaps``, ``episodes``, ...) to a path template and one of
the types below (navcore/io/layout.yaml); a stage asks ``catalog.dataset("costmaps", scene)`` and
calls ``load()`` / ``save(...)`` (or ``writing()`` for outputs written piece by piece). Every
save is atomic: the data goes to a temporary sibling that is renamed into place at the end, so a
killed run never leaves a half-written file or folder under the final name.
"""
from __future__ import annotations

import contextlib
import json
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from navcore.io import jsonio
from navcore.io.atomic import atomic_path, write_text_atomic
from navcore.io.codecs import array_codecs


class Dataset:
    """One stored dataset at a resolved path."""

    def __init__(self, path: str | Path):
        self.path = Path(path)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({str(self.path)!r})"

    def exists(self) -> bool:
        return self.path.exists()

    def load(self) -> Any:  # pragma: no cover - every type defines it
        raise NotImplementedError

    @contextlib.contextmanager
    def writing(self) -> Iterator[Path]:
        """A temporary path to build the dataset at; renamed into place when the block ends
        without error, removed otherwise."""
        with atomic_path(self.path) as tmp:
            yield tmp


class JSONDataset(Dataset):
    """A JSON document (reports, alignment, markers)."""

    def load(self) -> Any:
        return json.loads(self.path.read_text())

    def load_or(self, default: Any = None) -> Any:
        """The document, or ``default`` when it does not exist."""
        return self.load() if self.path.exists() else default

    def save(self, obj: Any, indent: int | None = 1, **dumps_kwargs) -> None:
        write_text_atomic(self.path, jsonio.dumps(obj, indent=indent, **dumps_kwargs))


class JSONGzDataset(Dataset):
    """A gzipped JSON document (Habitat episode files): compact, gzip mtime 0 (same bytes)."""

    def load(self) -> Any:
        import gzip

        return json.loads(gzip.decompress(self.path.read_bytes()))

    def save(self, obj: Any) -> None:
        import gzip

        with atomic_path(self.path) as tmp, open(tmp, "wb") as f, gzip.GzipFile(fileobj=f, mode="wb", mtime=0) as g:
            g.write(jsonio.dumps(obj).encode())

    def delete(self) -> None:
        self.path.unlink(missing_ok=True)


class TextDataset(Dataset):
    """A text file (Markdown tables)."""

    def load(self) -> str:
        return self.path.read_text()

    def save(self, text: str) -> None:
        write_text_atomic(self.path, text)


class ParquetDataset(Dataset):
    """One Parquet file of a Hive-partitioned table (task=.../scene_id=.../part-0.parquet)."""

    def load(self, columns: list[str] | None = None, **read_kwargs):
        """The pyarrow Table (``.to_pandas()`` for a DataFrame)."""
        import pyarrow.parquet as pq

        return pq.read_table(self.path, columns=columns, **read_kwargs)

    def load_or_none(self, columns: list[str] | None = None, **read_kwargs):
        return self.load(columns, **read_kwargs) if self.path.exists() else None

    def save(self, table, compression: str = "zstd", **write_kwargs) -> None:
        import pyarrow.parquet as pq

        with atomic_path(self.path) as tmp:
            pq.write_table(table, tmp, compression=compression, **write_kwargs)

    def delete(self) -> None:
        """Remove the file and its now-empty partition folder (a task no longer produced)."""
        self.path.unlink(missing_ok=True)
        with contextlib.suppress(OSError):
            self.path.parent.rmdir()


class ZarrDataset(Dataset):
    """A Zarr group (voxels: A, V; anything written chunk by chunk)."""

    def load(self):
        """The group, read-only."""
        import zarr

        return zarr.open_group(str(self.path), mode="r")

    @contextlib.contextmanager
    def writing(self):
        """A new Zarr group at a temporary path, renamed into place when the block succeeds."""
        import zarr

        with atomic_path(self.path) as tmp:
            yield zarr.open_group(str(tmp), mode="w")


class GaussianDataset(Dataset):
    """A GaussianScene in the pipeline's Zarr layout (navcore.gaussians.store)."""

    def load(self):
        """(GaussianScene, attrs)."""
        from navcore.gaussians.store import read_scene_zarr

        return read_scene_zarr(self.path)

    def save(self, scene, attrs: dict | None = None, source: dict | None = None) -> None:
        """source: store a reference to it instead of a copy (navcore.gaussians.store)."""
        from navcore.gaussians.store import write_scene_zarr

        with atomic_path(self.path) as tmp:
            write_scene_zarr(tmp, scene, attrs, source)


class AlignedGaussianDataset(Dataset):
    """The scene in the gravity frame, derived on read: the canonical store (``base``, a
    GaussianDataset) moved by the 4x4 ``source_to_aligned`` of the alignment document at ``path``.
    Nothing but those 16 numbers is stored for it (no second copy of the Gaussians)."""

    def __init__(self, path: str | Path, base: GaussianDataset):
        super().__init__(path)
        self.base = base

    def exists(self) -> bool:
        return self.path.exists() and self.base.exists()

    def transform(self) -> np.ndarray:
        return np.asarray(json.loads(self.path.read_text())["source_to_aligned"], np.float64)

    def load(self, view_dependent: bool = True):
        """(GaussianScene in the aligned frame, attrs with frame and source_to_aligned).

        view_dependent=False keeps only the degree-0 (base) colour, which a rotation leaves as it
        is: for readers of geometry and opacity (the costmap), rotating the higher SH bands of a
        degree-3 scene is most of the load (8.7 s of the 1.5 M fungi room's 11 s)."""
        gs, attrs = self.base.load()
        if not view_dependent and gs.sh.shape[1] > 1:
            gs.sh = np.ascontiguousarray(gs.sh[:, :1])
        t = self.transform()
        return gs.transformed(t), {**attrs, "frame": "aligned", "source_to_aligned": t.tolist()}


COSTMAP_LAYERS = ("raw", "support", "occ", "clearance", "components")
"""Arrays of one embodiment's group in a costmap store, [ny, nx], row = y."""
COSTMAP_GRID = "[ny, nx], row = y; cell (i, j) centre = origin + ((j+.5) res, (i+.5) res)"
HIDDEN_SPLATS = "hidden_splats"
"""[K] int64 of an embodiment's group: indices (into the aligned scene) of the noise splats hidden
from its camera (navcore.gaussians.content.camera_scene)."""


class CostmapDataset(ZarrDataset):
    """The costmaps of one scene: a group per embodiment holding COSTMAP_LAYERS and its attrs
    (origin, resolution, radius, margin, h_min, h_max, info), root attrs for the scene."""

    def load(self, embodiment: str):
        """The queryable Costmap of one embodiment."""
        from navcore.nav.costmap import Costmap

        g = super().load()[embodiment]
        a = g.attrs
        comp = np.asarray(g["components"][...]) if "components" in g else None
        return Costmap(np.asarray(g["clearance"][...]), a["origin"], a["resolution"], a["radius"], a["margin"], comp)

    def load_layers(self, embodiment: str) -> tuple[dict[str, np.ndarray], dict, dict]:
        """(layers by name, the embodiment's attrs, the root attrs)."""
        root = super().load()
        g = root[embodiment]
        return {k: np.asarray(g[k][...]) for k in COSTMAP_LAYERS if k in g}, dict(g.attrs), dict(root.attrs)

    def hidden(self, embodiment: str) -> np.ndarray:
        """Indices of the Gaussians hidden from this embodiment's camera (HIDDEN_SPLATS; empty
        when the store has none)."""
        g = super().load()[embodiment]
        return np.asarray(g[HIDDEN_SPLATS][...], np.int64) if HIDDEN_SPLATS in g else np.zeros(0, np.int64)

    @staticmethod
    def write_layers(root, embodiment, layers, attrs: dict, hidden: np.ndarray | None = None) -> Any:
        """Add one embodiment's group (layers: an object with the COSTMAP_LAYERS as attributes,
        e.g. CostmapLayers; hidden: sorted Gaussian indices) to a root group opened by writing();
        returns the group."""
        g = root.create_group(embodiment.name)
        for name in COSTMAP_LAYERS:
            arr = getattr(layers, name)
            g.create_array(name, data=arr, chunks=arr.shape, **array_codecs(arr.dtype))
        if hidden is not None:
            g.create_array(HIDDEN_SPLATS, data=np.asarray(hidden, np.int64), chunks=(max(len(hidden), 1),),
                           **array_codecs(np.int64))
        g.attrs.update({"origin": list(layers.origin), "resolution": layers.resolution, "radius": embodiment.radius,
                        "margin": layers.margin, "h_min": embodiment.h_min, "h_max": embodiment.h_max,
                        "layout": COSTMAP_GRID, **attrs})
        return g


QUALITY_LAYERS = ("blur", "hole", "view_blur", "view_hole", "unseen", "flagged", "camera_views")
"""Arrays of a scene's quality store (stage `screen`), [ny, nx] on its costmap grid: bool, but
camera_views (int32 capture cameras seeing each valid cell's floor, -1 elsewhere; only with cameras)."""


class QualityDataset(ZarrDataset):
    """The reconstruction-quality layer of one scene: QUALITY_LAYERS, the rendered lattice poses
    (view_poses [P, 2], view_blur_share / view_hole_share [P]) and attrs (origin, resolution,
    score, shares, the main embodiment)."""

    def load_layers(self) -> tuple[dict[str, np.ndarray], dict]:
        """(layers by name, attrs)."""
        root = super().load()
        return {k: np.asarray(root[k][...]) for k in QUALITY_LAYERS if k in root}, dict(root.attrs)

    @staticmethod
    def write(root, layers: dict[str, np.ndarray], attrs: dict) -> None:
        """Every array of layers (chunked whole) and the attrs, into a root opened by writing()."""
        for name, arr in layers.items():
            arr = np.asarray(arr)
            root.create_array(name, data=arr, chunks=tuple(max(d, 1) for d in arr.shape), **array_codecs(arr.dtype))
        root.attrs.update({"layout": COSTMAP_GRID, **attrs})


class ImageDataset(Dataset):
    """A PNG: saved from an [H, W(, C)] uint8 array or a matplotlib figure."""

    def load(self) -> np.ndarray:
        from PIL import Image

        return np.asarray(Image.open(self.path))

    def save(self, image, **savefig_kwargs) -> None:
        with atomic_path(self.path) as tmp:
            if hasattr(image, "savefig"):
                image.savefig(tmp, format="png", **savefig_kwargs)
            else:
                from PIL import Image

                Image.fromarray(np.asarray(image)).save(tmp, format="png")


class FolderWriter:
    """Files of a folder dataset being written (its temporary folder, renamed as a whole)."""

    def __init__(self, root: Path):
        self.root = root

    def __truediv__(self, name: str) -> Path:
        """Path of a file inside, for writers that want one (PLY, splat); parents created."""
        p = self.root / name
        p.parent.mkdir(parents=True, exist_ok=True)
        return p

    def json(self, name: str, obj: Any, indent: int | None = 1) -> str:
        (self / name).write_text(jsonio.dumps(obj, indent=indent))
        return name

    def text(self, name: str, text: str) -> str:
        (self / name).write_text(text)
        return name

    def reference(self, name: str, source: str | Path) -> str:
        """A file that refers to a local file without a second copy of its bytes: a hard link where
        the filesystem allows, else a symbolic link to its absolute path."""
        import os

        dst = self / name
        dst.parent.mkdir(parents=True, exist_ok=True)
        try:
            os.link(source, dst)
        except OSError:  # another filesystem, or hard links not supported
            os.symlink(Path(source).resolve(), dst)
        return name

    def bytes(self, name: str, data: bytes) -> str:
        (self / name).write_bytes(data)
        return name

    def parquet(self, name: str, table, compression: str = "zstd", **write_kwargs) -> str:
        import pyarrow.parquet as pq

        pq.write_table(table, self / name, compression=compression, **write_kwargs)
        return name

    def image(self, name: str, image) -> str:
        from PIL import Image

        Image.fromarray(np.asarray(image)).save(self / name, format="png")
        return name


class FolderDataset(Dataset):
    """A folder written as a whole (an asset, an export scene folder): ``writing()`` yields a
    FolderWriter on a temporary folder; files are read by name."""

    @contextlib.contextmanager
    def writing(self) -> Iterator[FolderWriter]:
        with atomic_path(self.path) as tmp:
            tmp.mkdir(parents=True)
            yield FolderWriter(tmp)

    def load(self) -> Path:
        """The folder (it must exist)."""
        if not self.path.is_dir():
            raise FileNotFoundError(f"{self.path} does not exist")
        return self.path

    def file(self, name: str) -> Path:
        return self.path / name

    def read_json(self, name: str, default: Any = None) -> Any:
        return JSONDataset(self.path / name).load_or(default)

    def glob(self, pattern: str) -> list[Path]:
        return sorted(self.path.glob(pattern))


class SyntheticSourceDataset(FolderDataset):
    """A procedural scene's source folder: the 3DGS file and its ground truth (mesh, labels,
    per-Gaussian instance ids, transform, cameras, floor plan)."""

    SOURCE_FILE = "scene.ply"
    GT_DIR = "ground_truth"

    @property
    def source_file(self) -> Path:
        return self.path / self.SOURCE_FILE

    def ground_truth(self, name: str) -> Path:
        """Path of one ground-truth file (instance_ids.npy, labels.json, ...)."""
        return self.path / self.GT_DIR / name

    def read_ground_truth(self, name: str, default: Any = None) -> Any:
        """A ground-truth file: JSON parsed, .npy loaded; ``default`` when absent."""
        p = self.ground_truth(name)
        if p.suffix != ".npy":
            return JSONDataset(p).load_or(default)
        return np.load(p) if p.exists() else default


class FileDataset(Dataset):
    """A file written by a library that wants a path (a video, a 3DGS source): ``writing()``
    yields a temporary path; ``load()`` returns the path of the existing file."""

    def load(self) -> Path:
        if not self.path.is_file():
            raise FileNotFoundError(f"{self.path} does not exist")
        return self.path


TYPES: dict[str, type[Dataset]] = {
    "json": JSONDataset, "json_gz": JSONGzDataset, "text": TextDataset, "parquet": ParquetDataset,
    "zarr": ZarrDataset, "gaussians": GaussianDataset, "aligned_gaussians": AlignedGaussianDataset,
    "costmap": CostmapDataset, "quality": QualityDataset, "image": ImageDataset, "folder": FolderDataset, "file": FileDataset,
    "synthetic_source": SyntheticSourceDataset,
}
"""Dataset type names of the layout file."""
