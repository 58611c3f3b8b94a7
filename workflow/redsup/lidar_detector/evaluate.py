"""Inference on a split and KITTI-style AP (BEV and 3D at IoU 0.7 and 0.5, R11 and R40).

The 2D boxes of ground truth and detections (the difficulty cuts only) are scaled to KITTI-camera pixels
(`redsup.det3d.kitti_pixels`, as the ch. 6 stage does) unless `kitti_pixels=False`: "easy" then means a
car of KITTI height nearer than about 27 m, as on KITTI, instead of 9 m on the world's 243 px camera.

Besides `kitti_eval.evaluate`'s flat dict the metrics carry `n_gt/<difficulty>` (valid ground-truth cars
per difficulty: AP needs at least 41 for a perfect detector to reach 100, see `kitti_eval`),
`n_detections`, `frames` and `infer_fps` (network + decoding + NMS, frames per second).
"""
from __future__ import annotations

import time

import numpy as np
import torch

from redsup import eval_frame
from redsup.det3d import kitti_eval
from redsup.det3d.kitti_pixels import kitti_pixel_scale, scale_frames
from redsup.det3d.kitti_types import FrameDet, FrameGT
from redsup.lidar_detector.data import SplitData
from redsup.lidar_detector.grid import GridSpec
from redsup.lidar_detector.model import CenterDetector
from redsup.lidar_detector.postprocess import InferSpec, detect_frame


@torch.no_grad()
def predict(model: CenterDetector, data: SplitData, grid: GridSpec, spec: InferSpec, template_size,
            device: str = "cpu", batch: int = 4) -> tuple[list[FrameDet], float]:
    """Detections of every frame of `data` and the seconds spent."""
    model.eval()
    bev = grid.bev()
    dets: list[FrameDet] = []
    t0 = time.perf_counter()
    for s in range(0, data.n_frames, batch):
        frames = list(range(s, min(s + batch, data.n_frames)))
        out = model([torch.from_numpy(data.points(f)).to(device) for f in frames])
        dets += [detect_frame(bev, out, b, spec, template_size, data.camera(f)) for b, f in enumerate(frames)]
    return dets, time.perf_counter() - t0


def valid_gt_counts(gts: list[FrameGT], cls: str = "car") -> dict[str, int]:
    """Valid (not ignored) ground-truth objects per difficulty, by the devkit's rules."""
    out = {}
    for d, name in enumerate(kitti_eval.DIFFICULTIES):
        n = 0
        for g in gts:
            height = np.nan_to_num(np.asarray(g.bbox, dtype=float)[:, 3] - np.asarray(g.bbox, dtype=float)[:, 1]) \
                if len(g.cls) else np.zeros(0)
            same = np.array([str(c).lower() == cls for c in g.cls], dtype=bool)
            ok = same & (np.asarray(g.occlusion) <= kitti_eval.MAX_OCCLUSION[d]) \
                & (np.asarray(g.truncation) <= kitti_eval.MAX_TRUNCATION[d]) & (height > kitti_eval.MIN_HEIGHT[d])
            n += int(ok.sum())
        out[f"n_gt/{name}"] = n
    return out


def eval_frames(data: SplitData, dets: list[FrameDet], kitti_pixels: bool = True) -> tuple[list[FrameGT], list[FrameDet]]:
    """(ground truth, detections) of every frame in the evaluation frame (the devkit's rectified camera), 2D boxes
    in KITTI-camera pixels when ``kitti_pixels``."""
    gts = [eval_frame.frames_to_eval([data.frame_gt(f)], data.eval_transform(f))[0] for f in range(data.n_frames)]
    eval_dets = [eval_frame.frames_to_eval([d], data.eval_transform(f))[0] for f, d in enumerate(dets)]
    if kitti_pixels:
        scales = [kitti_pixel_scale(data.camera(f)[0]) for f in range(data.n_frames)]
        gts = [scale_frames([g], s)[0] for g, s in zip(gts, scales)]
        eval_dets = [scale_frames([d], s)[0] for d, s in zip(eval_dets, scales)]
    return gts, eval_dets


def frame_ids(data: SplitData) -> list[str]:
    """One id a test frame (scene index / frame index in the scene): the bootstrap's units."""
    return [f"lidar_detector:{int(s)}/{int(i)}" for s, i in zip(data.arrays["frame_scene"], data.arrays["frame_index"])]


def sampling_noise(data: SplitData, dets: list[FrameDet], n: int, iou: float = 0.7, kitti_pixels: bool = True) -> dict:
    """``kitti_eval.bootstrap_ap`` of AP_BEV at ``iou`` over the frames of ``data`` ({} when ``n`` is 0)."""
    if n <= 0:
        return {}
    gts, eval_dets = eval_frames(data, dets, kitti_pixels)
    return kitti_eval.bootstrap_ap(gts, eval_dets, frame_ids(data), (("bev", iou),), n)


def evaluate_split(model: CenterDetector, data: SplitData, grid: GridSpec, spec: InferSpec, template_size,
                   device: str = "cpu", iou_thresholds: tuple[float, ...] = (0.7, 0.5),
                   kitti_pixels: bool = True) -> tuple[dict, list[FrameDet]]:
    """(metrics, detections in the world camera's pixels) of `model` on every frame of `data`."""
    dets, seconds = predict(model, data, grid, spec, template_size, device)
    gts, eval_dets = eval_frames(data, dets, kitti_pixels)
    metrics = kitti_eval.evaluate(gts, eval_dets, metrics=("bev", "3d"), iou_thresholds={"Car": tuple(iou_thresholds)})
    metrics.update({k: float(v) for k, v in valid_gt_counts(gts).items()})
    metrics["n_detections"] = float(sum(len(d.score) for d in dets))
    metrics["frames"] = float(data.n_frames)
    metrics["infer_fps"] = data.n_frames / seconds if seconds > 0 else float("nan")
    return metrics, dets
