"""Bit-packed masks and the per-scene detection / road files (`detections_{level}.npz`, `road.npz`).

Masks are stored as `np.packbits` of the H x W boolean image flattened row-major, one row per mask, with
`image_size` = (W, H) beside them. Everything that reads these files goes through the accessors here, so
nobody re-implements the packing.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np


def packed_width(size: tuple[int, int]) -> int:
    """Bytes per packed mask of an image of size (W, H)."""
    return -(-int(size[0]) * int(size[1]) // 8)


def pack_masks(masks, size: tuple[int, int]) -> np.ndarray:
    """(D, ceil(H*W/8)) uint8 from a sequence of (H, W) bool masks (may be empty)."""
    width, height = int(size[0]), int(size[1])
    out = np.zeros((len(masks), packed_width(size)), dtype=np.uint8)
    for i, mask in enumerate(masks):
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != (height, width):
            raise ValueError(f"mask {i} has shape {mask.shape}, expected (H, W) = {(height, width)}")
        out[i] = np.packbits(mask.ravel())
    return out


def unpack_mask(row: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(H, W) bool mask from one packed row."""
    width, height = int(size[0]), int(size[1])
    return np.unpackbits(row, count=width * height).reshape(height, width).astype(bool)


def load_detections(path: str | Path) -> dict:
    """All arrays of a `detections_{level}.npz` as a dict (plain numpy arrays, file closed)."""
    with np.load(path, allow_pickle=False) as data:
        return {key: data[key] for key in data.files}


def n_detections(d: dict) -> int:
    return int(len(d["frame"]))


def mask_of(d: dict, i: int) -> np.ndarray:
    """(H, W) bool mask of detection i."""
    return unpack_mask(d["mask"][i], tuple(d["image_size"]))


def points_of(d: dict, i: int) -> np.ndarray:
    """(n, 4) L_m points (LiDAR frame x, y, z, reflectance) of detection i."""
    return d["points"][d["point_offsets"][i]:d["point_offsets"][i + 1]]


def inliers_of(d: dict, i: int) -> np.ndarray:
    """(n,) bool: L_m point of detection i inside its matched ground-truth box (evaluation only)."""
    return d["point_inlier_gt"][d["point_offsets"][i]:d["point_offsets"][i + 1]]


def box_points_of(d: dict, i: int) -> np.ndarray:
    """(q, 4) LiDAR points inside the 2D box frustum of detection i."""
    return d["box_points"][d["box_point_offsets"][i]:d["box_point_offsets"][i + 1]]


def n_points(d: dict) -> np.ndarray:
    """(D,) number of L_m points per detection."""
    return np.diff(d["point_offsets"])


def offsets_from_counts(counts) -> np.ndarray:
    """(D+1,) int64 offsets for concatenated per-detection arrays."""
    out = np.zeros(len(counts) + 1, dtype=np.int64)
    np.cumsum(np.asarray(counts, dtype=np.int64), out=out[1:])
    return out


def load_road(path: str | Path) -> dict:
    with np.load(path, allow_pickle=False) as data:
        return {key: data[key] for key in data.files}


def road_of(r: dict, frame: int) -> np.ndarray:
    """(H, W) bool predicted road mask of one frame."""
    return unpack_mask(r["road"][frame], tuple(r["image_size"]))
