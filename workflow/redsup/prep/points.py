"""LiDAR points of a detection: L_m (points projecting into the 2D mask, McCraith ch. 6 §III-A) and the
2D-box frustum set (ch. 6 Table I row a), plus the evaluation-only ground-truth inlier flag.

A point's pixel is (round(u), round(v)), the convention of `geometry.sparse_depth_map`; points with camera
depth z <= min_depth or whose pixel falls outside the image are never selected.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from redsup import geometry, sceneio
from redsup.boxes3d import points_in_box


def read_sweep(path: str | Path) -> tuple[np.ndarray, int]:
    """(points (N, 4) float32, number of records dropped for non-finite values).

    A truncated or missing file raises `sceneio.SceneError` naming it.
    """
    points = sceneio.read_lidar(path)
    n_records = Path(path).stat().st_size // sceneio.LIDAR_RECORD_BYTES
    return points, int(n_records - len(points))


def project_sweep(points: np.ndarray, T_camera_lidar: np.ndarray, K: np.ndarray,
                  size: tuple[int, int], min_depth: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Indices of the points seen by the camera and their integer pixels: (index, u, v)."""
    width, height = int(size[0]), int(size[1])
    if len(points) == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, empty
    cam = geometry.transform_points(T_camera_lidar, points[:, :3].astype(np.float64))
    uv, z = geometry.project(K, cam)
    ok = (z > min_depth) & np.isfinite(uv).all(axis=1)
    index = np.flatnonzero(ok)
    u = np.round(uv[ok, 0]).astype(np.int64)
    v = np.round(uv[ok, 1]).astype(np.int64)
    inside = (u >= 0) & (u < width) & (v >= 0) & (v < height)
    return index[inside], u[inside], v[inside]


def in_mask(mask: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(n,) bool: projected pixel (u, v) lies on the mask."""
    return mask[v, u] if len(u) else np.zeros(0, dtype=bool)


def in_box(box_px: tuple[int, int, int, int], u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(n,) bool: pixel inside the inclusive pixel rectangle (col0, row0, col1, row1)."""
    c0, r0, c1, r1 = box_px
    return (u >= c0) & (u <= c1) & (v >= r0) & (v <= r1)


def mask_pixel_box(mask: np.ndarray) -> tuple[int, int, int, int]:
    """Inclusive pixel rectangle (col0, row0, col1, row1) of a non-empty mask."""
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    return int(cols[0]), int(rows[0]), int(cols[-1]), int(rows[-1])


def pixel_box_to_xyxy(box_px: tuple[int, int, int, int]) -> np.ndarray:
    """Pixel rectangle to x1, y1, x2, y2 of its outer edges: pixel centres are integers, so a mask
    covering columns c0..c1 spans x1 = c0 - 0.5 to x2 = c1 + 0.5 (width = number of columns)."""
    c0, r0, c1, r1 = box_px
    return np.array([c0 - 0.5, r0 - 0.5, c1 + 0.5, r1 + 0.5], dtype=np.float32)


def gt_inlier_flags(points_lidar: np.ndarray, T_vehicle_lidar: np.ndarray, box, margin: float) -> np.ndarray:
    """(n,) bool: point inside the ground-truth box (vehicle frame) grown by `margin`; False if box is None."""
    if box is None or len(points_lidar) == 0:
        return np.zeros(len(points_lidar), dtype=bool)
    vehicle = geometry.transform_points(T_vehicle_lidar, points_lidar[:, :3].astype(np.float64))
    return points_in_box(vehicle, box, margin)


class FramePoints:
    """The sweep of one frame projected into one camera, for selecting per-detection point sets."""

    def __init__(self, points: np.ndarray, T_camera_lidar: np.ndarray, K: np.ndarray,
                 size: tuple[int, int], min_depth: float):
        self.points = points
        self.index, self.u, self.v = project_sweep(points, T_camera_lidar, K, size, min_depth)

    def in_mask(self, mask: np.ndarray) -> np.ndarray:
        return self.points[self.index[in_mask(mask, self.u, self.v)]]

    def in_box(self, box_px: tuple[int, int, int, int]) -> np.ndarray:
        return self.points[self.index[in_box(box_px, self.u, self.v)]]
