"""The query API of a costmap: state and straight-motion validity of a disk footprint, one at a
time (for planners' callbacks) or batched over numpy arrays (for samplers and benchmarks).

A pose is valid when the interpolated clearance at its centre is >= radius + margin and it lies
in the supported region; the heading does not matter for a disk.
"""
from __future__ import annotations

import functools
import math

import numpy as np

from navcore.nav import collision as K

PARALLEL_BATCH = 20_000
"""Batches of at least this many queries use the threaded kernels."""


def _entry(dispatcher, *example_args):
    """Compiled entry point of a numba function for the types of example_args."""
    dispatcher(*example_args)  # compile (or load from cache) this signature
    types = tuple(dispatcher.typeof_pyval(a) for a in example_args)
    return dispatcher.overloads[types].entry_point


class Costmap:
    """Queryable costmap of one embodiment.

    Args:
        clearance: [ny, nx] float32 metres, -1 where unsupported (row = y).
        origin: (x, y) of the map's minimum corner, metres.
        resolution: cell size, metres.
        radius: footprint radius, metres. margin: interpolation margin, metres.
    """

    def __init__(self, clearance: np.ndarray, origin, resolution: float, radius: float, margin: float,
                 components: np.ndarray | None = None):
        self.clearance = np.ascontiguousarray(clearance, dtype=np.float32)
        self.origin = (float(origin[0]), float(origin[1]))
        self.resolution = float(resolution)
        self.radius = float(radius)
        self.margin = float(margin)
        self.components = components  # [ny, nx] int32 free-component labels (1 = largest), optional
        self._args = (self.clearance, self.origin[0], self.origin[1], 1.0 / self.resolution,
                      self.radius + self.margin)
        self._f, self._ox, self._oy, self._inv, self._thr = self._args
        # Single-call fast paths: bind the compiled entry points directly. Numba's dispatcher
        # resolves argument types on every call (~0.2 us); the entry point of the one signature
        # we use skips that, halving the cost of a planner's validity callback.
        self.is_state_valid = functools.partial(_entry(K.state_valid, *self._args, 0.0, 0.0), *self._args)
        self.is_motion_valid = functools.partial(_entry(K.motion_valid, *self._args, 0.0, 0.0, 0.0, 0.0), *self._args)

    @classmethod
    def from_layers(cls, layers) -> "Costmap":
        return cls(layers.clearance, layers.origin, layers.resolution, layers.radius, layers.margin,
                   layers.components)

    @classmethod
    def from_occupancy(cls, occ: np.ndarray, origin, resolution: float) -> "Costmap":
        """A costmap from a binary map alone (a ROS map of a released asset: occ [ny, nx] bool, row =
        y): clearance 1 on free cells and 0 on occupied ones, a state valid where the bilinear
        interpolation reaches 0.5, so the valid region's boundary lies half way between a free and
        an occupied cell centre. Coarser than the stored clearance, which is what a downloaded
        release has to check its episodes with."""
        clearance = np.where(np.asarray(occ, bool), 0.0, 1.0).astype(np.float32)
        return cls(clearance, origin, resolution, radius=0.5, margin=0.0)

    @classmethod
    def from_inflated_map(cls, occ: np.ndarray, origin, resolution: float, radius: float) -> "Costmap":
        """A costmap from a binary map whose occupied cells already hold the robot's radius (a
        release's ROS map: occ [ny, nx] bool, row = y), with a continuous clearance rebuilt from the
        signed distance to the map's free / occupied boundary, which lies half way between a free
        and an occupied cell centre: clearance = radius + that distance (at least 0). The valid
        region's edge is the one from_occupancy gives, but a state off a cell centre keeps its
        margin, so motions across narrow free corridors are judged as on the stored clearance
        rather than cell by cell. Metres."""
        from scipy.ndimage import distance_transform_edt

        occ = np.asarray(occ, bool)
        inside = distance_transform_edt(~occ) - 0.5  # free cells: cells to the nearest occupied centre, less half
        outside = distance_transform_edt(occ) - 0.5  # occupied cells: to the nearest free centre, less half
        signed = np.where(occ, -outside, inside) * resolution
        clearance = np.maximum(radius + signed, 0.0).astype(np.float32)
        return cls(clearance, origin, resolution, radius=radius, margin=0.0)

    @property
    def occupancy(self) -> np.ndarray:
        """[ny, nx] bool M_occ (cell centres that are not valid states)."""
        return self.clearance < self.radius + self.margin

    def view_depths(self, xy, angles, max_range: float = 10.0) -> np.ndarray:
        """[K] free distance (metres) from the point xy along each angle (radians) to the first
        obstacle of the obstacle layer (clearance under one cell) or the map's edge, at most
        max_range: sphere tracing on the clearance, so a ray costs a few steps in open space.
        Cells without floor support do not stop a ray (they are no obstacle to the eye)."""
        a = np.asarray(angles, float)
        x, y = (float(v) for v in np.asarray(xy, float).reshape(2))
        res = float(self.resolution)
        return K.ray_depths(self.clearance, float(self.origin[0]), float(self.origin[1]), res,
                            self.clearance.dtype.type(res), x, y, np.cos(a), np.sin(a), float(max_range))

    def fov_depth(self, xy, yaw: float, hfov_deg: float, max_range: float = 10.0) -> float:
        """The median free distance (metres, at most max_range) of 9 rays spread across a camera's
        horizontal field of view (`view_depths`): how far a camera at xy facing yaw sees on the
        obstacle layer."""
        half = math.radians(hfov_deg) / 2
        return float(np.median(self.view_depths(xy, yaw + np.linspace(-half, half, 9), max_range=max_range)))

    def is_state_valid(self, x: float, y: float) -> bool:  # replaced per instance by the fast path
        """Single pose (metres); yaw is irrelevant for a disk footprint."""
        return K.state_valid(self._f, self._ox, self._oy, self._inv, self._thr, x, y)

    def are_states_valid(self, xy: np.ndarray) -> np.ndarray:
        """[N, 2+] poses (x, y[, yaw]) -> [N] bool."""
        xy = np.ascontiguousarray(np.asarray(xy, dtype=np.float64)[:, :2])
        fn = K.states_valid if len(xy) >= PARALLEL_BATCH else K.states_valid_serial
        return fn(self._f, self._ox, self._oy, self._inv, self._thr, xy)

    def is_motion_valid(self, x0: float, y0: float, x1: float, y1: float) -> bool:  # fast path per instance
        """Straight segment between two positions: every point of it is a valid state."""
        return K.motion_valid(self._f, self._ox, self._oy, self._inv, self._thr, x0, y0, x1, y1)

    def are_motions_valid(self, segments: np.ndarray, slack: float = 0.0) -> np.ndarray:
        """[N, 4] segments (x0, y0, x1, y1) -> [N] bool (valid with `slack` metres to spare)."""
        seg = np.ascontiguousarray(np.asarray(segments, dtype=np.float64))
        fn = K.motions_valid if len(seg) >= PARALLEL_BATCH else K.motions_valid_serial
        return fn(self._f, self._ox, self._oy, self._inv, self._thr + slack, seg)

    def taut_path(self, xy: np.ndarray, step: float, slack: float = 1e-3) -> np.ndarray:
        """[M, 2] valid polyline (metres) -> [K, 2] a shorter one through the same corridor: its
        points resampled `step` apart, then string-pulled by straight motions valid with `slack`
        metres to spare (a taut path touches the obstacles; the slack keeps poses rounded to
        float32 valid), see collision.taut_path. The first and last points stay."""
        xy = np.ascontiguousarray(np.asarray(xy, dtype=np.float64)[:, :2])
        return K.taut_path(self._f, self._ox, self._oy, self._inv, self._thr + slack, xy, float(step))

    def relax_path(self, xy: np.ndarray, step0: float, step_min: float, sweeps: int, tol: float, splits: int,
                   min_turn: float, slack: float = 1e-3) -> np.ndarray:
        """[M, 2] valid polyline -> its bends moved to their shortest valid positions (pattern
        search, segments next to bends split; collision.relax_path), motions valid with `slack`."""
        xy = np.ascontiguousarray(np.asarray(xy, dtype=np.float64)[:, :2])
        return K.relax_path(self._f, self._ox, self._oy, self._inv, self._thr + slack, xy, float(step0),
                            float(step_min), int(sweeps), float(tol), int(splits), float(min_turn))

    def clearance_at(self, xy: np.ndarray) -> np.ndarray:
        """Interpolated clearance (metres; negative outside the supported region) at [N, 2] points."""
        return K.clearance_at(self._f, self._ox, self._oy, self._inv, np.ascontiguousarray(np.asarray(xy, float)[:, :2]))

    def component_at(self, xy: np.ndarray) -> np.ndarray:
        """[N, 2] points -> [N] free-component label of their cell (0 = occupied or off the map;
        1 = the largest component, the one samplers should use)."""
        if self.components is None:
            raise ValueError("this costmap was built without component labels")
        i, j = self.cells_of(xy).T
        ny, nx = self.components.shape
        ok = (i >= 0) & (i < ny) & (j >= 0) & (j < nx)
        out = np.zeros(len(xy), np.int32)
        out[ok] = self.components[i[ok], j[ok]]
        return out

    def cells_of(self, xy: np.ndarray) -> np.ndarray:
        """[N, 2+] points (x, y, ...) -> [N, 2] int64 (row, col) of the cells holding them (not
        bounds-checked)."""
        xy = np.asarray(xy, float)[:, :2]
        return np.stack([np.floor((xy[:, 1] - self.origin[1]) / self.resolution),
                         np.floor((xy[:, 0] - self.origin[0]) / self.resolution)], 1).astype(np.int64)

    def cell_centers(self, cells: np.ndarray) -> np.ndarray:
        """[N, 2] (row, col) -> [N, 2] (x, y) metres."""
        cells = np.asarray(cells)
        return np.stack([self.origin[0] + (cells[:, 1] + 0.5) * self.resolution,
                         self.origin[1] + (cells[:, 0] + 0.5) * self.resolution], 1)


def lattice_cells(valid: np.ndarray, step: int) -> np.ndarray:
    """[P, 2] (row, col): per `step` x `step` block of the grid holding valid cells, the valid cell
    nearest the block's centre (ties: the first in row-major order), blocks in row-major order. A
    lattice of poses over the free space that still puts one in a narrow corridor between lattice
    nodes."""
    step = max(1, int(step))
    cells = np.argwhere(valid)
    if not len(cells):
        return cells
    block = cells // step
    d = np.hypot(*(cells - (block * step + (step - 1) / 2.0)).T)
    order = np.lexsort((d, block[:, 1], block[:, 0]))
    _, first = np.unique(block[order], axis=0, return_index=True)
    return cells[order][first]
