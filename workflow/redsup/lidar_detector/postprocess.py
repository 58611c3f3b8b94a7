"""Inference from LiDAR only: heatmap peaks -> boxes -> rotated BEV non-maximum suppression -> camera view.

A peak is a cell whose heatmap probability is the maximum of its 3 x 3 neighbourhood and at least
`score_threshold`; the `max_peaks` highest are decoded: centre = cell corner + offset, yaw = centre of the
arg-max bin, size = the template's (the † rows) or template size x exp(size head). Greedy NMS in BEV
(`redsup.det3d.boxes.bev_iou` > `nms_iou` suppresses) keeps at most `max_detections`. Score = heatmap
value. Detections outside the front camera's view are dropped; the others get the 2D box of their
projected corners (`boxes_to_image_bbox`) for the KITTI difficulty rules.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from redsup.det3d.boxes import bev_iou, boxes_to_image_bbox
from redsup.det3d.kitti_types import FrameDet
from redsup.det3d.losses import yaw_bin_centers
from redsup.det3d.voting import BevGrid


@dataclass(frozen=True)
class InferSpec:
    score_threshold: float = 0.05
    max_peaks: int = 100
    nms_iou: float = 0.1
    max_detections: int = 50

    @classmethod
    def from_config(cls, cfg: dict) -> "InferSpec":
        return cls(float(cfg["score_threshold"]), int(cfg["max_peaks"]), float(cfg["nms_iou"]),
                   int(cfg["max_detections"]))


def heatmap_peaks(heat: torch.Tensor, max_peaks: int, threshold: float, kernel: int = 3):
    """(rows, cols, scores) of the local maxima of a (H, W) probability map, best first."""
    hmax = F.max_pool2d(heat[None, None], kernel, stride=1, padding=kernel // 2)[0, 0]
    keep = (heat >= hmax) & (heat >= threshold)
    rows, cols = torch.nonzero(keep, as_tuple=True)
    scores = heat[rows, cols]
    order = torch.argsort(scores, descending=True, stable=True)[:max_peaks]
    return rows[order], cols[order], scores[order]


def decode_boxes(grid: BevGrid, offset: torch.Tensor, yaw_logits: torch.Tensor, rows: torch.Tensor,
                 cols: torch.Tensor, template_size, size: torch.Tensor | None = None) -> np.ndarray:
    """(K, 7) boxes from one frame's maps (offset (3, H, W), yaw_logits (K, H, W), size (3, H, W) or None)."""
    off = offset[:, rows, cols].T
    centre = grid.decode(rows, cols, off)
    bins = yaw_bin_centers(yaw_logits.shape[0], dtype=off.dtype, device=off.device)
    yaw = bins[yaw_logits[:, rows, cols].argmax(dim=0)]
    base = torch.as_tensor(np.asarray(template_size, dtype=np.float32), device=off.device, dtype=off.dtype)
    dims = base.expand(len(rows), 3) if size is None else base * torch.exp(size[:, rows, cols].T.clamp(-1.0, 1.0))
    return torch.cat([centre, dims, yaw[:, None]], dim=1).detach().cpu().numpy().astype(np.float64)


def nms_bev(boxes: np.ndarray, scores: np.ndarray, iou_threshold: float, max_keep: int | None = None) -> np.ndarray:
    """Indices kept by greedy rotated-box NMS in BEV (highest score first; IoU > threshold suppresses)."""
    order = np.argsort(-np.asarray(scores), kind="stable")
    if len(order) == 0:
        return order
    iou = bev_iou(boxes[order], boxes[order])
    suppressed = np.zeros(len(order), dtype=bool)
    keep = []
    for i in range(len(order)):
        if suppressed[i]:
            continue
        keep.append(order[i])
        if max_keep is not None and len(keep) >= max_keep:
            break
        suppressed |= iou[i] > iou_threshold
    return np.asarray(keep, dtype=np.int64)


def camera_view(boxes: np.ndarray, K: np.ndarray, T_camera_vehicle: np.ndarray,
                image_size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(keep (N,) bool, bbox (N, 4)): boxes with a projected 2D box in the image (others outside the view)."""
    bbox = boxes_to_image_bbox(boxes, T_camera_vehicle, K, image_size)
    return np.isfinite(bbox).all(axis=1), bbox


def detect_frame(grid: BevGrid, outputs: dict[str, torch.Tensor], b: int, spec: InferSpec, template_size,
                 camera: tuple[np.ndarray, np.ndarray, tuple[int, int]]) -> FrameDet:
    """Detections of frame b of a batch of outputs, as a KITTI FrameDet."""
    heat = torch.sigmoid(outputs["heatmap"][b, 0].float())
    rows, cols, scores = heatmap_peaks(heat, spec.max_peaks, spec.score_threshold)
    size = outputs["size"][b].float() if "size" in outputs else None
    boxes = decode_boxes(grid, outputs["offset"][b].float(), outputs["yaw"][b].float(), rows, cols, template_size,
                         size)
    scores = scores.detach().cpu().numpy().astype(np.float64)
    keep = nms_bev(boxes, scores, spec.nms_iou, spec.max_detections)
    boxes, scores = boxes[keep], scores[keep]
    K, T, size_wh = camera
    visible, bbox = camera_view(boxes, K, T, size_wh)
    return FrameDet(boxes=boxes[visible], bbox=bbox[visible], score=scores[visible])
