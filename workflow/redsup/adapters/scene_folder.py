"""Scene-folder datasets (Galteland §3.6.1: Lyft, DDAD, NAP-lab after extraction) into the canonical format.

Input, one folder per scene under `path` (README.md, "Running on the real datasets"):

    <scene>/<folder>/<frames>.png|.jpg      images of one camera, in natural name order (frame i of every
                                            camera is the same instant)
    <scene>/<folder>.txt                    intrinsics: rows `fx 0 cx`, `0 fy cy`, `0 0 1` (optionally a 4th
                                            row `width height`), or <folder>.json {"fx", "fy", "cx", "cy"};
                                            fx / fy missing, 0 or NaN: from the lens, f = focal_mm / pixel
                                            pitch (Galteland eq. 3.36)
    <scene>/<depth_folder>/<frames>.png     optional precomputed depth maps (uint16, value / depth_scale m)
    <scene>/lidar_top/*.bin, extrinsics.json, ego_poses.txt   optional, already canonical

Without real sweeps, `lidar_top` is a virtual LiDAR in the vehicle frame whose points are the depth
maps' pixels back-projected (pixel centre, depth), so the `lidar_depth` rule reproduces each depth map
exactly (within prepare.depth_range); with neither, sweeps are empty (depth maps all 0).
Without extrinsics.json a camera sits `height` m above the vehicle origin looking along +x
(`cam_back`: along −x); without ego_poses.txt the poses are the identity.
"""
from __future__ import annotations

import functools
import json
import math
import re
from pathlib import Path

import cv2
import numpy as np

from redsup import geometry, sceneio
from redsup.adapters.common import IMAGE_EXTS, AdapterError, SceneWriter, image_size, list_frames
from redsup.adapters.frames2d import Frames2D
from redsup.sceneio import frame_name

# camera axes (x right, y down, z forward) in the vehicle frame (x forward, y left, z up)
R_VEHICLE_FRONT_CAMERA = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def camera_settings(spec: dict) -> dict[str, dict]:
    """{canonical camera: settings with defaults filled} of a scene_folder spec."""
    out = {}
    for camera, cfg in (spec.get("cameras") or {"cam_front": {}}).items():
        cfg = dict(cfg or {})
        cfg.setdefault("folder", camera)
        cfg.setdefault("depth_scale", 256.0)
        cfg.setdefault("height", 0.0)
        out[camera] = cfg
    return out


def _safe_id(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_]", "_", name)


@functools.lru_cache(maxsize=None)
def _table(path: str, splits: tuple, split: str, scenes: tuple, first_folder: str) -> dict:
    root = Path(path)
    if not root.is_dir():
        raise AdapterError(f"{root}: scene-folder dataset root missing (datasets.<name>.path)")
    found = {p.name: p for p in sorted(root.iterdir()) if p.is_dir() and (p / first_folder).is_dir()}
    if not found:
        raise AdapterError(f"{root}: no scene folders with a '{first_folder}/' camera folder")
    assignment: dict[str, str] = {}
    if splits:
        for name, file in splits:
            try:
                listed = [ln.split()[0] for ln in Path(file).read_text().splitlines() if ln.strip()]
            except FileNotFoundError as exc:
                raise AdapterError(f"{file}: split file missing (datasets.<name>.splits)") from exc
            for s in listed:
                assignment[Path(s).name] = name
    else:
        assignment = {s: split for s in found}
    if scenes:
        assignment = {s: v for s, v in assignment.items() if s in set(scenes)}
        unknown = sorted(set(scenes) - set(found))
        if unknown:
            raise AdapterError(f"{root}: scenes listed in datasets.<name>.scenes are missing: {unknown[:5]}")
    missing = sorted(set(assignment) - set(found))
    if missing:
        raise AdapterError(f"{root}: scenes named in the split files are missing (or lack '{first_folder}/'): "
                           f"{missing[:5]}" + (f" and {len(missing) - 5} more" if len(missing) > 5 else ""))
    table: dict[str, dict] = {}
    for name, s in sorted(assignment.items()):
        scene = f"{s}_{_safe_id(name)}"
        if scene in table:
            raise AdapterError(f"{root}: scene folders {table[scene]['folder']} and {name} map to the same id {scene}")
        table[scene] = {"folder": name, "dir": str(found[name]), "split": s}
    return table


