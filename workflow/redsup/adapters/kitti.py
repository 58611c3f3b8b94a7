"""KITTI raw drives and KITTI object frames converted into the canonical raw-scene format.

Frames (README.md, "The canonical raw-scene format"): `lidar_top` is the Velodyne frame itself (x forward, y left, z up; the
sweeps are KITTI's own records, linked or copied unchanged). The vehicle frame has the axes of the OXTS
IMU and its origin `imu_height` (KITTI setup: 0.93 m) below the IMU, on the road. Cameras are the
*rectified* cameras 2 (`cam_front`) and 3 (`cam_front_right`): K = P_rect[:, :3] and the camera frame is
the rectified one, T_cam_velo = [I | K⁻¹ P_rect[:, 3]] · R_rect_00 · T_velo_to_cam, so a LiDAR point's
camera z is exactly the third row of P_rect · R_rect · T_velo_to_cam · X, the depth the Monodepth2 /
Eigen ground truth uses.

Pixel convention of the KITTI raw depth ground truth: Monodepth2's `generate_depth_map` (after the KITTI
Matlab devkit, which is 1-based) puts a point at pixel round(u) − 1, round(v) − 1. The `lidar_depth` rule
puts it at round(u), round(v). With `depth_convention: monodepth2` (default for kitti_raw) the written
intrinsics have cx − 1, cy − 1, so the prepared sparse depth maps equal Monodepth2's ground truth
pixel for pixel (within prepare.depth_range); `exact` writes P_rect's own principal point.
"""
from __future__ import annotations

import datetime
import functools
import math
from pathlib import Path

import numpy as np

from redsup import eval_frame, geometry
from redsup.adapters.common import (AdapterError, SceneWriter, expect_size, image_size, list_frames, read_kv_file,
                                    rigid, translation)
from redsup.adapters.frames2d import Frames2D
from redsup.boxes3d import points_in_box
from redsup.sceneio import BOX_COLUMNS, LIDAR_RECORD_BYTES, frame_name, read_lidar

FPS = 10.0
RAW_CAMERAS = {"cam_front": "02", "cam_front_right": "03"}
OBJECT_CAMERAS = {"cam_front": "2", "cam_front_right": "3"}
LABEL_FIELDS = [
    "cls", "truncation", "occlusion", "alpha", "x1", "y1", "x2", "y2", "h", "w", "l", "cx", "cy", "cz", "ry"]
EARTH_RADIUS = 6378137.0


