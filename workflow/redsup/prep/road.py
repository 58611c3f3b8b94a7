"""A noisy road segmenter standing in for the pretrained one of McCraith ch. 5 (road pixels feed the
per-frame road-plane fit).

From the ground-truth semantic road label (Cityscapes id 7): the signed distance to the road boundary
is shifted by a per-frame offset and a smooth random field (wavy boundary errors), then a few elliptic
false blobs (on e.g. sidewalk) are added and missed blobs cut out of the road. Pixel-valued settings are
given at `reference_height` and scaled with the image height. Deterministic given the seed.

`road.npz`: road (T, ceil(H*W/8)) uint8 packed bits (see masks_io), image_size (2,) = (W, H),
iou (T,) float32 per-frame IoU with the ground-truth road (1 when both are empty), camera.
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from redsup import sceneio
from redsup.fileio import save_npz_atomic
from redsup.prep import masks_io

ROAD_LABEL = 7


def signed_distance(mask: np.ndarray) -> np.ndarray:
    """Distance to the mask boundary in pixels: >= 1 inside, <= -1 outside (float32)."""
    m = mask.astype(np.uint8)
    if m.all():
        return np.full(mask.shape, 1e4, np.float32)
    if not m.any():
        return np.full(mask.shape, -1e4, np.float32)
    inside = cv2.distanceTransform(m, cv2.DIST_L2, 3)
    outside = cv2.distanceTransform(1 - m, cv2.DIST_L2, 3)
    return (inside - outside).astype(np.float32)


def smooth_field(shape: tuple[int, int], cell_px: float, rng: np.random.Generator) -> np.ndarray:
    """Zero-mean, roughly unit-std random field varying over about `cell_px` pixels."""
    height, width = shape
    gh = max(2, int(np.ceil(height / max(cell_px, 1.0))) + 1)
    gw = max(2, int(np.ceil(width / max(cell_px, 1.0))) + 1)
    coarse = rng.standard_normal((gh, gw)).astype(np.float32)
    field = cv2.resize(coarse, (width, height), interpolation=cv2.INTER_CUBIC)
    std = float(field.std())
    return field / std if std > 0 else field


def _blobs(target: np.ndarray, n: int, height_px: tuple[float, float], rng: np.random.Generator,
           scale: float) -> np.ndarray:
    """Union of n ellipses centred on random pixels of `target` (bool image)."""
    out = np.zeros(target.shape, dtype=np.uint8)
    rows, cols = np.nonzero(target)
    if len(rows) == 0:
        return out.astype(bool)
    for _ in range(n):
        k = rng.integers(len(rows))
        half_h = max(1, int(round(rng.uniform(*height_px) * scale / 2)))
        half_w = max(1, int(round(half_h * rng.uniform(1.0, 3.0))))
        cv2.ellipse(out, (int(cols[k]), int(rows[k])), (half_w, half_h), float(rng.uniform(-20, 20)),
                    0, 360, 1, thickness=-1)
    return out.astype(bool)


def segment_road(semantic: np.ndarray, road_cfg: dict, rng: np.random.Generator, scale: float = 1.0) -> np.ndarray:
    """(H, W) bool predicted road from a Cityscapes-id label image."""
    gt = semantic == ROAD_LABEL
    sd = signed_distance(gt)
    offset = rng.normal(0.0, road_cfg["boundary_offset_std_px"]) * scale
    noise = road_cfg["boundary_noise_px"] * scale
    if noise > 0:
        sd = sd + noise * smooth_field(gt.shape, road_cfg["noise_cell_px"] * scale, rng)
    pred = (sd + offset) > 0
    n_fp = rng.poisson(road_cfg["fp_blobs_per_frame"]) if road_cfg["fp_blobs_per_frame"] > 0 else 0
    n_fn = rng.poisson(road_cfg["fn_blobs_per_frame"]) if road_cfg["fn_blobs_per_frame"] > 0 else 0
    if n_fp:
        pred |= _blobs(np.isin(semantic, road_cfg["fp_labels"]) & ~gt, n_fp, road_cfg["blob_height_px"], rng, scale)
    if n_fn:
        pred &= ~_blobs(gt, n_fn, road_cfg["blob_height_px"], rng, scale)
    return pred


def road_iou(pred: np.ndarray, gt: np.ndarray) -> float:
    union = np.count_nonzero(pred | gt)
    return float(np.count_nonzero(pred & gt) / union) if union else 1.0


def write_road(scene_dir: str | Path, out_path: str | Path, detection_cfg: dict, seed: int) -> dict:
    """Write `road.npz` for one scene; returns summary numbers (mean / min IoU with the ground truth)."""
    scene_dir = Path(scene_dir)
    camera, road_cfg = detection_cfg["camera"], detection_cfg["road"]
    meta = sceneio.read_meta(scene_dir)
    _, size = sceneio.read_intrinsics(scene_dir / f"{camera}.txt")
    scale = size[1] / detection_cfg["reference_height"]
    paths = sceneio.sensor_frames(scene_dir, f"gt/semantic/{camera}", "png", int(meta["n_frames"]))
    packed = np.zeros((len(paths), masks_io.packed_width(size)), dtype=np.uint8)
    ious = np.zeros(len(paths), dtype=np.float32)
    fractions = np.zeros(len(paths), dtype=np.float32)
    for i, path in enumerate(paths):
        semantic = sceneio.read_label_png(path)
        if semantic.shape != (size[1], size[0]):
            raise sceneio.SceneError(f"{path}: shape {semantic.shape} does not match the {camera} "
                                     f"intrinsics size (W, H) = {size}")
        rng = np.random.default_rng(np.random.SeedSequence([int(seed), i]))
        pred = segment_road(semantic, road_cfg, rng, scale)
        packed[i] = np.packbits(pred.ravel())
        ious[i] = road_iou(pred, semantic == ROAD_LABEL)
        fractions[i] = pred.mean()
    save_npz_atomic(out_path, road=packed, image_size=np.array(size, dtype=np.int32), iou=ious,
                    camera=np.array(camera))
    n = len(paths)
    return {"n_frames": n, "road_iou_mean": float(ious.mean()) if n else 0.0,
            "road_iou_min": float(ious.min()) if n else 0.0,
            "road_fraction_mean": float(fractions.mean()) if n else 0.0}