def scene_table(spec: dict) -> dict:
    splits = tuple(sorted((k, str(v)) for k, v in (spec.get("splits") or {}).items()))
    first = next(iter(camera_settings(spec).values()))["folder"]
    return _table(str(spec["path"]), splits, spec.get("split", "train"), tuple(spec.get("scenes") or ()), first)


def read_intrinsics(path_txt: Path, cfg: dict, size: tuple[int, int]) -> np.ndarray:
    """K of one camera from <folder>.txt or <folder>.json; fx, fy from focal_mm / pixel_pitch_um if missing."""
    path_json = path_txt.with_suffix(".json")
    values: dict[str, float] = {}
    if path_txt.exists():
        rows = [ln.split() for ln in path_txt.read_text().splitlines() if ln.strip()]
        try:
            K = np.array([[float(x) for x in r] for r in rows[:3]])
            if K.shape != (3, 3):
                raise ValueError(f"K has shape {K.shape}")
        except (ValueError, IndexError) as exc:
            raise AdapterError(f"{path_txt}: malformed intrinsics (rows 'fx 0 cx', '0 fy cy', '0 0 1'): {exc}") from exc
        values = {"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2]}
        if len(rows) > 3:
            stated = tuple(int(float(x)) for x in rows[3][:2])
            if stated != tuple(size):
                raise AdapterError(f"{path_txt}: says the image is {stated[0]}x{stated[1]}, it is {size[0]}x{size[1]}")
    elif path_json.exists():
        try:
            data = json.loads(path_json.read_text())
        except json.JSONDecodeError as exc:
            raise AdapterError(f"{path_json}: not valid JSON: {exc}") from exc
        values = {k: float(data[k]) for k in ("fx", "fy", "cx", "cy") if data.get(k) is not None}
    else:
        raise AdapterError(f"{path_txt}: intrinsics missing (or {path_json.name})")
    for k in ("cx", "cy"):
        if not math.isfinite(values.get(k, float("nan"))):
            raise AdapterError(f"{path_txt if path_txt.exists() else path_json}: principal point {k} missing")
    for k in ("fx", "fy"):
        if not (math.isfinite(values.get(k, float("nan"))) and values[k] > 0):
            if cfg.get("focal_mm") is None or cfg.get("pixel_pitch_um") is None:
                raise AdapterError(f"{path_txt if path_txt.exists() else path_json}: {k} missing; set the "
                                   f"camera's focal_mm and pixel_pitch_um (f = focal length / pixel pitch)")
            values[k] = focal_from_lens(cfg["focal_mm"], cfg["pixel_pitch_um"])
    return np.array([[values["fx"], 0.0, values["cx"]], [0.0, values["fy"], values["cy"]], [0.0, 0.0, 1.0]])


def focal_from_lens(focal_mm: float, pixel_pitch_um: float) -> float:
    """Focal length in pixels, f / m (Galteland eq. 3.36: 5.49 mm / 3 µm = 1830 px)."""
    return float(focal_mm) * 1e-3 / (float(pixel_pitch_um) * 1e-6)


def default_extrinsic(camera: str, height: float) -> np.ndarray:
    R = R_VEHICLE_FRONT_CAMERA
    if camera == "cam_back":
        R = np.diag([-1.0, -1.0, 1.0]) @ R
    T = np.eye(4)
    T[:3, :3] = R
    T[2, 3] = height
    return T


def depth_points(depth: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(N, 3) camera-frame points of the non-zero pixels of a depth map (pixel centres)."""
    v, u = np.nonzero(depth > 0)
    return geometry.backproject(K, np.stack([u, v], axis=1).astype(np.float64), depth[v, u].astype(np.float64))


def adapt(dataset: str, spec: dict, scene: str, out_dir: str | Path, seed: int = 0) -> dict:
    """Write one scene folder as a canonical scene; returns summary numbers."""
    entry = scene_table(spec).get(scene)
    if entry is None:
        raise AdapterError(f"dataset {dataset}: no scene {scene}")
    src = Path(entry["dir"])
    cams = camera_settings(spec)
    frames = {c: list_frames(src / cfg["folder"], IMAGE_EXTS) for c, cfg in cams.items()}
    n = len(next(iter(frames.values())))
    for c, paths in frames.items():
        if not paths:
            raise AdapterError(f"{src / cams[c]['folder']}: no images ({', '.join(IMAGE_EXTS)}): empty camera "
                               f"folder")
        if len(paths) != n or n == 0:
            raise AdapterError(f"{src / cams[c]['folder']}: {len(paths)} images, but "
                               f"{src / next(iter(cams.values()))['folder']} has {n} (need one per frame)")
    given = sceneio.read_extrinsics(src / "extrinsics.json") if (src / "extrinsics.json").exists() else {}
    extrinsics, Ks, sizes = {}, {}, {}
    for c, cfg in cams.items():
        sizes[c] = image_size(frames[c][0])
        Ks[c] = read_intrinsics(src / f"{cfg['folder']}.txt", cfg, sizes[c])
        extrinsics[c] = given.get(c, given.get(cfg["folder"], default_extrinsic(c, float(cfg["height"]))))
    poses = sceneio.read_poses(src / "ego_poses.txt") if (src / "ego_poses.txt").exists() \
        else np.tile(np.eye(4), (n, 1, 1))
    if len(poses) != n:
        raise AdapterError(f"{src / 'ego_poses.txt'}: {len(poses)} poses for {n} frames")
    sweeps = list_frames(src / "lidar_top", (".bin",))
    if sweeps and len(sweeps) != n:
        raise AdapterError(f"{src / 'lidar_top'}: {len(sweeps)} sweeps for {n} frames")
    if sweeps and "lidar_top" not in given:
        raise AdapterError(f"{src / 'extrinsics.json'}: real sweeps in lidar_top/ need its extrinsics ('lidar_top')")
    lidar_source = "sweeps" if sweeps else "none"
    depth_cams = {c: cfg for c, cfg in cams.items() if cfg.get("depth_folder")}
    if not sweeps and depth_cams:
        lidar_source = "depth maps"
        depth_frames = {c: list_frames(src / cfg["depth_folder"], (".png",)) for c, cfg in depth_cams.items()}
        for c, paths in depth_frames.items():
            if len(paths) != n:
                raise AdapterError(f"{src / depth_cams[c]['depth_folder']}: {len(paths)} depth maps for {n} frames")
    frames2d = Frames2D(spec, spec["path"])
    rows: list[dict] = []
    with SceneWriter(out_dir, link=not spec.get("copy_files", False)) as w:
        for c in cams:
            w.write_intrinsics(c, Ks[c], sizes[c])
            for i, path in enumerate(frames[c]):
                if i in (0, n - 1) and image_size(path) != sizes[c]:
                    raise AdapterError(f"{path}: image size {image_size(path)} differs from frame 0's {sizes[c]}")
                w.place_image(path, f"{c}/{frame_name(i, 'png')}")
                rows += frames2d.write(w, c, i, path, sizes[c], None, labelled=False)
        if sweeps:
            for i, path in enumerate(sweeps):
                w.place(path, f"lidar_top/{frame_name(i, 'bin')}")
            extrinsics["lidar_top"] = given["lidar_top"]
        else:
            extrinsics["lidar_top"] = np.eye(4)  # virtual LiDAR: points in the vehicle frame
            for i in range(n):
                parts = [np.zeros((0, 3))]
                for c, cfg in depth_cams.items():
                    depth = cv2.imread(str(depth_frames[c][i]), cv2.IMREAD_UNCHANGED)
                    if depth is None or depth.ndim != 2 or (depth.shape[1], depth.shape[0]) != sizes[c]:
                        raise AdapterError(f"{depth_frames[c][i]}: need a single-channel depth PNG of {sizes[c]}")
                    cam_points = depth_points(depth.astype(np.float64) / float(cfg["depth_scale"]), Ks[c])
                    parts.append(geometry.transform_points(extrinsics[c], cam_points))
                xyz = np.concatenate(parts)
                w.write_lidar(f"lidar_top/{frame_name(i, 'bin')}", np.hstack([xyz, np.zeros((len(xyz), 1))]))
        w.write_extrinsics(extrinsics)
        w.write_poses(poses)
        w.write_boxes(rows)
        meta = {"scene": Path(out_dir).name, "dataset": dataset, "domain": "scene_folder", "split": entry["split"],
                "fps": float(spec.get("fps", 10.0)), "n_frames": n, "cameras": list(cams), "lidars": ["lidar_top"],
                "seed": int(seed), "source": {"kind": "scene_folder", "path": str(src)}, "lidar": lidar_source,
                "ego_poses": "ego_poses.txt" if (src / "ego_poses.txt").exists() else "identity",
                **frames2d.meta()}
        w.write_meta(meta)
    return {"frames": n, "cameras": len(cams), "lidar_from_depth_maps": float(lidar_source == "depth maps"),
            **frames2d.stats}
