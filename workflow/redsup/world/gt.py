"""Ground-truth boxes per frame: 3D box in the vehicle frame, world velocity, KITTI occlusion level and
truncation, tight 2D box of the visible pixels in cam_front, visible pixel and LiDAR return counts.

Occlusion compares the object's visible pixels (instance buffer) with its unoccluded pixels: the rays
its own boxes intersect, counted from the renderer's ray/primitive pairs (as if it were rendered alone).
"""
from __future__ import annotations

import numpy as np

from .common import rotate
from .prims import CAR_KINDS, Prims
from .raycast import Pairs
from .sensors import box_corners

COLUMNS = ["frame", "track_id", "cls", "x", "y", "z", "l", "w", "h", "yaw", "vx", "vy", "vz", "occlusion",
           "truncation", "x1", "y1", "x2", "y2", "visible_px", "n_lidar"]


def occlusion_level(visible: np.ndarray, own: np.ndarray, fractions) -> np.ndarray:
    """KITTI levels: 0 fully visible, 1 partly, 2 largely occluded, 3 unknown (not in the image)."""
    frac = np.where(own > 0, visible / np.maximum(own, 1), 0.0)
    level = np.where(frac >= fractions[0], 0, np.where(frac >= fractions[1], 1, 2))
    return np.where(own > 0, level, 3)


def own_pixels(pairs: Pairs, prims: Prims, n_cars: int) -> np.ndarray:
    """Per car-table row: number of rays (pixels) its boxes intersect, ignoring every other surface."""
    box = pairs.prim < prims.n_box
    ray, prim = pairs.ray[box], pairs.prim[box]
    car = np.isin(prims.kind[prim], CAR_KINDS)
    ent = prims.ent[prim[car]].astype(np.int64)
    keys = np.unique(ent * (int(ray.max(initial=0)) + 1) + ray[car])
    return np.bincount(keys // (int(ray.max(initial=0)) + 1), minlength=n_cars)[:n_cars]


def instance_boxes(instance: np.ndarray, max_id: int):
    """Per id 0..max_id: visible pixel count and tight box (x1, y1, x2, y2) in continuous pixel
    coordinates (pixel (u, v) covers [u - 0.5, u + 0.5]); NaN where not visible."""
    v, u = np.nonzero(instance)
    ids = instance[v, u].astype(np.int64)
    count = np.bincount(ids, minlength=max_id + 1)[:max_id + 1]
    lo_u = np.full(max_id + 1, np.inf)
    hi_u = np.full(max_id + 1, -np.inf)
    lo_v, hi_v = lo_u.copy(), hi_u.copy()
    np.minimum.at(lo_u, ids, u)
    np.maximum.at(hi_u, ids, u)
    np.minimum.at(lo_v, ids, v)
    np.maximum.at(hi_v, ids, v)
    box = np.stack([lo_u - 0.5, lo_v - 0.5, hi_u + 0.5, hi_v + 0.5], axis=1)
    box[count == 0] = np.nan
    return count, box


def truncation(cam, corners_cam: np.ndarray) -> np.ndarray:
    """Fraction of each projected 3D box's bounding rectangle outside the image (1 if behind)."""
    u_lo, u_hi, v_lo, v_hi, front = cam.project_bounds(corners_cam)
    area = np.maximum(u_hi - u_lo, 1e-9) * np.maximum(v_hi - v_lo, 1e-9)
    iw = np.clip(np.minimum(u_hi, cam.width - 0.5) - np.maximum(u_lo, -0.5), 0, None)
    ih = np.clip(np.minimum(v_hi, cam.height - 0.5) - np.maximum(v_lo, -0.5), 0, None)
    return np.where(front, np.clip(1.0 - iw * ih / area, 0.0, 1.0), 1.0)


def car_boxes_world(pos: np.ndarray, rot: np.ndarray, size: np.ndarray):
    """Geometric centres (N, 3) of the cars' full boxes (ground to roof)."""
    return pos + rot[:, :, 2] * (size[:, 2:3] / 2)


def frame_rows(frame: int, car_pos, car_rot, car_vel, cars: dict, T_world_vehicle, cam, T_world_cam,
               instance: np.ndarray, own: np.ndarray, n_lidar_by_track: np.ndarray, gt_cfg: dict) -> list:
    """CSV rows (lists, COLUMNS order) of the cars within gt range of the ego vehicle at one frame."""
    T_vw = np.linalg.inv(T_world_vehicle)
    rel = car_pos - T_world_vehicle[:3, 3]
    near = np.nonzero(np.hypot(rel[:, 0], rel[:, 1]) <= gt_cfg["range"])[0]
    if len(near) == 0:
        return []
    size = cars["size"][near]
    tid = cars["track_id"][near]
    centre_w = car_boxes_world(car_pos[near], car_rot[near], size)
    centre_v = rotate(centre_w, T_vw[:3, :3]) + T_vw[:3, 3]
    fwd_v = rotate(car_rot[near, :, 0], T_vw[:3, :3])
    yaw = np.arctan2(fwd_v[:, 1], fwd_v[:, 0])
    max_id = int(cars["track_id"].max())
    count, box = instance_boxes(instance, max_id)
    T_cw = np.linalg.inv(T_world_cam)
    corners = box_corners(centre_w, car_rot[near], size / 2)
    trunc = truncation(cam, rotate(corners, T_cw[:3, :3]) + T_cw[:3, 3])
    visible = count[tid]
    occ = occlusion_level(visible, own[near], gt_cfg["occlusion_fractions"])
    nl = n_lidar_by_track[tid] if len(n_lidar_by_track) > max_id else np.zeros(len(near), np.int64)
    rows = []
    for k in range(len(near)):
        rows.append([frame, int(tid[k]), "Car", *np.round(centre_v[k], 4), *np.round(size[k], 4),
                     round(float(yaw[k]), 5), *np.round(car_vel[near[k]], 4), int(occ[k]),
                     round(float(trunc[k]), 4), *np.round(box[tid[k]], 2), int(visible[k]), int(nl[k])])
    return rows
