"""KITTI AP of lifted boxes on a split (McCraith ch. 6: single frames, every 2D detection, score = mask score).

Ground truth = `gt/boxes.csv` of every frame of the scenes (`redsup.det3d.scenes.gt_frames`); 2D boxes of
ground truth and detections are scaled to KITTI-camera pixels (`redsup.det3d.kitti_pixels`) so that the
easy / moderate / hard height cuts mean what they mean on KITTI. 3D boxes of KITTI scenes are evaluated
upright in the rectified camera frame, as the devkit (`redsup.eval_frame`). Detections that could not be lifted
(no or too few LiDAR points) are simply absent (a miss if they were a car).

Returns `kitti_eval.evaluate`'s flat dict, e.g. `Car_bev_0.5/moderate_R40`, `Car_3d_0.7/easy_R11`, plus
`n_gt/easy` ... (valid ground-truth cars per difficulty, named as the chapter-7 stage names them).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from redsup import sceneio
from redsup.det3d.kitti_eval import DIFFICULTIES, MAX_OCCLUSION, MAX_TRUNCATION, MIN_HEIGHT, bootstrap_ap, evaluate
from redsup.det3d.kitti_pixels import kitti_pixel_scale, scale_frames
from redsup.det3d.scenes import gt_frames
from redsup.eval_frame import frames_to_eval, scene_eval_transform
from redsup.lifting.data import ObjectTable
from redsup.lifting.postprocess import frame_detections


def split_frames(scene_dirs: list[str | Path], table: ObjectTable, boxes: np.ndarray, camera: str = "cam_front",
                 reference_focal: float | None = None) -> tuple[list, list]:
    """(ground-truth frames, detection frames) of every frame of the scenes, 2D boxes in KITTI pixels."""
    gts, dets = [], []
    for k, scene_dir in enumerate(scene_dirs):
        K, _ = sceneio.read_intrinsics(Path(scene_dir) / f"{camera}.txt")
        scale = kitti_pixel_scale(K) if reference_focal is None else kitti_pixel_scale(K, reference_focal)
        T_eval = scene_eval_transform(scene_dir)     # KITTI: upright in rect0, as the devkit
        g = gt_frames(scene_dir)
        gts += scale_frames(frames_to_eval(g, T_eval), scale)
        dets += scale_frames(frames_to_eval(frame_detections(table, boxes, k, len(g)), T_eval), scale)
    return gts, dets


def evaluate_frames(gts: list, dets: list, iou_thresholds=(0.7, 0.5)) -> dict[str, float]:
    """AP_BEV and AP_3D (R11, R40) at the thresholds, plus `n_gt/<difficulty>` (valid cars)."""
    metrics = evaluate(gts, dets, metrics=("bev", "3d"), iou_thresholds={"Car": tuple(iou_thresholds)})
    metrics.update({k: float(v) for k, v in valid_gt_counts(gts).items()})
    return metrics


def frame_ids(scene_dirs: list[str | Path]) -> list[str]:
    """One id a test frame, in `split_frames`' order ("<scene folder>/<frame>"): the bootstrap's units."""
    return [f"{Path(d).name}/{f}" for d in scene_dirs for f in range(int(sceneio.read_meta(Path(d))["n_frames"]))]


def sampling_noise(gts: list, dets: list, scene_dirs: list[str | Path], ious: tuple[float, ...], n: int,
                   difficulties: tuple[str, ...] = ("moderate",)) -> dict:
    """Test-sampling noise of the split's moderate AP_BEV (the column the ch. 6 claims and the ch. 7 table's
    lifting row are decided on) at each IoU of ``ious``: ``bootstrap_ap`` on ``n`` resamples of its frames ({} when
    ``n`` is 0). Other columns keep their seed spread only (a resample costs two matching passes a column)."""
    if n <= 0:
        return {}
    return bootstrap_ap(gts, dets, frame_ids(scene_dirs), tuple(("bev", float(iou)) for iou in ious), n,
                        difficulties=difficulties)


def evaluate_split(scene_dirs, table: ObjectTable, boxes: np.ndarray, camera: str = "cam_front",
                   iou_thresholds=(0.7, 0.5), reference_focal: float | None = None) -> dict[str, float]:
    gts, dets = split_frames(scene_dirs, table, boxes, camera, reference_focal)
    return evaluate_frames(gts, dets, iou_thresholds)


def valid_gt_counts(gts: list) -> dict[str, int]:
    """Valid (not ignored) cars per difficulty as the devkit counts them; AP needs >= 41 to reach 100."""
    out = {}
    for d, name in enumerate(DIFFICULTIES):
        n = 0
        for g in gts:
            cls = np.array([str(c).lower() for c in g.cls])
            height = np.nan_to_num(np.asarray(g.bbox)[:, 3] - np.asarray(g.bbox)[:, 1], nan=0.0) if len(cls) else 0
            ok = ((cls == "car") & (np.asarray(g.occlusion) <= MAX_OCCLUSION[d])
                  & (np.asarray(g.truncation) <= MAX_TRUNCATION[d]) & (height > MIN_HEIGHT[d]))
            n += int(np.count_nonzero(ok))
        out[f"n_gt/{name}"] = n
    return out
