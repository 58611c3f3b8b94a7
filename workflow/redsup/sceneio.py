"""Reading the canonical raw-scene format (README, "The canonical raw-scene format"), validating on read.

Every reader raises `SceneError` naming the file and what is wrong with it, so a bad input fails its
own Snakemake job with a message a user can act on.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import pandas as pd

LIDAR_RECORD_BYTES = 16  # x, y, z, reflectance as float32
BOX_COLUMNS = ["frame", "track_id", "cls", "x", "y", "z", "l", "w", "h", "yaw", "vx", "vy", "vz",
               "occlusion", "truncation", "x1", "y1", "x2", "y2", "visible_px", "n_lidar"]


class SceneError(ValueError):
    """A malformed or missing input file; the message names the file."""


def read_json(path: str | Path, missing: str = "missing", error: type[SceneError] = SceneError):
    """The JSON content of `path`; `error` naming the file when it is absent ("<path>: <missing>") or not
    valid JSON."""
    path = Path(path)
    try:
        return json.loads(path.read_text())
    except FileNotFoundError as exc:
        raise error(f"{path}: {missing}") from exc
    except json.JSONDecodeError as exc:
        raise error(f"{path}: not valid JSON: {exc}") from exc


def frame_name(index: int, ext: str) -> str:
    return f"{index:06d}.{ext}"


def read_meta(scene_dir: str | Path) -> dict:
    path = Path(scene_dir) / "scene.json"
    meta = read_json(path, "missing (every scene folder needs scene.json)")
    for key in ("scene", "n_frames", "fps", "cameras", "lidars"):
        if key not in meta:
            raise SceneError(f"{path}: key '{key}' missing")
    return meta


def read_intrinsics(path: str | Path) -> tuple[np.ndarray, tuple[int, int]]:
    """(K 3x3, (width, height)) from an intrinsics file: 3 rows of K, then `width height`."""
    path = Path(path)
    try:
        rows = [line.split() for line in path.read_text().splitlines() if line.strip()]
    except FileNotFoundError as exc:
        raise SceneError(f"{path}: intrinsics file missing") from exc
    try:
        K = np.array([[float(x) for x in row] for row in rows[:3]])
        size = tuple(int(x) for x in rows[3])
    except (ValueError, IndexError) as exc:
        raise SceneError(f"{path}: malformed intrinsics (expected 3 rows 'fx 0 cx', '0 fy cy', "
                         f"'0 0 1' and a row 'width height'): {exc}") from exc
    if K.shape != (3, 3) or len(size) != 2:
        raise SceneError(f"{path}: malformed intrinsics: K has shape {K.shape}, size row {size}")
    if not np.allclose(K[2], [0, 0, 1]) or K[0, 0] <= 0 or K[1, 1] <= 0 or min(size) <= 0:
        raise SceneError(f"{path}: implausible intrinsics (need fx, fy > 0, last row 0 0 1, "
                         f"positive size): K={K.tolist()}, size={size}")
    return K, (size[0], size[1])


def write_intrinsics(path: str | Path, K: np.ndarray, size: tuple[int, int]) -> None:
    lines = [" ".join(f"{v:.6f}" for v in row) for row in np.asarray(K)]
    Path(path).write_text("\n".join(lines + [f"{size[0]} {size[1]}"]) + "\n")


def read_lidar(path: str | Path) -> np.ndarray:
    """(N, 4) float32 points (x, y, z, reflectance). Rows with non-finite values are dropped."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError as exc:
        raise SceneError(f"{path}: LiDAR sweep missing") from exc
    if len(raw) % LIDAR_RECORD_BYTES:
        raise SceneError(f"{path}: size {len(raw)} bytes is not a multiple of the {LIDAR_RECORD_BYTES}-byte "
                         f"record (x, y, z, reflectance float32): truncated or wrong format")
    points = np.frombuffer(raw, dtype="<f4").reshape(-1, 4)
    return points[np.isfinite(points).all(axis=1)]


def read_image(path: str | Path) -> np.ndarray:
    """RGB uint8 image."""
    import cv2   # here: jobs that read only JSON / npz (tables, calibration) skip its 0.1-0.15 s import

    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        what = "missing" if not Path(path).exists() else "unreadable (not a valid image)"
        raise SceneError(f"{path}: image {what}")
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def read_label_png(path: str | Path) -> np.ndarray:
    """A single-channel PNG as stored (uint8 or uint16)."""
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None or img.ndim != 2:
        raise SceneError(f"{path}: missing or not a single-channel PNG")
    return img


