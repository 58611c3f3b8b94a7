"""Ground-truth 3D boxes (gt/boxes.csv rows: centre x, y, z, size l, w, h, yaw about z, vehicle frame)."""
from __future__ import annotations

import numpy as np

from redsup import geometry


def box_corners(box) -> np.ndarray:
    """(8, 3) corners of a box given as (x, y, z, l, w, h, yaw); centre is the geometric centre."""
    x, y, z, length, width, height, yaw = (float(v) for v in box)
    sx = np.array([1, 1, 1, 1, -1, -1, -1, -1]) * length / 2
    sy = np.array([1, 1, -1, -1, 1, 1, -1, -1]) * width / 2
    sz = np.array([1, -1, 1, -1, 1, -1, 1, -1]) * height / 2
    c, s = np.cos(yaw), np.sin(yaw)
    return np.stack([x + c * sx - s * sy, y + s * sx + c * sy, z + sz], axis=1)


def points_in_box(points: np.ndarray, box, margin: float = 0.0) -> np.ndarray:
    """(N,) bool: which of the (N, >=3) points (same frame as the box) lie inside the box grown by
    `margin` metres on every side."""
    x, y, z, length, width, height, yaw = (float(v) for v in box)
    d = np.asarray(points, dtype=np.float64)[:, :3] - np.array([x, y, z])
    c, s = np.cos(yaw), np.sin(yaw)
    along = c * d[:, 0] + s * d[:, 1]
    across = -s * d[:, 0] + c * d[:, 1]
    return ((np.abs(along) <= length / 2 + margin) & (np.abs(across) <= width / 2 + margin)
            & (np.abs(d[:, 2]) <= height / 2 + margin))


def distance_to_box(points: np.ndarray, box) -> np.ndarray:
    """(N,) Euclidean distance (m) of the (N, >=3) points to the box (same frame): 0 inside, else the distance to
    the nearest point of the solid box."""
    x, y, z, length, width, height, yaw = (float(v) for v in box)
    d = np.asarray(points, dtype=np.float64)[:, :3] - np.array([x, y, z])
    c, s = np.cos(yaw), np.sin(yaw)
    local = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1)
    excess = np.maximum(np.abs(local) - np.array([length, width, height]) / 2, 0.0)
    return np.linalg.norm(excess, axis=1)


def projected_box_area(box, T_camera_vehicle: np.ndarray, K: np.ndarray, min_depth: float = 0.1) -> float:
    """Area in pixels of the 2D rectangle enclosing the projected corners of a vehicle-frame box
    (not clipped to the image: truncation counts as invisible). 0 when no corner is in front."""
    corners = geometry.transform_points(T_camera_vehicle, box_corners(box))
    front = corners[:, 2] > min_depth
    if not front.any():
        return 0.0
    uv, _ = geometry.project(K, corners[front])
    return float(np.ptp(uv[:, 0]) * np.ptp(uv[:, 1]))
