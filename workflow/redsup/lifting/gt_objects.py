"""Point sets of ground-truth cars, for the fully supervised reference rows only (McCraith ch. 6 Table III (e),
Table IV (i) "original GT"): the LiDAR points projecting into a car's ground-truth instance mask in the
detector's camera, with its ground-truth box as the target.

Reads `gt/` (instance masks and boxes), which the scene format reserves for evaluation and the explicitly
fully supervised rows; nothing self-supervised imports this module.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from redsup import geometry, sceneio
from redsup.det3d.scenes import LIDAR
from redsup.lifting.data import RawObjects
from redsup.prep.points import FramePoints, read_sweep

BOX_FIELDS = ["x", "y", "z", "l", "w", "h", "yaw"]


def gt_car_boxes(scene_dir: str | Path, classes=("car",)) -> dict[tuple[int, int], np.ndarray]:
    """(frame, track_id) -> (7,) ground-truth box in that frame's vehicle frame."""
    boxes = sceneio.read_boxes(Path(scene_dir) / "gt" / "boxes.csv")
    wanted = {c.lower() for c in classes}
    cars = boxes[boxes["cls"].astype(str).str.lower().isin(wanted)]
    values = cars[BOX_FIELDS].to_numpy(dtype=np.float64)
    return {(int(f), int(t)): values[k] for k, (f, t) in enumerate(zip(cars["frame"], cars["track_id"]))}


def matched_targets(frame: np.ndarray, matched_track: np.ndarray,
                    boxes: dict[tuple[int, int], np.ndarray]) -> np.ndarray:
    """(D, 7) the matched ground-truth box of each detection, NaN rows where it has none."""
    out = np.full((len(frame), 7), np.nan)
    for i, (f, t) in enumerate(zip(frame, matched_track)):
        if t >= 0 and (int(f), int(t)) in boxes:
            out[i] = boxes[(int(f), int(t))]
    return out


def unmatched_gt_objects(scene_dir: str | Path, matched: set[tuple[int, int]], camera: str = "cam_front",
                         min_depth: float = 0.1, classes=("car",)) -> RawObjects:
    """Ground-truth cars that no detection matched, with the LiDAR points inside their instance masks."""
    scene_dir = Path(scene_dir)
    meta = sceneio.read_meta(scene_dir)
    K, size = sceneio.read_intrinsics(scene_dir / f"{camera}.txt")
    ext = sceneio.read_extrinsics(scene_dir / "extrinsics.json")
    T_camera_lidar = geometry.invert_pose(ext[camera]) @ ext[LIDAR]
    boxes = gt_car_boxes(scene_dir, classes)
    by_frame: dict[int, list[int]] = {}
    for (f, t) in boxes:
        if (f, t) not in matched:
            by_frame.setdefault(f, []).append(t)
    sets, frame, target, bbox = [], [], [], []
    for f in range(int(meta["n_frames"])):
        tracks = by_frame.get(f)
        if not tracks:
            continue
        instance = sceneio.read_label_png(scene_dir / "gt" / "instance" / camera / sceneio.frame_name(f, "png"))
        present = set(np.unique(instance).tolist())
        tracks = [t for t in tracks if t in present]
        if not tracks:
            continue
        sweep, _ = read_sweep(scene_dir / LIDAR / sceneio.frame_name(f, "bin"))
        fp = FramePoints(sweep, T_camera_lidar, K, size, min_depth)
        for t in tracks:
            pts = fp.in_mask(instance == t)
            sets.append(geometry.transform_points(ext[LIDAR], pts[:, :3].astype(np.float64)) if len(pts)
                        else np.zeros((0, 3)))
            rows, cols = np.nonzero(instance == t)
            bbox.append([cols.min() - 0.5, rows.min() - 0.5, cols.max() + 0.5, rows.max() + 0.5])
            frame.append(f)
            target.append(boxes[(f, t)])
    n = len(sets)
    return RawObjects(sets=sets, frame=np.asarray(frame, dtype=np.int64), detection=np.full(n, -1, dtype=np.int64),
                      track=np.full(n, -1, dtype=np.int64), score=np.ones(n), bbox=np.asarray(bbox).reshape(n, 4),
                      target=np.asarray(target).reshape(n, 7))
