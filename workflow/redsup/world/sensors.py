"""Sensors: pinhole cameras and the spinning LiDAR, their ray grids and primitive culling rectangles.

A sensor casts a grid of rays from one origin; `rects` maps the corners of a primitive (in the sensor
frame) to a conservative rectangle of grid rows/columns, so each primitive is tested only against the
rays that can hit it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .common import pose

# camera axes (x right, y down, z forward) in the vehicle frame (x forward, y left, z up)
R_VEHICLE_FRONT = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
R_VEHICLE_BACK = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
_SIGNS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
_EDGES = np.array([(a, b) for a in range(8) for b in range(a + 1, 8)
                   if np.sum(_SIGNS[a] != _SIGNS[b]) == 1])
NEAR = 0.05


def box_corners(center: np.ndarray, rot: np.ndarray, half: np.ndarray) -> np.ndarray:
    """(M, 8, 3) corners of oriented boxes."""
    local = _SIGNS[None, :, :] * half[:, None, :]
    return center[:, None, :] + np.einsum("mij,mkj->mki", rot, local)


def intrinsics(width: int, height: int, hfov_deg: float) -> np.ndarray:
    """Square-pixel pinhole with the principal point at the image centre (pixel-centre convention)."""
    f = 0.5 * width / np.tan(np.radians(hfov_deg) / 2.0)
    return np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])


def fine_camera(cam: "Camera", k: int) -> "Camera":
    """The same camera on a k-times finer pixel grid: pixel (u, v) of ``cam`` covers the k x k fine pixels
    (k u .. k u + k - 1, k v .. k v + k - 1), so f becomes k f and the principal point (c + 0.5) k - 0.5."""
    if k == 1:
        return cam
    K = cam.K.astype(np.float64).copy()
    K[0, 0] *= k
    K[1, 1] *= k
    K[0, 2] = (K[0, 2] + 0.5) * k - 0.5
    K[1, 2] = (K[1, 2] + 0.5) * k - 0.5
    return Camera(cam.name, K, cam.width * k, cam.height * k, cam.T_vehicle_sensor)


@dataclass
class Camera:
    name: str
    K: np.ndarray
    width: int
    height: int
    T_vehicle_sensor: np.ndarray

    @property
    def n_rays(self) -> int:
        return self.width * self.height

    @property
    def grid_width(self) -> int:
        return self.width

    @property
    def pixel_angle(self) -> float:
        return 1.0 / self.K[0, 0]

    def ray_dirs(self) -> np.ndarray:
        """(H*W, 3) camera-frame directions with z = 1, row-major over pixels (so t = depth)."""
        if getattr(self, "_dirs", None) is None:
            self._dirs = self._make_dirs()
        return self._dirs

    def _make_dirs(self) -> np.ndarray:
        u, v = np.meshgrid(np.arange(self.width, dtype=np.float64), np.arange(self.height, dtype=np.float64))
        x = (u - self.K[0, 2]) / self.K[0, 0]
        y = (v - self.K[1, 2]) / self.K[1, 1]
        return np.stack([x.ravel(), y.ravel(), np.ones(self.n_rays)], axis=-1)

    def project_bounds(self, corners: np.ndarray):
        """Bounds (u_lo, u_hi, v_lo, v_hi, any_in_front) of the projections of boxes given by their
        corners in the camera frame (M, 8, 3); edges are clipped at the near plane first."""
        a, b = corners[:, _EDGES[:, 0]], corners[:, _EDGES[:, 1]]
        za, zb = a[..., 2], b[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (NEAR - za) / (zb - za)
        cross = (za - NEAR) * (zb - NEAR) < 0
        clip = a + np.where(cross, s, 0.0)[..., None] * (b - a)
        pts = np.concatenate([corners, clip], axis=1)
        ok = np.concatenate([corners[..., 2] > NEAR, cross], axis=1)
        z = np.where(ok, pts[..., 2], 1.0)
        u = self.K[0, 0] * pts[..., 0] / z + self.K[0, 2]
        v = self.K[1, 1] * pts[..., 1] / z + self.K[1, 2]
        big = 1e7
        return (np.min(np.where(ok, u, big), axis=1), np.max(np.where(ok, u, -big), axis=1),
                np.min(np.where(ok, v, big), axis=1), np.max(np.where(ok, v, -big), axis=1), ok.any(axis=1))

    def rects(self, corners: np.ndarray):
        """Rows/columns [r0, r1) x [c0, c1) covering the projection of each box (corners in the camera
        frame, (M, 8, 3)); boxes entirely behind the near plane get an empty rectangle."""
        u_lo, u_hi, v_lo, v_hi, front = self.project_bounds(corners)
        c0 = np.clip(np.floor(u_lo - 0.5), 0, self.width).astype(np.int64)
        c1 = np.clip(np.floor(u_hi + 0.5) + 2, 0, self.width).astype(np.int64)
        r0 = np.clip(np.floor(v_lo - 0.5), 0, self.height).astype(np.int64)
        r1 = np.clip(np.floor(v_hi + 0.5) + 2, 0, self.height).astype(np.int64)
        empty = ~front | (c1 <= c0) | (r1 <= r0)
        r1 = np.where(empty, r0, r1)
        return r0, r1, c0, c1


@dataclass
class Lidar:
    name: str
    elevations: np.ndarray   # (B,) radians, descending (row order)
    n_az: int
    max_range: float
    T_vehicle_sensor: np.ndarray

    @property
    def n_rays(self) -> int:
        return len(self.elevations) * self.n_az

    @property
    def grid_width(self) -> int:
        return self.n_az

    def ray_dirs(self) -> np.ndarray:
        """(B*n_az, 3) unit directions, row = beam, column = azimuth 2 pi c / n_az (from x towards y)."""
        if getattr(self, "_dirs", None) is None:
            self._dirs = self._make_dirs()
        return self._dirs

    def _make_dirs(self) -> np.ndarray:
        az = 2.0 * np.pi * np.arange(self.n_az) / self.n_az
        el = self.elevations[:, None]
        return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az),
                         np.broadcast_to(np.sin(el), (len(self.elevations), self.n_az))], axis=-1).reshape(-1, 3)

    def rects(self, corners: np.ndarray):
        """Beam rows [r0, r1) and azimuth columns [c0, c1) (c1 may exceed n_az: wraps) covering each box
        (corners in the LiDAR frame, (M, 8, 3)); conservative bounds from the bounding circle."""
        xy = corners[..., :2]
        c = xy.mean(axis=1)
        r_xy = np.max(np.linalg.norm(xy - c[:, None], axis=-1), axis=1)
        rc = np.linalg.norm(c, axis=-1)
        full = rc <= r_xy + 0.05
        az_c = np.arctan2(c[:, 1], c[:, 0])
        da = np.arctan2(xy[..., 1], xy[..., 0]) - az_c[:, None]
        da = (da + np.pi) % (2 * np.pi) - np.pi
        step = 2 * np.pi / self.n_az
        c0 = np.floor((az_c + da.min(axis=1)) / step).astype(np.int64) - 1
        c1 = np.ceil((az_c + da.max(axis=1)) / step).astype(np.int64) + 2
        c0 = np.where(full, 0, c0)
        c1 = np.where(full, self.n_az, np.minimum(c1, c0 + self.n_az))
        zmin, zmax = corners[..., 2].min(axis=1), corners[..., 2].max(axis=1)
        dmin, dmax = np.maximum(rc - r_xy, 0.05), rc + r_xy
        el_hi = np.arctan2(zmax, np.where(zmax > 0, dmin, dmax))
        el_lo = np.arctan2(zmin, np.where(zmin < 0, dmin, dmax))
        margin = 0.6 * np.max(np.abs(np.diff(self.elevations))) if len(self.elevations) > 1 else 0.01
        asc = self.elevations[::-1]
        n = len(asc)
        lo_idx = np.searchsorted(asc, el_lo - margin, side="left")   # first ascending index >= el_lo
        hi_idx = np.searchsorted(asc, el_hi + margin, side="right")  # one past last <= el_hi
        r0 = n - hi_idx
        r1 = n - lo_idx
        empty = (r1 <= r0) | (rc - r_xy > self.max_range)
        r1 = np.where(empty, r0, r1)
        return r0, r1, c0, c1


def make_rig(domain: dict, rig_cfg: dict, lidar_cfg: dict) -> tuple[list[Camera], Lidar]:
    """The cameras a domain renders and the roof LiDAR, with their vehicle-frame mounting."""
    K = intrinsics(domain["width"], domain["height"], domain["hfov_deg"])
    h = domain["camera_height"]
    mounts = {
        "cam_front": (R_VEHICLE_FRONT, [rig_cfg["camera_x"], 0.0, h]),
        "cam_front_right": (R_VEHICLE_FRONT, [rig_cfg["camera_x"], -rig_cfg["stereo_baseline"], h]),
        "cam_back": (R_VEHICLE_BACK, [rig_cfg["back_camera_x"], 0.0, h]),
    }
    cams = [Camera(name, K.copy(), domain["width"], domain["height"], pose(*mounts[name]))
            for name in domain["cameras"]]
    lidar = make_lidar(lidar_cfg, [rig_cfg["lidar_x"], 0.0, domain["lidar_height"]])
    return cams, lidar


def make_lidar(lidar_cfg: dict, position) -> Lidar:
    el = np.radians(np.linspace(lidar_cfg["fov_up_deg"], lidar_cfg["fov_down_deg"], lidar_cfg["beams"]))
    return Lidar("lidar_top", el, lidar_cfg["azimuth_steps"], lidar_cfg["max_range"],
                 pose(np.eye(3), np.asarray(position, dtype=np.float64)))