# --------------------------------------------------------------------------------------- calibration
def camera_from_projection(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(K, T_cam_rect0) of a rectified projection P = K [I | t]: K = P[:, :3], t = K⁻¹ P[:, 3]."""
    P = np.asarray(P, dtype=np.float64).reshape(3, 4)
    K = P[:, :3].copy()
    return K, translation(np.linalg.solve(K, P[:, 3]))


def camera_extrinsic(T_vehicle_lidar: np.ndarray, T_cam_lidar: np.ndarray) -> np.ndarray:
    """T_vehicle_cam such that invert_pose(T_vehicle_cam) @ T_vehicle_lidar == T_cam_lidar to float precision.

    KITTI's rotations are orthonormal only to about 1e-6 (7 printed digits); inverting them by transposition
    (`geometry.invert_pose`, as the lidar_depth rule does) would move far points by ~1e-5 px and flip rare
    round-half pixels. Solving for the stored camera extrinsic instead keeps P_rect·R_rect·T_velo_to_cam as
    given: R_c^T = R_m R_l^-1, t_c = t_l - (R_c^T)^-1 t_m.
    """
    R_cT = T_cam_lidar[:3, :3] @ np.linalg.inv(T_vehicle_lidar[:3, :3])
    out = np.eye(4)
    out[:3, :3] = R_cT.T
    out[:3, 3] = T_vehicle_lidar[:3, 3] - np.linalg.solve(R_cT, T_cam_lidar[:3, 3])
    return out


def rig(projections: dict[str, np.ndarray], R_rect: np.ndarray, T_cam0_velo: np.ndarray,
        T_velo_imu: np.ndarray, imu_height: float) -> tuple[dict, dict, np.ndarray]:
    """(K per camera, T_vehicle_sensor per sensor incl. lidar_top, T_vehicle_rect0)."""
    T_rect0_velo = rigid(np.asarray(R_rect).reshape(3, 3), np.zeros(3)) @ T_cam0_velo
    T_vehicle_velo = translation([0.0, 0.0, imu_height]) @ np.linalg.inv(T_velo_imu)
    Ks, extrinsics = {}, {"lidar_top": T_vehicle_velo}
    for camera, P in projections.items():
        K, T_cam_rect0 = camera_from_projection(P)
        Ks[camera] = K
        extrinsics[camera] = camera_extrinsic(T_vehicle_velo, T_cam_rect0 @ T_rect0_velo)
    return Ks, extrinsics, T_vehicle_velo @ np.linalg.inv(T_rect0_velo)


def shift_principal_point(K: np.ndarray, convention: str) -> np.ndarray:
    K = np.array(K, dtype=np.float64, copy=True)
    if convention == "monodepth2":
        K[0, 2] -= 1.0
        K[1, 2] -= 1.0
    return K


# ------------------------------------------------------------------------------------------ oxts poses
def oxts_poses(paths: list[Path]) -> np.ndarray:
    """(T, 4, 4) T_world_imu from OXTS packets: Mercator position (scale from the first latitude) and
    R = Rz(yaw) Ry(pitch) Rx(roll); world = the Mercator frame moved to the first position (z up)."""
    rows = []
    for p in paths:
        try:
            values = np.array(p.read_text().split(), dtype=np.float64)
        except (FileNotFoundError, ValueError) as exc:
            raise AdapterError(f"{p}: missing or malformed OXTS packet ({exc})") from exc
        if values.size < 6:
            raise AdapterError(f"{p}: an OXTS packet has 30 numbers, found {values.size}")
        if not np.isfinite(values[:6]).all():
            raise AdapterError(f"{p}: non-finite position or orientation in the OXTS packet "
                               f"(lat lon alt roll pitch yaw = {values[:6].tolist()})")
        rows.append(values[:6])
    rows = np.array(rows)
    scale = math.cos(math.radians(rows[0, 0]))
    poses = []
    for lat, lon, alt, roll, pitch, yaw in rows:
        t = [scale * EARTH_RADIUS * math.radians(lon),
             scale * EARTH_RADIUS * math.log(math.tan(math.radians(90.0 + lat) / 2.0)), alt]
        cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                                  math.cos(yaw), math.sin(yaw))
        Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
        Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
        Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
        poses.append(rigid(Rz @ Ry @ Rx, t))
    poses = np.array(poses)
    poses[:, :3, 3] -= poses[0, :3, 3]
    return poses


# ---------------------------------------------------------------------------------------- timestamps
def check_timestamps(path: Path, first: int, count: int) -> None:
    """A sensor's `timestamps.txt` (one `YYYY-MM-DD HH:MM:SS.fffffffff` per frame), if present, must have a
    line for each of the scene's frames first..first+count-1, strictly increasing: a repeated or backward
    time means duplicated or reordered frames, which the 10 fps frame clock would silently mistime."""
    if not path.is_file():
        return
    lines = path.read_text().splitlines()
    if len(lines) < first + count:
        raise AdapterError(f"{path}: {len(lines)} timestamps, the scene needs lines {first + 1}..{first + count}")
    previous = None
    for n in range(first, first + count):
        text = lines[n].strip()
        try:
            day, clock = text.split()
            whole, _, frac = clock.partition(".")
            t = datetime.datetime.strptime(f"{day} {whole}", "%Y-%m-%d %H:%M:%S").replace(
                tzinfo=datetime.timezone.utc).timestamp() + float(f"0.{frac or 0}")
        except ValueError as exc:
            raise AdapterError(f"{path}: line {n + 1} is not a timestamp (YYYY-MM-DD HH:MM:SS.fff): {text!r}") from exc
        if previous is not None and t == previous:
            raise AdapterError(f"{path}: line {n + 1} repeats the timestamp of line {n} ({text}): duplicated frame")
        if previous is not None and t < previous:
            raise AdapterError(f"{path}: line {n + 1} ({text}) is earlier than line {n}: frames out of order")
        previous = t


# -------------------------------------------------------------------------------------------- labels
def read_labels(path: Path) -> list[dict]:
    """KITTI object label_2 rows (15 fields, a 16th score is ignored)."""
    try:
        lines = [ln.split() for ln in path.read_text().splitlines() if ln.strip()]
    except FileNotFoundError as exc:
        raise AdapterError(f"{path}: label file missing") from exc
    out = []
    for i, fields in enumerate(lines):
        if len(fields) not in (15, 16):
            raise AdapterError(f"{path}: line {i + 1} has {len(fields)} fields, a KITTI label has 15 "
                               f"(type truncated occluded alpha bbox(4) dimensions(3) location(3) rotation_y)")
        try:
            row = {"cls": fields[0], **{k: float(v) for k, v in zip(LABEL_FIELDS[1:], fields[1:15])}}
        except ValueError as exc:
            raise AdapterError(f"{path}: line {i + 1}: {exc}") from exc
        out.append(row)
    return out


def label_to_row(label: dict, frame: int, track_id: int, T_vehicle_rect0: np.ndarray) -> dict:
    """A boxes.csv row: geometric centre and heading moved from rectified camera 0 to the vehicle frame.

    The vehicle-frame yaw is the heading whose projection back onto the camera's horizontal plane is the
    label's (`redsup.eval_frame`): evaluation moves the box back upright into the camera frame and
    gets the label's own box, as the KITTI devkit uses it."""
    row = {c: float("nan") for c in BOX_COLUMNS}
    row.update(frame=frame, track_id=track_id, cls=label["cls"], occlusion=int(label["occlusion"]),
               truncation=label["truncation"], x1=label["x1"], y1=label["y1"], x2=label["x2"], y2=label["y2"])
    if label["cls"].lower() == "dontcare":
        return row
    centre = np.array([label["cx"], label["cy"] - label["h"] / 2.0, label["cz"]])
    heading = np.array([math.cos(label["ry"]), 0.0, -math.sin(label["ry"])])
    c = geometry.transform_points(T_vehicle_rect0, centre[None])[0]
    d = eval_frame.heading_keeping_projection(T_vehicle_rect0[:3, :3], heading, np.array([0.0, -1.0, 0.0]),
                                              np.array([0.0, 0.0, 1.0]))
    row.update(x=c[0], y=c[1], z=c[2], l=label["l"], w=label["w"], h=label["h"], yaw=math.atan2(d[1], d[0]))
    return row


# ------------------------------------------------------------------------------------------- listings
def _split_file_lines(path: str | Path) -> list[list[str]]:
    path = Path(path)
    try:
        return [ln.split() for ln in path.read_text().splitlines() if ln.strip()]
    except FileNotFoundError as exc:
        raise AdapterError(f"{path}: split file missing (datasets.<name>.splits)") from exc


def raw_drives(root: Path) -> dict[str, Path]:
    """{drive folder name: path} of every `<date>/<date>_drive_<n>_sync` under the root."""
    if not root.is_dir():
        raise AdapterError(f"{root}: KITTI raw root missing (datasets.<name>.path)")
    return {d.name: d for d in sorted(root.glob("*/*_drive_*_sync")) if d.is_dir()}


@functools.lru_cache(maxsize=None)
def _raw_table(path: str, splits: tuple, split: str, drives: tuple, window: int | None) -> dict:
    root = Path(path)
    found = raw_drives(root)
    if not found:
        raise AdapterError(f"{root}: no drive folders (<date>/<date>_drive_NNNN_sync) found")
    wanted: dict[str, str] = {}
    listed: dict[str, set[int]] = {}
    if splits:
        for name, file in splits:
            for fields in _split_file_lines(file):
                drive = Path(fields[0]).name
                if wanted.setdefault(drive, name) != name:
                    raise AdapterError(f"{file}: drive {drive} is also in split '{wanted[drive]}'")
                if len(fields) > 1 and fields[1].isdigit():
                    listed.setdefault(drive, set()).add(int(fields[1]))
        missing = sorted(set(wanted) - set(found))
        if missing:
            raise AdapterError(f"{root}: drives named in the split files are missing: {missing[:5]}"
                               + (f" and {len(missing) - 5} more" if len(missing) > 5 else ""))
    else:
        wanted = {d: split for d in found}
    if drives:
        unknown = sorted(set(drives) - set(found))
        if unknown:
            raise AdapterError(f"{root}: drives listed in datasets.<name>.drives are missing: {unknown[:5]}")
        wanted = {d: s for d, s in wanted.items() if d in set(drives)}
    table = {}
    for drive, name in sorted(wanted.items()):
        n = len(list_frames(found[drive] / "image_02" / "data", (".png",)))
        if n == 0:
            raise AdapterError(f"{found[drive] / 'image_02' / 'data'}: no images (a KITTI raw drive needs "
                               f"image_02/data/NNNNNNNNNN.png)")
        starts = range(0, n, window) if window else [0]
        for start in starts:
            count = min(window, n - start) if window else n
            if window and count < 2 and start > 0:
                continue
            scene = f"{name}_{drive}" + (f"_{start:06d}" if window else "")
            frames = sorted(i - start for i in listed.get(drive, ()) if start <= i < start + count)
            table[scene] = {"drive": drive, "dir": str(found[drive]), "split": name, "start": start,
                            "count": count, "split_frames": frames}
    return table


def raw_scene_table(spec: dict) -> dict:
    splits = tuple(sorted((k, str(v)) for k, v in (spec.get("splits") or {}).items()))
    return _raw_table(str(spec["path"]), splits, spec.get("split", "train"), tuple(spec.get("drives") or ()),
                      spec.get("window"))


def object_root(spec: dict) -> Path:
    path = Path(spec["path"])
    subset = spec.get("subset", "training")
    root = path / subset if (path / subset).is_dir() else path
    if not (root / "image_2").is_dir():
        raise AdapterError(f"{path}: no {subset}/image_2 folder (KITTI object layout: {subset}/{{image_2, "
                           f"velodyne, calib, label_2}})")
    return root


@functools.lru_cache(maxsize=None)
def _object_table(path: str, subset: str, splits: tuple, split: str) -> dict:
    root = object_root({"path": path, "subset": subset})
    ids = [p.stem for p in list_frames(root / "image_2", (".png",))]
    if not ids:
        raise AdapterError(f"{root / 'image_2'}: no images")
    if splits:
        have = set(ids)
        table = {}
        for name, file in splits:
            listed = [fields[0] for fields in _split_file_lines(file)]
            missing = [i for i in listed if i not in have]
            if missing:
                raise AdapterError(f"{file}: frames missing from {root / 'image_2'}: {missing[:5]}"
                                   + (f" and {len(missing) - 5} more" if len(missing) > 5 else ""))
            table.update({f"{name}_{i}": {"frame_id": i, "split": name} for i in listed})
        return table
    return {f"{split}_{i}": {"frame_id": i, "split": split} for i in ids}


def object_scene_table(spec: dict) -> dict:
    splits = tuple(sorted((k, str(v)) for k, v in (spec.get("splits") or {}).items()))
    return _object_table(str(spec["path"]), spec.get("subset", "training"), splits, spec.get("split", "train"))


# ------------------------------------------------------------------------------------------- adapters
def _check_frames(folder: Path, stems: list[str], ext: str, what: str) -> list[Path]:
    paths = [folder / f"{s}{ext}" for s in stems]
    missing = [p.name for p in paths if not p.exists()]
    if missing:
        raise AdapterError(f"{folder}: {len(missing)} of {len(paths)} {what} missing ({', '.join(missing[:5])}"
                           + (f" and {len(missing) - 5} more)" if len(missing) > 5 else ")"))
    return paths


def _check_sweeps(paths: list[Path]) -> None:
    """Velodyne records are linked, not read: check each source file's size here (x, y, z, reflectance
    float32 records), so a truncated sweep fails at adaptation naming the source, not the link."""
    for p in paths:
        size = p.stat().st_size
        if size == 0 or size % LIDAR_RECORD_BYTES:
            raise AdapterError(f"{p}: velodyne sweep of {size} bytes is not a non-empty multiple of the "
                               f"{LIDAR_RECORD_BYTES}-byte record (x, y, z, reflectance float32): truncated or "
                               f"wrong format")


def _base_meta(scene: str, dataset: str, kind: str, split: str, n: int, cameras: list[str], seed: int) -> dict:
    return {"scene": scene, "dataset": dataset, "domain": kind, "split": split, "fps": FPS, "n_frames": n,
            "cameras": cameras, "lidars": ["lidar_top"], "seed": int(seed)}


def adapt_raw(dataset: str, spec: dict, scene: str, out_dir: str | Path, seed: int = 0) -> dict:
    """Write one KITTI raw drive (or window of it) as a canonical scene; returns summary numbers."""
    entry = raw_scene_table(spec).get(scene)
    if entry is None:
        raise AdapterError(f"dataset {dataset}: no scene {scene} (have {sorted(raw_scene_table(spec))[:5]} ...)")
    drive_dir = Path(entry["dir"])
    date_dir = drive_dir.parent
    cameras = list(spec.get("cameras") or ["cam_front"])
    cam2cam_path = date_dir / "calib_cam_to_cam.txt"
    cam2cam = read_kv_file(cam2cam_path, ("R_rect_00", *(f"P_rect_{RAW_CAMERAS[c]}" for c in cameras),
                                          *(f"S_rect_{RAW_CAMERAS[c]}" for c in cameras)))
    velo_path = date_dir / "calib_velo_to_cam.txt"
    velo = read_kv_file(velo_path, ("R", "T"))
    imu_path = date_dir / "calib_imu_to_velo.txt"
    imu = read_kv_file(imu_path, ("R", "T"))
    T_cam0_velo = rigid(expect_size(velo_path, "R", velo["R"], 9), expect_size(velo_path, "T", velo["T"], 3))
    T_velo_imu = rigid(expect_size(imu_path, "R", imu["R"], 9), expect_size(imu_path, "T", imu["T"], 3))
    projections = {c: expect_size(cam2cam_path, f"P_rect_{RAW_CAMERAS[c]}", cam2cam[f"P_rect_{RAW_CAMERAS[c]}"], 12)
                   for c in cameras}
    Ks, extrinsics, T_vehicle_rect0 = rig(projections, expect_size(cam2cam_path, "R_rect_00", cam2cam["R_rect_00"], 9),
                                          T_cam0_velo, T_velo_imu, float(spec.get("imu_height", 0.93)))
    all_frames = list_frames(drive_dir / "image_02" / "data", (".png",))
    stems = [p.stem for p in all_frames[entry["start"]:entry["start"] + entry["count"]]]
    n = len(stems)
    if n < entry["count"]:
        raise AdapterError(f"{drive_dir / 'image_02' / 'data'}: scene {scene} needs frames {entry['start']}.."
                           f"{entry['start'] + entry['count'] - 1}, the folder now has {len(all_frames)} images "
                           f"(files removed after the scenes were listed?)")
    images = {c: _check_frames(drive_dir / f"image_{RAW_CAMERAS[c]}" / "data", stems, ".png", "images")
              for c in cameras}
    sweeps = _check_frames(drive_dir / "velodyne_points" / "data", stems, ".bin", "velodyne sweeps")
    _check_sweeps(sweeps)
    for folder in [*(f"image_{RAW_CAMERAS[c]}" for c in cameras), "velodyne_points", "oxts"]:
        check_timestamps(drive_dir / folder / "timestamps.txt", entry["start"], n)
    oxts_dir = drive_dir / "oxts" / "data"
    if oxts_dir.is_dir():
        T_world_imu = oxts_poses(_check_frames(oxts_dir, stems, ".txt", "OXTS packets"))
        T_imu_vehicle = translation([0.0, 0.0, -float(spec.get("imu_height", 0.93))])
        poses, pose_source = T_world_imu @ T_imu_vehicle, "oxts"
    else:
        poses = np.tile(np.eye(4), (n, 1, 1))
        pose_source = "identity (no oxts: camera and LiDAR of a frame are simultaneous)"
    convention = spec.get("depth_convention", "monodepth2")
    frames2d = Frames2D(spec, spec["path"])
    rows: list[dict] = []
    with SceneWriter(out_dir, link=not spec.get("copy_files", False)) as w:
        for camera in cameras:
            size = tuple(int(v) for v in cam2cam[f"S_rect_{RAW_CAMERAS[camera]}"])
            for probe in (images[camera][0], images[camera][-1]):
                if image_size(probe) != size:
                    raise AdapterError(f"{probe}: image is {image_size(probe)}, {cam2cam_path} S_rect_"
                                       f"{RAW_CAMERAS[camera]} says {size}")
            w.write_intrinsics(camera, shift_principal_point(Ks[camera], convention), size)
            for i, src in enumerate(images[camera]):
                w.place_image(src, f"{camera}/{frame_name(i, 'png')}")
                rows += frames2d.write(w, camera, i, src, size, None, labelled=False)
        for i, src in enumerate(sweeps):
            w.place(src, f"lidar_top/{frame_name(i, 'bin')}")
        w.write_extrinsics(extrinsics)
        w.write_poses(poses)
        w.write_boxes(rows)
        meta = _base_meta(Path(out_dir).name, dataset, "kitti_raw", entry["split"], n, cameras, seed)
        meta.update(source={"kind": "kitti_raw", "drive": entry["drive"], "path": str(drive_dir),
                            "frames": stems}, ego_poses=pose_source, depth_convention=convention,
                    eval_frame=eval_frame.meta_entry(T_vehicle_rect0),
                    split_frames=entry["split_frames"], **frames2d.meta())
        w.write_meta(meta)
    return {"frames": n, "cameras": len(cameras), "poses_from_oxts": float(pose_source == "oxts"),
            "split_frames": len(entry["split_frames"]), **frames2d.stats}


def adapt_object(dataset: str, spec: dict, scene: str, out_dir: str | Path, seed: int = 0) -> dict:
    """Write one KITTI object frame as a one-frame canonical scene with its labels as gt/boxes.csv."""
    entry = object_scene_table(spec).get(scene)
    if entry is None:
        raise AdapterError(f"dataset {dataset}: no scene {scene}")
    root = object_root(spec)
    fid = entry["frame_id"]
    cameras = list(spec.get("cameras") or ["cam_front"])
    calib_path = root / "calib" / f"{fid}.txt"
    calib = read_kv_file(calib_path, ("R0_rect", "Tr_velo_to_cam", "Tr_imu_to_velo",
                                      *(f"P{OBJECT_CAMERAS[c]}" for c in cameras)))
    T_cam0_velo = np.vstack([expect_size(calib_path, "Tr_velo_to_cam", calib["Tr_velo_to_cam"], 12).reshape(3, 4),
                             [0, 0, 0, 1]])
    T_velo_imu = np.vstack([expect_size(calib_path, "Tr_imu_to_velo", calib["Tr_imu_to_velo"], 12).reshape(3, 4),
                            [0, 0, 0, 1]])
    projections = {c: expect_size(calib_path, f"P{OBJECT_CAMERAS[c]}", calib[f"P{OBJECT_CAMERAS[c]}"], 12)
                   for c in cameras}
    Ks, extrinsics, T_vehicle_rect0 = rig(projections, expect_size(calib_path, "R0_rect", calib["R0_rect"], 9),
                                          T_cam0_velo, T_velo_imu, float(spec.get("imu_height", 0.93)))
    sweep = root / "velodyne" / f"{fid}.bin"
    if not sweep.is_file():
        raise AdapterError(f"{sweep}: velodyne sweep missing")
    _check_sweeps([sweep])
    points = read_lidar(sweep)
    T_eval_vehicle = eval_frame.eval_transform(T_vehicle_rect0)
    points_eval = geometry.transform_points(T_eval_vehicle @ extrinsics["lidar_top"], points[:, :3].astype(np.float64))
    label_path = root / "label_2" / f"{fid}.txt"
    labels = read_labels(label_path) if spec.get("subset", "training") == "training" else []
    rows = [label_to_row(lab, 0, k + 1, T_vehicle_rect0) for k, lab in enumerate(labels)]
    for lab, row in zip(labels, rows):
        if np.isfinite(row["x"]):      # counted in the devkit's frame: the label's box upright in rect0
            box = eval_frame.label_box(*(lab[k] for k in ("cx", "cy", "cz", "h", "w", "l", "ry")))
            row["n_lidar"] = int(points_in_box(points_eval, box).sum())
    frames2d = Frames2D(spec, spec["path"])
    with SceneWriter(out_dir, link=not spec.get("copy_files", False)) as w:
        for camera in cameras:
            image = root / f"image_{OBJECT_CAMERAS[camera]}" / f"{fid}.png"
            size = image_size(image)
            w.write_intrinsics(camera, Ks[camera], size)
            w.place_image(image, f"{camera}/{frame_name(0, 'png')}")
            rows += frames2d.write(w, camera, 0, image, size, rows if camera == "cam_front" else None,
                                   labelled=bool(labels))
        w.place(sweep, f"lidar_top/{frame_name(0, 'bin')}")
        w.write_extrinsics(extrinsics)
        w.write_poses(np.eye(4)[None])
        w.write_boxes(rows)
        meta = _base_meta(Path(out_dir).name, dataset, "kitti_object", entry["split"], 1, cameras, seed)
        meta.update(source={"kind": "kitti_object", "frame": fid, "path": str(root)},
                    ego_poses="identity (single frame)", eval_frame=eval_frame.meta_entry(T_vehicle_rect0),
                    **frames2d.meta())
        w.write_meta(meta)
    n_objects = sum(1 for r in rows if str(r["cls"]).lower() != "dontcare")
    return {"frames": 1, "objects": n_objects, "cars": sum(1 for r in rows if str(r["cls"]).lower() == "car"),
            "lidar_points": int(len(points)), **frames2d.stats}
