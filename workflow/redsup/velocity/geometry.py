"""Camera geometry of McCraith ch. 3 §III-A: eq. (1) and the geometric velocity baseline.

A camera at height H above a flat road, looking straight ahead (OpenCV axes: x right, y down, z forward).
A ground point P = (X, 0, Z) projects to the pixel (u, v) = (cx + fx X / Z, cy + fy H / Z). A box
b = (x, y, w, h) is read through the midpoint of its bottom edge (x + w / 2, y + h), assumed to be the image
of such a ground point, which eq. (1) inverts:

    Z = fy H / (v - cy),   X = H (u - cx) / fx / ((v - cy) / fy) = Z (u - cx) / fx.

(The thesis writes Z = f H / v, X = H u / v with (u, v) relative to the principal point and one focal length.)

Geometric velocity estimator (stated, the thesis only says "the derivative at the last frame"): the slope of
the least-squares line through the last `window` reprojected points (X_t, Z_t), times the frame rate. With
window = 2 it is the backward difference (P_T - P_{T-1}) fps. Frames whose box bottom is at or above the
horizon (v - cy < `min_v_px`) have no ground point and are left out of the fit; with fewer than two usable
frames the estimate is (0, 0) and the track is flagged invalid.

Conventions of this package: velocities as (vx, vz) and positions as (x, z) (lateral first, the thesis'
V = (dX/dt, dZ/dt)); the TuSimple files store them forward first and `redsup.velocity.data` converts.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from redsup.sceneio import SceneError


@dataclass(frozen=True)
class Calibration:
    """Pinhole intrinsics (px) and the camera height above the road (m)."""

    fx: float
    fy: float
    cx: float
    cy: float
    height: float

    def as_dict(self) -> dict:
        return {"fx": self.fx, "fy": self.fy, "cx": self.cx, "cy": self.cy, "height": self.height}


_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def read_calibration(split_dir: str | Path) -> Calibration:
    """`calibration.txt` of a clip split: ours (`fx fy cx cy` / camera height) or the real TuSimple file
    (an "Intrinsic matrix:" 3x3 block and "Camera Height:" with a value like 1.80m).
    SceneError naming the file on anything else."""
    path = Path(split_dir) / "calibration.txt"
    try:
        text = path.read_text()
    except FileNotFoundError as exc:
        raise SceneError(f"{path}: missing (a clip split holds calibration.txt)") from exc
    if "intrinsic" in text.lower():
        head, _, tail = text.lower().partition("height")
        nums = [float(v) for v in re.findall(_NUMBER, head)]
        height = [float(v) for v in re.findall(_NUMBER, tail)]
        if len(nums) != 9 or len(height) != 1:
            raise SceneError(f"{path}: expected a 3x3 intrinsic matrix and one camera height")
        K = np.array(nums).reshape(3, 3)
        calib = Calibration(float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]), height[0])
    else:
        lines = [ln.split() for ln in text.splitlines() if ln.strip()]
        try:
            if len(lines) != 2 or len(lines[0]) != 4 or len(lines[1]) != 1:
                raise ValueError
            fx, fy, cx, cy = (float(v) for v in lines[0])
            calib = Calibration(fx, fy, cx, cy, float(lines[1][0]))
        except ValueError:
            raise SceneError(f"{path}: expected 'fx fy cx cy' on the first line and the camera height (m) "
                             "on the second") from None
    values = np.array([calib.fx, calib.fy, calib.height])
    if not (np.all(np.isfinite(values)) and np.all(values > 0) and np.isfinite(calib.cx) and np.isfinite(calib.cy)):
        raise SceneError(f"{path}: focal lengths and camera height must be positive numbers, got {calib}")
    return calib


def bottom_centre(boxes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(u, v) of the midpoint of the bottom edge of boxes (..., 4) given as x, y, w, h."""
    boxes = np.asarray(boxes, dtype=np.float64)
    return boxes[..., 0] + boxes[..., 2] / 2, boxes[..., 1] + boxes[..., 3]


