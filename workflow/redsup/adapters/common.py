"""Shared pieces of the dataset adapters: errors, calibration text files, transforms, and a writer that
builds one canonical scene folder (README.md, "The canonical raw-scene format") in a temporary sibling and renames it at the end.
"""
from __future__ import annotations

import json
import os
import re
import shutil
import struct
from pathlib import Path

import cv2
import numpy as np
import pandas as pd

from redsup import sceneio
from redsup.sceneio import BOX_COLUMNS, SceneError

IMAGE_EXTS = (".png", ".jpg", ".jpeg")


class AdapterError(SceneError):
    """A real dataset is missing files or has malformed ones; the message names what and where."""


def rigid(R, t) -> np.ndarray:
    """4x4 transform from a 3x3 rotation (or 9 numbers) and a translation (3 numbers)."""
    T = np.eye(4)
    T[:3, :3] = np.asarray(R, dtype=np.float64).reshape(3, 3)
    T[:3, 3] = np.asarray(t, dtype=np.float64).reshape(3)
    return T


def translation(t) -> np.ndarray:
    return rigid(np.eye(3), t)


def read_kv_file(path: str | Path, required: tuple[str, ...] = ()) -> dict[str, np.ndarray]:
    """A KITTI calibration text file (`key: v1 v2 ...` per line) as {key: float array}.

    Lines whose values are not numbers (calib_time) are kept out. A missing file or required key raises
    AdapterError naming the file.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError as exc:
        raise AdapterError(f"{path}: calibration file missing") from exc
    out: dict[str, np.ndarray] = {}
    for line in text.splitlines():
        if ":" not in line:
            continue
        key, _, values = line.partition(":")
        try:
            out[key.strip()] = np.array([float(v) for v in values.split()], dtype=np.float64)
        except ValueError:
            continue
    missing = [k for k in required if k not in out]
    if missing:
        raise AdapterError(f"{path}: calibration keys missing: {missing} (have {sorted(out)})")
    return out


def expect_size(path: Path, key: str, values: np.ndarray, n: int) -> np.ndarray:
    if values.size != n:
        raise AdapterError(f"{path}: '{key}' has {values.size} numbers, expected {n}")
    return values


def natural_key(path: Path):
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", path.name)]


def list_frames(folder: str | Path, exts: tuple[str, ...]) -> list[Path]:
    """Files of one sensor folder with one of `exts`, in natural (numeric) order; [] if no folder."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    return sorted((p for p in folder.iterdir() if p.suffix.lower() in exts), key=natural_key)


def image_size(path: str | Path) -> tuple[int, int]:
    """(width, height) of an image: PNG from its header, others by decoding."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            head = fh.read(24)
    except FileNotFoundError as exc:
        raise AdapterError(f"{path}: image missing") from exc
    if head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR":
        return struct.unpack(">II", head[16:24])
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise AdapterError(f"{path}: unreadable image")
    return int(image.shape[1]), int(image.shape[0])


PNG_END = b"\x00\x00\x00\x00IEND\xaeB`\x82"  # the IEND chunk every complete PNG ends with


def check_png_complete(path: str | Path) -> None:
    """AdapterError unless the PNG ends with its IEND chunk (a cut download or copy loses it). Linked images
    are not decoded at adaptation, so this cheap check names the source instead of a later job the link."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
            fh.seek(0, os.SEEK_END)
            size = fh.tell()
            fh.seek(max(0, size - len(PNG_END)))
            tail = fh.read()
    except FileNotFoundError as exc:
        raise AdapterError(f"{path}: image missing") from exc
    if head != b"\x89PNG\r\n\x1a\n":
        raise AdapterError(f"{path}: not a PNG (no PNG signature)")
    if tail != PNG_END:
        raise AdapterError(f"{path}: truncated PNG ({size} bytes, no IEND chunk at the end)")


def mirrored(root: str | Path, relative: Path, suffix: str) -> Path:
    """The file beside-layout convention for precomputed per-image inputs: `root` / the image's path
    relative to the dataset root, with its extension replaced by `suffix`."""
    return Path(root) / relative.with_suffix(suffix)


class SceneWriter:
    """Builds a canonical scene in `<out>.tmp<pid>` and renames it to `out` on success (context manager)."""

    def __init__(self, out_dir: str | Path, link: bool = True):
        self.out = Path(out_dir)
        self.tmp = self.out.parent / f".{self.out.name}.tmp{os.getpid()}"
        self.link = link

    def __enter__(self) -> "SceneWriter":
        if self.tmp.exists():
            shutil.rmtree(self.tmp)
        self.tmp.mkdir(parents=True)
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is None:
            if self.out.exists():
                shutil.rmtree(self.out)
            self.tmp.rename(self.out)
        else:
            shutil.rmtree(self.tmp, ignore_errors=True)
        return False

    def path(self, relative: str) -> Path:
        p = self.tmp / relative
        p.parent.mkdir(parents=True, exist_ok=True)
        return p

    def write_json(self, relative: str, data) -> None:
        self.path(relative).write_text(json.dumps(data, indent=1))

    def write_meta(self, meta: dict) -> None:
        self.write_json("scene.json", meta)

    def write_extrinsics(self, extrinsics: dict[str, np.ndarray]) -> None:
        self.write_json("extrinsics.json", {k: np.asarray(v, dtype=float).tolist() for k, v in extrinsics.items()})

    def write_poses(self, poses: np.ndarray) -> None:
        poses = sceneio.check_poses(np.asarray(poses, dtype=np.float64), f"ego poses of {self.out}")
        np.savetxt(self.path("ego_poses.txt"), poses[:, :3, :].reshape(len(poses), 12), fmt="%.12g")

    def write_intrinsics(self, camera: str, K: np.ndarray, size: tuple[int, int]) -> None:
        sceneio.write_intrinsics(self.path(f"{camera}.txt"), K, size)

    def place(self, source: Path, relative: str) -> None:
        """Symlink (or copy) a source file that is already in the canonical format."""
        if not source.exists():
            raise AdapterError(f"{source}: missing")
        dst = self.path(relative)
        if self.link:
            os.symlink(source.resolve(), dst)
        else:
            shutil.copyfile(source, dst)

    def place_image(self, source: Path, relative: str) -> None:
        """A PNG source is placed as is; other formats are decoded and written as PNG."""
        if source.suffix.lower() == ".png":
            check_png_complete(source)
            self.place(source, relative)
            return
        image = cv2.imread(str(source), cv2.IMREAD_COLOR)
        if image is None:
            raise AdapterError(f"{source}: {'unreadable image' if source.exists() else 'image missing'}")
        cv2.imwrite(str(self.path(relative)), image)

    def write_png(self, relative: str, array: np.ndarray) -> None:
        if not cv2.imwrite(str(self.path(relative)), array):
            raise AdapterError(f"could not write {relative}")

    def write_lidar(self, relative: str, points: np.ndarray) -> None:
        self.path(relative).write_bytes(np.ascontiguousarray(points, dtype="<f4").reshape(-1, 4).tobytes())

    def write_boxes(self, rows: list[dict]) -> None:
        frame = pd.DataFrame(rows, columns=BOX_COLUMNS)
        frame.to_csv(self.path("gt/boxes.csv"), index=False, float_format="%.9g")


def empty_box_row(frame: int, track_id: int, cls: str) -> dict:
    """A boxes.csv row with every measured field unknown (NaN); occlusion -1 (KITTI's 'unknown')."""
    row = {c: float("nan") for c in BOX_COLUMNS}
    row.update(frame=int(frame), track_id=int(track_id), cls=cls, occlusion=-1)
    return row
