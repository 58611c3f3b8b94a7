"""The frame KITTI AP is computed in: boxes upright in the *rectified camera* frame, as the devkit does.

The devkit (`evaluate_object.cpp` and its python port) intersects boxes (x, y, z, h, w, l, ry) of the
rectified camera 0 frame: a rotated rectangle in the camera's x-z plane and an interval along its y axis.
On real KITTI the vehicle (IMU) frame's up axis is tilted ~0.5 deg from the camera's vertical, so a box
upright in the vehicle frame is not the devkit's box; 3D IoU differs by up to ~0.005 and 3D AP by up to a
few AP. Every KITTI evaluation therefore moves boxes into the *upright camera frame* first:

    X = z_rect (forward), Y = -x_rect (left), Z = -y_rect (up)       (a proper rotation of rect0)

with (x, y, z, l, w, h, yaw) boxes, geometric centre and yaw about Z, the convention of
`redsup.det3d.boxes`. A KITTI label maps exactly: centre (cz, -cx, -(cy - h/2)), yaw = -ry - pi/2, and
the IoU of two boxes there equals the devkit's. Vehicle-frame boxes (training / detector output) are moved
with `to_eval_frame`: centre by the rigid transform, heading projected onto the camera's horizontal plane
(a box written as a KITTI label gets exactly this box). `adapters.kitti.label_to_row` chooses the
vehicle-frame heading whose projection back is the label's, so a label -> vehicle -> eval round trip is
exact to float precision.

A scene's transform is `meta["eval_frame"]["T_eval_vehicle"]` (written by the KITTI adapters); scenes
without it (the embedded world, whose camera and vehicle frames share the vertical) are evaluated in the
vehicle frame as before.
"""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from redsup import sceneio

NAME = "kitti_rect0_upright"
R_UPRIGHT_RECT = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def T_upright_rect() -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R_UPRIGHT_RECT
    return T


def eval_transform(T_vehicle_rect0: np.ndarray) -> np.ndarray:
    """T_eval_vehicle for a scene whose vehicle frame is T_vehicle_rect0 from rectified camera 0."""
    return T_upright_rect() @ np.linalg.inv(np.asarray(T_vehicle_rect0, dtype=np.float64))


def meta_entry(T_vehicle_rect0: np.ndarray) -> dict:
    return {"name": NAME, "T_eval_vehicle": eval_transform(T_vehicle_rect0).tolist()}


def scene_eval_transform(scene_dir: str | Path) -> np.ndarray | None:
    """The scene's T_eval_vehicle, or None where boxes are evaluated in the vehicle frame."""
    entry = sceneio.read_meta(scene_dir).get("eval_frame")
    if not entry:
        return None
    T = np.asarray(entry["T_eval_vehicle"], dtype=np.float64)
    if T.shape != (4, 4):
        raise ValueError(f"{Path(scene_dir) / 'scene.json'}: eval_frame.T_eval_vehicle has shape {T.shape}, not (4, 4)")
    return T


def wrap_angle(a):
    return (np.asarray(a, dtype=np.float64) + np.pi) % (2 * np.pi) - np.pi


def to_eval_frame(boxes: np.ndarray, T_eval_vehicle: np.ndarray | None) -> np.ndarray:
    """(N, 7) vehicle-frame boxes as boxes upright in the evaluation frame (unchanged when T is None)."""
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    if T_eval_vehicle is None or len(boxes) == 0:
        return boxes.copy()
    T = np.asarray(T_eval_vehicle, dtype=np.float64)
    out = boxes.copy()
    out[:, :3] = boxes[:, :3] @ T[:3, :3].T + T[:3, 3]
    heading = np.stack([np.cos(boxes[:, 6]), np.sin(boxes[:, 6]), np.zeros(len(boxes))], axis=1) @ T[:3, :3].T
    out[:, 6] = np.arctan2(heading[:, 1], heading[:, 0])
    return out


def label_box(cx: float, cy: float, cz: float, h: float, w: float, l: float, ry: float) -> np.ndarray:
    """A KITTI label's 3D box (location = bottom centre in rect0, rotation_y) in the evaluation frame."""
    return np.array([cz, -cx, -(cy - h / 2.0), l, w, h, float(wrap_angle(-ry - math.pi / 2.0))])


def label_fields(box) -> dict:
    """Inverse of `label_box`: KITTI location (bottom centre), dimensions and rotation_y of an eval box."""
    x, y, z, l, w, h, yaw = (float(v) for v in box)
    return {"cx": -y, "cy": -z + h / 2.0, "cz": x, "h": h, "w": w, "l": l,
            "ry": float(wrap_angle(-yaw - math.pi / 2.0))}


def heading_keeping_projection(R_dst_src: np.ndarray, heading_src: np.ndarray, up_src: np.ndarray,
                               up_dst: np.ndarray) -> np.ndarray:
    """Unit heading in the plane normal to `up_dst` whose projection back onto the plane normal to
    `up_src` is `heading_src` (moved by R_dst_src): the heading of span(R h, R up_src) on that plane."""
    d = R_dst_src @ heading_src
    m = np.cross(d, R_dst_src @ up_src)
    v = np.cross(up_dst, m)
    if np.linalg.norm(v) < 1e-12:       # heading along the tilt axis' normal: projection is the same
        v = d - np.dot(d, up_dst) * up_dst
    v = v / np.linalg.norm(v)
    return v if np.dot(v, d) >= 0 else -v


def frames_to_eval(frames: list, T_eval_vehicle: np.ndarray | None) -> list:
    """FrameGT / FrameDet objects with their 3D boxes moved by `to_eval_frame` (new objects)."""
    if T_eval_vehicle is None:
        return list(frames)
    return [replace(f, boxes=to_eval_frame(f.boxes, T_eval_vehicle)) for f in frames]
