"""The bird's-eye view of one test frame of a training run, drawn with OpenCV (matplotlib's start-up would add a
second to every training job; the training curves are MLflow metrics with their steps, charted by its UI)."""
from __future__ import annotations

import cv2
import numpy as np

from redsup.det3d.boxes import bev_corners
from redsup.lidar_detector.grid import GridSpec
from redsup.prep.figures import with_caption

POINT = (150, 150, 150)   # RGB: LiDAR points grey
GT = (0, 160, 0)          # ground-truth boxes green
DET = (220, 0, 0)         # detections red, paler with lower score


def bev_pixels(xy: np.ndarray, grid: GridSpec, px_per_m: float) -> np.ndarray:
    """(N, 2) vehicle-frame x (forward), y (left) in metres -> (N, 2) pixel (column, row): x to the right, y up,
    the grid's (x_min, y_max) corner at pixel (0, 0)."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    return np.stack([(xy[:, 0] - grid.x_range[0]) * px_per_m, (grid.y_range[1] - xy[:, 1]) * px_per_m], axis=1)


def _faded(colour, alpha: float) -> tuple[int, int, int]:
    return tuple(int(round(255 - alpha * (255 - c))) for c in colour)


def bev_image(points: np.ndarray, gt_boxes: np.ndarray, det_boxes: np.ndarray, det_scores: np.ndarray,
              grid: GridSpec, title: str, px_per_m: float = 10.0) -> np.ndarray:
    """RGB uint8 image of the grid's area: LiDAR points (grey), ground-truth boxes (green) and detections (red,
    faded towards white as the score falls to 0.15), each box with a line from its centre to its front, under
    a caption band with ``title``."""
    w = int(round((grid.x_range[1] - grid.x_range[0]) * px_per_m))
    h = int(round((grid.y_range[1] - grid.y_range[0]) * px_per_m))
    canvas = np.full((h, w, 3), 255, np.uint8)
    uv = np.floor(bev_pixels(np.asarray(points)[:, :2], grid, px_per_m)).astype(int) if len(points) else np.zeros((0, 2), int)
    keep = (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
    canvas[uv[keep, 1], uv[keep, 0]] = POINT
    for boxes, colour, scores in ((gt_boxes, GT, None), (det_boxes, DET, det_scores)):
        boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
        for k, corners in enumerate(bev_corners(boxes) if len(boxes) else []):
            c = colour if scores is None else _faded(colour, float(np.clip(scores[k], 0.15, 1.0)))
            poly = np.round(bev_pixels(corners, grid, px_per_m)).astype(np.int32)
            cv2.polylines(canvas, [poly], True, c, 1, cv2.LINE_AA)
            front = np.round(bev_pixels(np.stack([boxes[k, :2], (corners[0] + corners[3]) / 2]), grid,
                                        px_per_m)).astype(int)
            cv2.line(canvas, tuple(map(int, front[0])), tuple(map(int, front[1])), c, 1, cv2.LINE_AA)
    return with_caption(canvas, (title, f"x forward {grid.x_range[0]:g}..{grid.x_range[1]:g} m (right), "
                                        f"y left {grid.y_range[0]:g}..{grid.y_range[1]:g} m (up), {px_per_m:g} px/m"))
