"""KITTI-equivalent 2D box heights for the difficulty levels of `kitti_eval` on cameras other than KITTI's.

The KITTI difficulties cut on the 2D box height in pixels of KITTI's camera (40 / 25 / 25 px at a focal
length of 721.5 px, i.e. a 1.5 m tall car nearer than about 27 m is "easy"). The embedded world's cameras
have other focal lengths (the default kitti_like camera: 243.5 px), so raw pixel heights would make
"easy" mean "nearer than 9 m". Scaling every 2D box (ground truth and detections alike) by
KITTI_FOCAL_PX / f_y before the evaluation gives the difficulties their KITTI meaning in metres; the 3D
boxes and therefore the IoUs are untouched.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from redsup.det3d.kitti_types import FrameDet, FrameGT

KITTI_FOCAL_PX = 721.5377   # f_x = f_y of KITTI object's P2 (left colour camera)


def kitti_pixel_scale(K: np.ndarray, reference_focal: float = KITTI_FOCAL_PX) -> float:
    """Factor that turns pixel lengths of a camera with intrinsics K into KITTI-camera pixels."""
    return float(reference_focal) / float(np.asarray(K)[1, 1])


def scale_frames(frames: list, scale: float) -> list:
    """FrameGT / FrameDet objects with their 2D boxes multiplied by `scale` (new objects)."""
    out = []
    for f in frames:
        if not isinstance(f, (FrameGT, FrameDet)):
            raise TypeError(f"scale_frames: expected FrameGT or FrameDet, got {type(f).__name__}")
        out.append(replace(f, bbox=np.asarray(f.bbox, dtype=np.float64) * scale))
    return out
