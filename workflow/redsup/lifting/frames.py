"""The per-object input frame of the lifting network (Frustum PointNet's frustum normalisation).

Every L_m set is expressed relative to its pseudo-centre c (coordinate-wise median of the points, robust to
the outliers the mask lets through) and rotated about z by minus the viewing azimuth phi = atan2(c_y, c_x),
so that +x of the object frame points away from the sensor along the ray through c. The network predicts the
translation and yaw in this frame; `to_vehicle` maps them back:

    p_local = R(-phi) (p - c),     t_vehicle = c + R(phi) t_local,     yaw_vehicle = yaw_local + phi.

Yaw bins (`redsup.det3d.losses.yaw_bin_centers`) therefore quantise the yaw relative to the viewing ray (the
KITTI observation angle), which is what a partial scan determines. The normalisation hides where the object
is; `context_features` gives it back to the network's heads (azimuth, range, height) when configured.
"""
from __future__ import annotations

import numpy as np
import torch


def pseudo_centre(points: np.ndarray) -> np.ndarray:
    """(3,) coordinate-wise median of (n, >=3) points (n >= 1)."""
    return np.median(np.asarray(points, dtype=np.float64)[:, :3], axis=0)


def azimuth_of(centre) -> np.ndarray | torch.Tensor:
    """Viewing azimuth atan2(y, x) of centres (..., 3)."""
    if isinstance(centre, torch.Tensor):
        return torch.atan2(centre[..., 1], centre[..., 0])
    centre = np.asarray(centre, dtype=np.float64)
    return np.arctan2(centre[..., 1], centre[..., 0])


def rotate_z(xyz, angle):
    """Rotate (..., n, 3) points (or (..., 3) vectors with angle (...,)) about z by `angle` (broadcast on the
    leading dimensions: angle has the shape of xyz without its last one or two axes)."""
    lib = torch if isinstance(xyz, torch.Tensor) else np
    c, s = lib.cos(angle), lib.sin(angle)
    while c.ndim < xyz.ndim - 1:
        c, s = c[..., None], s[..., None]
    x, y, z = xyz[..., 0], xyz[..., 1], xyz[..., 2]
    out = [c * x - s * y, s * x + c * y, z]
    return torch.stack(out, dim=-1) if lib is torch else np.stack(out, axis=-1)


def to_local(points, centre, azimuth):
    """Points (..., n, 3) of objects with centres (..., 3) and azimuths (...) into the object frames."""
    if isinstance(points, torch.Tensor):
        return rotate_z(points - centre[..., None, :], -azimuth)
    return rotate_z(np.asarray(points) - np.asarray(centre)[..., None, :], -np.asarray(azimuth))


def to_vehicle(translation_local, yaw_local, centre, azimuth):
    """Poses (translation (..., 3), yaw (...)) in the object frames -> vehicle frame (differentiable)."""
    return centre + rotate_z(translation_local, azimuth), yaw_local + azimuth


def pose_to_local(translation, yaw, centre, azimuth):
    """Vehicle-frame poses -> object frames (targets of the supervised rows)."""
    return rotate_z(translation - centre, -azimuth), yaw - azimuth


def context_features(centre: torch.Tensor, azimuth: torch.Tensor) -> torch.Tensor:
    """(B, 4) where the object is, which the object frame hides: cos / sin of the viewing azimuth, range / 40 m,
    height of the pseudo-centre (the network's optional position input, `lifting.network.position_input`)."""
    rng = torch.linalg.vector_norm(centre[..., :2], dim=-1)
    return torch.stack([torch.cos(azimuth), torch.sin(azimuth), rng / 40.0, centre[..., 2]], dim=-1)


def wrap_angle(a):
    """Angles into [-pi, pi)."""
    lib = torch if isinstance(a, torch.Tensor) else np
    return lib.remainder(a + np.pi, 2 * np.pi) - np.pi
