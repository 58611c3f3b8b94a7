"""Network outputs -> 3D boxes (McCraith ch. 6 test time).

Box = the posed template's tight box g B_0: centre = the predicted translation, yaw = the yaw head's test-time
yaw (arg-max bin / atan2 / selected hypothesis; no search at test time), size = the FIXED template size
(`redsup.det3d.template.TemplateSpec`, 3.9 x 1.6 x 1.5 m; the method predicts no size). Score = the 2D
detector's mask score.
"""
from __future__ import annotations

import numpy as np
import torch

from redsup.det3d.kitti_types import FrameDet
from redsup.lifting.data import ObjectTable
from redsup.lifting.frames import to_vehicle, wrap_angle


@torch.no_grad()
def predict_boxes(model, table: ObjectTable, size, batch_size: int = 512) -> np.ndarray:
    """(N, 7) vehicle-frame boxes (x, y, z, l, w, h, yaw) for every object of the table."""
    model.eval()
    out_boxes = np.zeros((len(table), 7))
    size = np.asarray(size, dtype=np.float64)
    for s in range(0, len(table), batch_size):
        idx = np.arange(s, min(len(table), s + batch_size))
        b = table.batch(idx)
        out = model(b.points, b.mask, b.context)
        t_v, yaw_v = to_vehicle(out["translation"], model.yaw.decode(out), b.centre, b.azimuth)
        out_boxes[idx, :3] = t_v.double().cpu().numpy()
        out_boxes[idx, 3:6] = size
        out_boxes[idx, 6] = wrap_angle(yaw_v.double()).cpu().numpy()
    return out_boxes


def frame_detections(table: ObjectTable, boxes: np.ndarray, scene: int, n_frames: int) -> list[FrameDet]:
    """FrameDet per frame of one scene of the table (score = mask score, 2D box = the mask's box)."""
    sel = table.scene == scene
    frames = table.frame[sel]
    out = []
    for f in range(n_frames):
        m = frames == f
        out.append(FrameDet(boxes=boxes[sel][m].reshape(-1, 7), bbox=table.bbox[sel][m].reshape(-1, 4),
                            score=table.score[sel][m]))
    return out
