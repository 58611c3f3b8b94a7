"""Sparse LiDAR depth maps per camera frame (Galteland §3.6.2.3, eq. 3.29-3.32).

Depth maps are written at the cropped but not resized resolution (the KITTI evaluation convention:
predictions are resized to the ground truth), with the intrinsics of that crop.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from tqdm import tqdm

from redsup import geometry, sceneio
from redsup.fileio import save_npz_atomic

LIDAR = "lidar_top"


def frame_depth(points: np.ndarray, T_lidar_to_cam: np.ndarray, K: np.ndarray,
                size: tuple[int, int], depth_range: tuple[float, float]) -> np.ndarray:
    """Sparse depth image of one sweep seen from one camera."""
    cam_points = geometry.transform_points(T_lidar_to_cam, points[:, :3].astype(np.float64))
    return geometry.sparse_depth_map(cam_points, K, size[0], size[1], depth_range)


def lidar_depth_maps(scene_dir: str | Path, camera: str, crop: dict, depth_range: tuple[float, float],
                     out_path: str | Path) -> dict:
    """Write `<camera>_depth.npz`: depth (T, h, w) float32 (0 = no return) and K of the crop.

    When the scene carries the renderer's depth buffer (gt/depth), the summary includes the median
    relative error of the projected LiDAR against it on pixels where both exist.
    """
    scene_dir = Path(scene_dir)
    meta = sceneio.read_meta(scene_dir)
    K_raw, (width, height) = sceneio.read_intrinsics(scene_dir / f"{camera}.txt")
    poses = sceneio.read_poses(scene_dir / "ego_poses.txt")
    extrinsics = sceneio.read_extrinsics(scene_dir / "extrinsics.json")
    for sensor in (camera, LIDAR):
        if sensor not in extrinsics:
            raise sceneio.SceneError(f"{scene_dir / 'extrinsics.json'}: no extrinsics for '{sensor}'")
    n = meta["n_frames"]
    if len(poses) != n:
        raise sceneio.SceneError(f"{scene_dir / 'ego_poses.txt'}: {len(poses)} poses for {n} frames")
    sweeps = sceneio.sensor_frames(scene_dir, LIDAR, "bin", n)
    K = geometry.crop_intrinsics(K_raw, crop["left"], crop["top"])
    size = (width - crop["left"] - crop["right"], height - crop["top"] - crop["bottom"])
    gt_dir = scene_dir / "gt" / "depth" / camera
    depth = np.zeros((n, size[1], size[0]), dtype=np.float32)
    errors, densities = [], []
    for i, sweep in enumerate(tqdm(sweeps, desc=f"{scene_dir.name}/{camera} depth", mininterval=5)):
        T = geometry.lidar_to_camera(extrinsics[LIDAR], poses[i], poses[i], extrinsics[camera])
        depth[i] = frame_depth(sceneio.read_lidar(sweep), T, K, size, depth_range)
        densities.append(float((depth[i] > 0).mean()))
        gt_path = gt_dir / sceneio.frame_name(i, "png")
        if gt_path.exists():
            buffer = sceneio.read_depth_png(gt_path)[crop["top"]:height - crop["bottom"],
                                                     crop["left"]:width - crop["right"]]
            errors.append(geometry.median_relative_error(depth[i], buffer))
    save_npz_atomic(out_path, depth=depth, K=K, crop=np.array([crop["top"], crop["bottom"],
                                                              crop["left"], crop["right"]]))
    summary = {"frames": n, "valid_pixel_fraction": float(np.mean(densities))}
    if errors:
        summary["lidar_vs_render_median_rel_error"] = float(np.nanmedian(errors))
    return summary