def ground_point(u, v, calib: Calibration, min_v_px: float = 0.5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eq. (1): (X, Z, valid) of the ground point imaged at pixel (u, v). Invalid (bottom at or above the
    horizon, v - cy < min_v_px, or not finite) gives NaN."""
    u, v = np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64)
    dv = v - calib.cy
    valid = np.isfinite(u) & np.isfinite(dv) & (dv >= min_v_px)
    safe = np.where(valid, dv, 1.0)
    Z = np.where(valid, calib.fy * calib.height / safe, np.nan)
    X = np.where(valid, Z * (u - calib.cx) / calib.fx, np.nan)
    return X, Z, valid


def project_ground(X, Z, calib: Calibration) -> tuple[np.ndarray, np.ndarray]:
    """The inverse of eq. (1): pixel (u, v) of the ground point (X, 0, Z), Z > 0."""
    X, Z = np.asarray(X, dtype=np.float64), np.asarray(Z, dtype=np.float64)
    return calib.cx + calib.fx * X / Z, calib.cy + calib.fy * calib.height / Z


def box_ground_point(boxes, calib: Calibration, min_v_px: float = 0.5):
    """Eq. (1) applied to the bottom-edge midpoint of boxes (..., 4): (X, Z, valid)."""
    return ground_point(*bottom_centre(boxes), calib, min_v_px)


def box_from_ground(X, Z, w, h, calib: Calibration) -> np.ndarray:
    """Boxes (..., 4) x, y, w, h whose bottom-edge midpoint images the ground point (X, 0, Z)."""
    u, v = project_ground(X, Z, calib)
    w, h = np.broadcast_to(w, u.shape), np.broadcast_to(h, u.shape)
    return np.stack([u - w / 2, v - h, w, h], axis=-1)


def line_slope_at_end(values: np.ndarray, valid: np.ndarray, window: int) -> tuple[np.ndarray, np.ndarray]:
    """Per row of (N, T) `values`: slope per frame of the least-squares line through the valid samples
    among the last `window` frames, and whether at least two were valid."""
    values = np.asarray(values, dtype=np.float64)[:, -window:]
    w = np.asarray(valid, dtype=bool)[:, -window:].astype(np.float64)
    t = np.arange(values.shape[1], dtype=np.float64)[None]
    n = w.sum(axis=1)
    ok = n >= 2
    n_safe = np.maximum(n, 1.0)
    vals = np.where(w > 0, values, 0.0)
    t_mean = (w * t).sum(axis=1) / n_safe
    y_mean = (w * vals).sum(axis=1) / n_safe
    dt = (t - t_mean[:, None]) * w
    sxx = (dt * dt).sum(axis=1)
    sxy = (dt * (vals - y_mean[:, None])).sum(axis=1)
    ok &= sxx > 0
    return np.where(ok, sxy / np.where(sxx > 0, sxx, 1.0), 0.0), ok


def geometric_velocity(boxes: np.ndarray, calib: Calibration, fps: float, window: int = 10,
                       min_v_px: float = 0.5) -> dict[str, np.ndarray]:
    """The geometric baseline on tracks (N, T, 4): eq. (1) per frame, velocity = slope of the line fitted
    to the last `window` ground points (see module doc). Returns velocity (N, 2) [vx, vz] m/s, position
    (N, 2) [x, z] at the last frame (NaN where eq. (1) is undefined), valid (N,) bool."""
    if window < 2:
        raise ValueError(f"geometric window must be at least 2 frames, got {window}")
    boxes = np.asarray(boxes, dtype=np.float64)
    X, Z, valid = box_ground_point(boxes, calib, min_v_px)
    sx, ok_x = line_slope_at_end(X, valid, window)
    sz, ok_z = line_slope_at_end(Z, valid, window)
    ok = ok_x & ok_z
    velocity = np.stack([sx, sz], axis=-1) * fps
    velocity[~ok] = 0.0
    position = np.stack([X[:, -1], Z[:, -1]], axis=-1)
    return {"velocity": velocity, "position": position, "valid": ok}
