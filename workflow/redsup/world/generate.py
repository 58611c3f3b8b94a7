"""`write_scene`: render one scene of the embedded world into the canonical raw-scene format.

The scene is written into a temporary sibling folder and renamed at the end, so a crash leaves no
partial scene behind. Generation is deterministic given (seed, domain, split, index) and the config.
"""
from __future__ import annotations

import csv
import json
import os
import shutil
import time
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from ..sceneio import write_intrinsics
from .common import SPLIT_CODES, derive_rng
from .gt import COLUMNS, frame_rows, own_pixels
from .layout import build_world, frame_state
from .lidar import sweep
from .sensors import make_rig
from .shade import SceneView, render_camera

SPLITS = ("train", "val", "test", "long")
PNG = [cv2.IMWRITE_PNG_COMPRESSION, 1]


def write_png(path: Path, image: np.ndarray) -> None:
    if image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
    if not cv2.imwrite(str(path), image, PNG):
        raise OSError(f"{path}: could not write PNG")


def write_jpg(path: Path, image: np.ndarray, quality: int) -> None:
    """An RGB image as a baseline JPEG of IJG ``quality``."""
    if not cv2.imwrite(str(path), cv2.cvtColor(image, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, int(quality)]):
        raise OSError(f"{path}: could not write JPEG")


def depth_png(depth: np.ndarray) -> np.ndarray:
    """KITTI convention: uint16 value / 256 = metres; 0 where there is no surface or beyond 255.99 m."""
    value = np.round(depth * 256.0)
    return np.where((value > 0) & (value < 65536), value, 0).astype(np.uint16)


def temp_dir_for(out_dir: Path) -> Path:
    tmp = out_dir.parent / f".{out_dir.name}.tmp{os.getpid()}"
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir(parents=True)
    return tmp


def publish(tmp: Path, out_dir: Path) -> None:
    if out_dir.exists():
        shutil.rmtree(out_dir)
    tmp.rename(out_dir)


def write_scene(world_cfg: dict, dataset: str, domain: str, split: str, index: int, seed: int,
                out_dir: str | Path) -> dict:
    """Render scene `index` of `split` of `domain` into `out_dir`; returns summary numbers."""
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    if domain not in world_cfg["domains"]:
        raise ValueError(f"unknown world domain {domain!r} (have {sorted(world_cfg['domains'])})")
    start = time.time()
    dom = world_cfg["domains"][domain]
    n_frames = int(world_cfg["frames"][split])
    fps = float(world_cfg["fps"])
    world = build_world(world_cfg, dom, derive_rng(seed, "scene", domain, SPLIT_CODES.get(split, split), index), n_frames)
    cams, lidar = make_rig(dom, world_cfg["rig"], world_cfg["lidar"])
    view = SceneView(world.road, world.style, world.cars, world.buildings)
    out_dir = Path(out_dir)
    tmp = temp_dir_for(out_dir)
    try:
        meta = {"scene": out_dir.name, "dataset": dataset, "domain": domain, "split": split, "fps": fps,
                "n_frames": n_frames, "cameras": [c.name for c in cams], "lidars": [lidar.name], "seed": int(seed)}
        (tmp / "scene.json").write_text(json.dumps(meta, indent=1))
        extr = {s.name: np.round(s.T_vehicle_sensor, 9).tolist() for s in [*cams, lidar]}
        (tmp / "extrinsics.json").write_text(json.dumps(extr, indent=1))
        for cam in cams:
            write_intrinsics(tmp / f"{cam.name}.txt", cam.K, (cam.width, cam.height))
            for sub in ("", "gt/instance/", "gt/semantic/", "gt/depth/"):
                (tmp / f"{sub}{cam.name}").mkdir(parents=True)
        (tmp / lidar.name).mkdir()
        stats = _render_frames(world, world_cfg, dom, cams, lidar, view, n_frames, tmp,
                               derive_rng(seed, "frames", domain, SPLIT_CODES.get(split, split), index))
        poses = world.ego.poses[:, :3, :].reshape(n_frames, 12)
        np.savetxt(tmp / "ego_poses.txt", poses, fmt="%.9f")
        publish(tmp, out_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    ego = world.ego
    return {"frames": n_frames, "cameras": len(cams), "lidar_points_per_sweep": stats["points"] / n_frames,
            "glass_passthrough_fraction": stats["passed"] / max(stats["points"], 1),
            "cars_per_frame": stats["rows"] / n_frames, "visible_cars_per_frame": stats["visible"] / n_frames,
            "car_lidar_points_per_frame": stats["car_points"] / n_frames,
            "mean_ego_speed": float(ego.v.mean()), "stationary_fraction": float(np.mean(ego.v < 0.1)),
            "ego_pitch_std_deg": float(np.degrees(ego.pitch.std())),
            "road_grade_range": float(np.ptp(world.road.slope(ego.s))), "seconds": time.time() - start}


def _render_frames(world, cfg, dom, cams, lidar, view, n_frames, folder: Path, rng) -> dict:
    reach = cfg["render_distance"] + 30.0
    stats = {"points": 0, "passed": 0, "rows": 0, "visible": 0, "car_points": 0}
    n_cars = len(world.cars["size"])
    max_id = int(world.cars["track_id"].max()) if n_cars else 0
    with open(folder / "gt" / "boxes.csv", "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(COLUMNS)
        for i in tqdm(range(n_frames), desc=f"render {folder.name}", unit="frame", mininterval=5):
            state = frame_state(world, i, reach)
            name = f"{i:06d}"
            T_wl = state.T_world_vehicle @ lidar.T_vehicle_sensor
            sw = sweep(lidar, T_wl, state.prims, view, cfg["lidar"], rng)
            sw["points"].tofile(folder / lidar.name / f"{name}.bin")
            n_lidar = np.bincount(sw["instance"].astype(np.int64), minlength=max_id + 1)
            stats["points"] += len(sw["points"])
            stats["passed"] += int(sw["passed"].sum())
            stats["car_points"] += int((sw["instance"] > 0).sum())
            for cam in cams:
                T_wc = state.T_world_vehicle @ cam.T_vehicle_sensor
                out = render_camera(cam, T_wc, state.prims, view, dom["appearance"], cfg["pixel_noise"],
                                    cfg["render_distance"], cfg["fog_distance"], rng)
                write_png(folder / cam.name / f"{name}.png", out["rgb"])
                write_png(folder / "gt" / "instance" / cam.name / f"{name}.png", out["instance"])
                write_png(folder / "gt" / "semantic" / cam.name / f"{name}.png", out["label"])
                write_png(folder / "gt" / "depth" / cam.name / f"{name}.png", depth_png(out["depth"]))
                if cam.name == "cam_front":
                    own = own_pixels(out["pairs"], state.prims, n_cars)
                    rows = frame_rows(i, state.car_pos, state.car_rot, state.car_vel, world.cars,
                                      state.T_world_vehicle, cam, T_wc, out["instance"], own, n_lidar, cfg["gt"])
                    writer.writerows(rows)
                    stats["rows"] += len(rows)
                    stats["visible"] += sum(1 for r in rows if r[19] > 0)
    return stats
