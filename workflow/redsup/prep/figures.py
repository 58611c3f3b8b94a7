"""Diagnostic images of the preparation stages (logged to MLflow by the Snakemake scripts), drawn with OpenCV:
the preparation jobs already use it, and matplotlib's start-up would double a detection job's time."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from redsup import geometry, sceneio
from redsup.prep import masks_io
from redsup.prep.detections import LIDAR

MATCHED = (255, 255, 0)      # RGB: yellow box = matched to a ground-truth car
UNMATCHED = (255, 0, 255)    # magenta = a false positive or a merged mask
INLIER = (0, 255, 0)         # L_m point inside the matched ground-truth box
OUTLIER = (255, 0, 0)        # ... outside it


def busiest_frame(d: dict) -> int:
    """The frame with most detections (0 when there are none)."""
    if len(d["frame"]) == 0:
        return 0
    return int(np.bincount(d["frame"]).argmax())


def overlay_scale(width: int, min_width: int = 800) -> int:
    """The whole-number magnification that makes an image ``width`` px wide at least ``min_width`` px wide (so
    that boxes, scores and the caption stay legible on small renders), at least 1."""
    return max(1, -(-int(min_width) // int(width)))


def detection_overlay(scene_dir: str | Path, d: dict, frame: int, min_width: int = 800) -> np.ndarray:
    """RGB uint8 image (the camera's size x `overlay_scale`, with a caption band): the frame's masks blended over
    the camera image, boxes and scores (yellow matched, magenta unmatched), and the L_m points coloured by the
    ground-truth inlier flag (green inside the matched box, red outside)."""
    scene_dir = Path(scene_dir)
    camera = str(d["camera"])
    image = sceneio.read_image(scene_dir / camera / sceneio.frame_name(frame, "png"))
    K, _ = sceneio.read_intrinsics(scene_dir / f"{camera}.txt")
    ext = sceneio.read_extrinsics(scene_dir / "extrinsics.json")
    T = geometry.invert_pose(ext[camera]) @ ext[LIDAR]
    overlay = image.astype(np.float32) / 255.0
    rng = np.random.default_rng(0)
    ids = np.flatnonzero(d["frame"] == frame)
    for i in ids:
        m = masks_io.mask_of(d, i)
        overlay[m] = 0.5 * overlay[m] + 0.5 * rng.uniform(0.2, 1.0, 3)
    h, w = image.shape[:2]
    scale = overlay_scale(w, min_width)
    canvas = cv2.resize(np.round(overlay * 255).astype(np.uint8), (w * scale, h * scale),
                        interpolation=cv2.INTER_NEAREST)
    for i in ids:
        x1, y1, x2, y2 = (float(v) * scale for v in d["box"][i])
        colour = MATCHED if d["matched_track"][i] >= 0 else UNMATCHED
        cv2.rectangle(canvas, (int(round(x1)), int(round(y1))), (int(round(x2)), int(round(y2))), colour, 1)
        cv2.putText(canvas, f"{d['score'][i]:.2f}", (int(round(x1)), max(int(round(y1)) - 3, 8)),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.35, colour, 1, cv2.LINE_AA)
        pts = masks_io.points_of(d, i)
        if len(pts):
            uv, _ = geometry.project(K, geometry.transform_points(T, pts[:, :3].astype(np.float64)))
            inl = masks_io.inliers_of(d, i)
            for (u, v), ok in zip(np.round(uv * scale).astype(int), inl):
                if 0 <= u < w * scale and 0 <= v < h * scale:
                    cv2.circle(canvas, (int(u), int(v)), 1, INLIER if ok else OUTLIER, -1)
    return with_caption(canvas, (f"{scene_dir.name} frame {frame}: {len(ids)} detections ({d['level']})",
                                 "yellow = matched, magenta = unmatched; L_m points green = in gt box, red = outlier"))


def with_caption(image: np.ndarray, lines: tuple[str, str]) -> np.ndarray:
    """``image`` (RGB uint8) under a 36-pixel white band holding two lines of black text."""
    band = np.full((36, image.shape[1], 3), 255, np.uint8)
    for k, line in enumerate(lines):
        cv2.putText(band, line, (4, 14 + 16 * k), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
    return np.concatenate([band, image])
