"""The frames KITTI AP is computed on (`kitti_eval`) and KITTI label folders are read into (`kitti_files`):
one frame's ground truth and one frame's detections, as arrays. No imports of the package, so both
modules can use them without importing each other.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class FrameGT:
    """Ground truth of one frame: G objects, including DontCare rows (cls "DontCare")."""
    boxes: np.ndarray        # (G, 7) x, y, z, l, w, h, yaw (vehicle frame); NaN rows allowed
    bbox: np.ndarray         # (G, 4) x1, y1, x2, y2 image box in pixels
    occlusion: np.ndarray    # (G,) KITTI level 0..3
    truncation: np.ndarray   # (G,) 0..1
    cls: np.ndarray          # (G,) class names, case-insensitive
    alpha: np.ndarray | None = field(default=None)  # (G,) observation angle (label field 4, rad); for AOS


@dataclass(frozen=True)
class FrameDet:
    """Detections of one frame: D boxes with a 2D image box and a score."""
    boxes: np.ndarray        # (D, 7)
    bbox: np.ndarray         # (D, 4)
    score: np.ndarray        # (D,)
    cls: np.ndarray | None = field(default=None)   # (D,) class names; None = all "Car"
    alpha: np.ndarray | None = field(default=None)  # (D,) observation angle (rad); None or any -10: no AOS
