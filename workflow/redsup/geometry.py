"""Pure camera and pose geometry (numpy). No I/O, no hidden state.

Conventions (README, "The canonical raw-scene format"): 4x4 homogeneous transforms T_a_b map b-coordinates to a-coordinates;
cameras are OpenCV pinholes (x right, y down, z forward) and pixel (0, 0) is the centre of the
top-left pixel.
"""
from __future__ import annotations

import numpy as np


def invert_pose(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid 4x4 transform (or a stack [..., 4, 4])."""
    R = T[..., :3, :3]
    t = T[..., :3, 3:]
    out = np.zeros_like(T)
    Rt = np.swapaxes(R, -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3:] = -Rt @ t
    out[..., 3, 3] = 1.0
    return out


def transform_points(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a 4x4 transform to an (N, 3) array of points."""
    return points @ T[:3, :3].T + T[:3, 3]


def lidar_to_camera(T_vehicle_lidar: np.ndarray, T_world_vehicle_lidar_time: np.ndarray,
                    T_world_vehicle_camera_time: np.ndarray, T_vehicle_camera: np.ndarray) -> np.ndarray:
    """T_{L_j}^{C_i} = T_{V_i}^{C_i} T_W^{V_i} T_{V_j}^W T_{L_j}^{V_j}  (Galteland eq. 3.29).

    Maps points of a LiDAR sweep taken at time j into the camera frame at image time i.
    """
    return (invert_pose(T_vehicle_camera) @ invert_pose(T_world_vehicle_camera_time)
            @ T_world_vehicle_lidar_time @ T_vehicle_lidar)


def project(K: np.ndarray, points_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pinhole projection of (N, 3) camera-frame points: returns (N, 2) pixel coordinates and depth z."""
    z = points_cam[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = (points_cam @ K.T)[:, :2] / z[:, None]
    return uv, z


def backproject(K: np.ndarray, uv: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """(N, 2) pixels with depth (camera z) to (N, 3) camera-frame points."""
    ones = np.ones((uv.shape[0], 1))
    rays = np.hstack([uv, ones]) @ np.linalg.inv(K).T
    return rays * depth[:, None]


def crop_intrinsics(K: np.ndarray, left: float, top: float) -> np.ndarray:
    """Principal point after cutting `left` columns and `top` rows (Galteland eq. 3.33-3.35)."""
    out = np.array(K, dtype=np.float64, copy=True)
    out[0, 2] -= left
    out[1, 2] -= top
    return out


def resize_intrinsics(K: np.ndarray, scale_x: float, scale_y: float) -> np.ndarray:
    """Intrinsics after resizing by (scale_x, scale_y) with pixel-centre convention.

    A pixel coordinate u maps to (u + 0.5) * s - 0.5, so fx' = s fx and cx' = (cx + 0.5) s - 0.5.
    """
    out = np.array(K, dtype=np.float64, copy=True)
    out[0, 0] *= scale_x
    out[0, 1] *= scale_x
    out[0, 2] = (K[0, 2] + 0.5) * scale_x - 0.5
    out[1, 1] *= scale_y
    out[1, 2] = (K[1, 2] + 0.5) * scale_y - 0.5
    return out


def crop_resize_intrinsics(K: np.ndarray, crop: dict, raw_size: tuple[int, int],
                           out_size: tuple[int, int]) -> np.ndarray:
    """Intrinsics of an image cropped by `crop` (top/bottom/left/right px) then resized to out_size (w, h)."""
    width, height = raw_size
    cw = width - crop["left"] - crop["right"]
    ch = height - crop["top"] - crop["bottom"]
    if cw <= 0 or ch <= 0:
        raise ValueError(f"crop {crop} leaves nothing of a {width}x{height} image")
    Kc = crop_intrinsics(K, crop["left"], crop["top"])
    return resize_intrinsics(Kc, out_size[0] / cw, out_size[1] / ch)


def sparse_depth_map(points_cam: np.ndarray, K: np.ndarray, width: int, height: int,
                     depth_range: tuple[float, float]) -> np.ndarray:
    """Sparse depth image (camera z, 0 = no return) from camera-frame points (Galteland eq. 3.30-3.32).

    Points outside `depth_range` or outside the image are dropped; where several points fall on one
    pixel the nearest one wins. Pixel of a point = round(u), round(v).
    """
    uv, z = project(K, points_cam)
    keep = (z > depth_range[0]) & (z < depth_range[1]) & np.isfinite(uv).all(axis=1)
    u = np.round(uv[keep, 0]).astype(np.int64)
    v = np.round(uv[keep, 1]).astype(np.int64)
    z = z[keep]
    inside = (u >= 0) & (u < width) & (v >= 0) & (v < height)
    u, v, z = u[inside], v[inside], z[inside]
    depth = np.zeros((height, width), dtype=np.float32)
    order = np.argsort(-z)  # far first, so the nearest point is written last and wins
    depth[v[order], u[order]] = z[order]
    return depth


def median_relative_error(estimate: np.ndarray, reference: np.ndarray) -> float:
    """Median |est - ref| / ref over pixels where both are positive (NaN when there are none)."""
    valid = (estimate > 0) & (reference > 0)
    if not valid.any():
        return float("nan")
    return float(np.median(np.abs(estimate[valid] - reference[valid]) / reference[valid]))