def read_depth_png(path: str | Path) -> np.ndarray:
    """KITTI-convention uint16 depth PNG to metres (0 = no value)."""
    return read_label_png(path).astype(np.float32) / 256.0


RIGID_TOLERANCE = 1e-4  # max |R^T R - I|: KITTI's printed rotations are orthonormal to ~1e-6


def rigid_problem(T: np.ndarray) -> str | None:
    """Why a 4x4 (or 3x4) matrix is no rigid transform (non-finite, rotation not orthonormal with det +1,
    last row not 0 0 0 1), or None."""
    T = np.asarray(T, dtype=np.float64)
    if not np.isfinite(T).all():
        return "non-finite values"
    R = T[:3, :3]
    err = float(np.abs(R.T @ R - np.eye(3)).max())
    det = float(np.linalg.det(R))
    if err > RIGID_TOLERANCE or det <= 0:
        return (f"not a rotation (|R^T R - I| = {err:.2g}, tolerance {RIGID_TOLERANCE:g}; det R = {det:.6g}, "
                f"need +1)")
    if T.shape[0] == 4 and not np.allclose(T[3], [0, 0, 0, 1]):
        return f"last row {T[3].tolist()} is not [0, 0, 0, 1]"
    return None


def check_poses(poses: np.ndarray, where: str | Path) -> np.ndarray:
    """`poses` (T, 4, 4) unchanged; SceneError naming `where` and the first bad line (1-based)."""
    for i, T in enumerate(np.asarray(poses)):
        problem = rigid_problem(T)
        if problem:
            raise SceneError(f"{where}: line {i + 1}: pose {problem}")
    return poses


def read_poses(path: str | Path) -> np.ndarray:
    """(T, 4, 4) T_world_vehicle from 12 numbers per line; every pose finite and rigid."""
    path = Path(path)
    try:
        values = np.loadtxt(path, ndmin=2)
    except FileNotFoundError as exc:
        raise SceneError(f"{path}: ego poses missing") from exc
    except ValueError as exc:
        raise SceneError(f"{path}: malformed ego poses: {exc}") from exc
    if values.shape[1] != 12:
        raise SceneError(f"{path}: expected 12 numbers per line (3x4 pose), got {values.shape[1]}")
    poses = np.tile(np.eye(4), (len(values), 1, 1))
    poses[:, :3, :] = values.reshape(-1, 3, 4)
    return check_poses(poses, path)


def read_extrinsics(path: str | Path) -> dict[str, np.ndarray]:
    path = Path(path)
    data = read_json(path, "sensor extrinsics missing")
    out = {}
    for name, matrix in data.items():
        T = np.asarray(matrix, dtype=np.float64)
        if T.shape != (4, 4):
            raise SceneError(f"{path}: extrinsics of '{name}' have shape {T.shape}, expected 4x4")
        problem = rigid_problem(T)
        if problem:
            raise SceneError(f"{path}: extrinsics of '{name}': {problem}")
        out[name] = T
    return out


def read_boxes(path: str | Path) -> pd.DataFrame:
    import pandas as pd   # here, not at the top: most jobs read scenes and never boxes (0.5 s of start-up each)

    path = Path(path)
    try:
        boxes = pd.read_csv(path)
    except FileNotFoundError as exc:
        raise SceneError(f"{path}: ground-truth boxes missing") from exc
    missing = [c for c in BOX_COLUMNS if c not in boxes.columns]
    if missing:
        raise SceneError(f"{path}: columns missing: {missing}")
    return boxes


def sensor_frames(scene_dir: str | Path, sensor: str, ext: str, n_frames: int) -> list[Path]:
    """Paths of frames 0..n_frames-1 of one sensor; SceneError listing the missing ones."""
    folder = Path(scene_dir) / sensor
    paths = [folder / frame_name(i, ext) for i in range(n_frames)]
    missing = [p.name for p in paths if not p.exists()]
    if missing:
        shown = ", ".join(missing[:5]) + (f" and {len(missing) - 5} more" if len(missing) > 5 else "")
        raise SceneError(f"{folder}: {len(missing)} of {n_frames} frames missing ({shown})")
    return paths
