"""Object-level views of a prepared scene for chapters 6 and 7: ground-truth frames for the KITTI-style
evaluation, and per-detection LiDAR point sets in the vehicle frame.

Boxes are (x, y, z, l, w, h, yaw) in the vehicle frame of their frame (README, "The canonical raw-scene format"), the same
convention as `redsup.det3d.boxes` and `redsup.det3d.kitti_eval`.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from redsup import geometry, sceneio
from redsup.det3d.kitti_types import FrameGT
from redsup.prep import masks_io

if TYPE_CHECKING:   # pandas only types the rows (read by sceneio.read_boxes): 0.4 s of start-up in every job
    import pandas as pd

LIDAR = "lidar_top"
BOX_COLUMNS = ["x", "y", "z", "l", "w", "h", "yaw"]
CLASS_NAMES = {"car": "Car", "dontcare": "DontCare", "van": "Van"}


def _frame_gt(rows: pd.DataFrame) -> FrameGT:
    cls = np.array([CLASS_NAMES.get(str(c).lower(), str(c)) for c in rows["cls"]], dtype=object)
    bbox = rows[["x1", "y1", "x2", "y2"]].to_numpy(dtype=np.float64)
    return FrameGT(boxes=rows[BOX_COLUMNS].to_numpy(dtype=np.float64), bbox=np.nan_to_num(bbox, nan=0.0),
                   occlusion=rows["occlusion"].to_numpy(dtype=np.int64),
                   truncation=rows["truncation"].to_numpy(dtype=np.float64), cls=cls)


def gt_frames(scene_dir: str | Path, frames: list[int] | None = None) -> list[FrameGT]:
    """One FrameGT per frame (all frames of the scene by default).

    Objects not visible in the camera have a NaN 2D box in `gt/boxes.csv`; here their box becomes
    (0, 0, 0, 0), height 0, so every difficulty ignores them rather than counting them as missed.
    """
    scene_dir = Path(scene_dir)
    boxes = sceneio.read_boxes(scene_dir / "gt" / "boxes.csv")
    n = sceneio.read_meta(scene_dir)["n_frames"]
    frames = list(range(n)) if frames is None else frames
    by_frame = dict(tuple(boxes.groupby("frame")))
    empty = boxes.iloc[:0]
    return [_frame_gt(by_frame.get(f, empty)) for f in frames]


@dataclass(frozen=True)
class ObjectSet:
    """Detections of one scene with their LiDAR points in the vehicle frame (concatenated + offsets)."""
    frame: np.ndarray          # (D,) frame index
    score: np.ndarray          # (D,) detector score
    bbox: np.ndarray           # (D, 4) x1, y1, x2, y2 of the mask (raw camera pixels)
    matched_track: np.ndarray  # (D,) ground-truth track id or -1 (evaluation / supervised rows only)
    points: np.ndarray         # (P, 4) x, y, z (vehicle frame), reflectance
    offsets: np.ndarray        # (D + 1,) detection i owns points[offsets[i]:offsets[i + 1]]
    inlier_gt: np.ndarray      # (P,) point inside the matched ground-truth box (evaluation only)

    def points_of(self, i: int) -> np.ndarray:
        return self.points[self.offsets[i]:self.offsets[i + 1]]

    def __len__(self) -> int:
        return len(self.frame)


def object_set(scene_dir: str | Path, detections_path: str | Path, source: str = "mask") -> ObjectSet:
    """Detections of a scene with their L_m (`source="mask"`) or 2D-box frustum points (`"box"`)."""
    if source not in ("mask", "box"):
        raise ValueError(f"source must be 'mask' or 'box', not {source!r}")
    ext = sceneio.read_extrinsics(Path(scene_dir) / "extrinsics.json")
    d = masks_io.load_detections(detections_path)
    key = "points" if source == "mask" else "box_points"
    pts = d[key].astype(np.float64)
    xyz = geometry.transform_points(ext[LIDAR], pts[:, :3]) if len(pts) else np.zeros((0, 3))
    inlier = d["point_inlier_gt"] if source == "mask" else d.get("box_point_inlier_gt",
                                                                 np.zeros(len(pts), dtype=bool))
    return ObjectSet(frame=d["frame"].astype(np.int64), score=d["score"].astype(np.float64),
                     bbox=d["box"].astype(np.float64), matched_track=d["matched_track"].astype(np.int64),
                     points=np.hstack([xyz, pts[:, 3:4]]).astype(np.float32),
                     offsets=d["point_offsets" if source == "mask" else "box_point_offsets"].astype(np.int64),
                     inlier_gt=np.asarray(inlier, dtype=bool))


def sweep_in_vehicle_frame(scene_dir: str | Path, frame: int) -> np.ndarray:
    """(N, 4) LiDAR sweep of one frame in the vehicle frame (x, y, z, reflectance)."""
    scene_dir = Path(scene_dir)
    ext = sceneio.read_extrinsics(scene_dir / "extrinsics.json")
    pts = sceneio.read_lidar(scene_dir / LIDAR / sceneio.frame_name(frame, "bin")).astype(np.float64)
    return np.hstack([geometry.transform_points(ext[LIDAR], pts[:, :3]), pts[:, 3:4]]).astype(np.float32)


def camera_model(scene_dir: str | Path, camera: str = "cam_front") -> tuple[np.ndarray, np.ndarray, tuple[int, int]]:
    """(K, T_camera_vehicle, (width, height)) of a raw camera, for projecting boxes into the image."""
    scene_dir = Path(scene_dir)
    K, size = sceneio.read_intrinsics(scene_dir / f"{camera}.txt")
    ext = sceneio.read_extrinsics(scene_dir / "extrinsics.json")
    return K, geometry.invert_pose(ext[camera]), size
