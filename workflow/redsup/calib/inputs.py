"""One scene's inputs to the calibration tables, at the resolutions each step needs.

- the raw network depth ``pred`` (T, h, w) and its intrinsics ``K`` at the prepared resolution (the depth
  stage's ``results/depth/predictions/<dataset>/<mode>/<scene>.npz``: ``depth``, ``K``);
- the stand-in road masks (``road.npz``, raw camera resolution) cropped and resized to the prepared
  resolution with nearest-neighbour sampling at pixel centres (the convention of
  ``redsup.geometry.crop_resize_intrinsics``, so masks and ``K`` agree);
- the LiDAR ground truth ``gt`` (T, H, W) at the cropped raw resolution (``<camera>_depth.npz``), where the
  prediction is evaluated after bilinear resizing of its disparity (Monodepth2's evaluation).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from redsup.prep import masks_io
from redsup.sceneio import read_extrinsics, read_meta


@dataclass
class SceneInputs:
    name: str
    pred: np.ndarray  # (T, h, w) float32 raw network depth (network units)
    K: np.ndarray  # (3, 3) intrinsics of pred
    gt: np.ndarray | None = None  # (T, H, W) float32 LiDAR depth (0 = none)
    road: np.ndarray | None = None  # (T, h, w) bool road masks at the prediction's resolution
    gt_K: np.ndarray | None = None  # (3, 3) intrinsics of gt (the crop of the raw camera)
    road_gt: np.ndarray | None = None  # (T, H, W) bool road masks cropped to the ground truth (diagnostics)

    @property
    def n_frames(self) -> int:
        return int(self.pred.shape[0])


def crop_resize_nearest(mask: np.ndarray, crop: dict, out_size: tuple[int, int]) -> np.ndarray:
    """Cut crop[top/bottom/left/right] pixels of an (H, W) (or (T, H, W)) mask, then resize it to
    out_size = (width, height) by nearest neighbour: output pixel j takes the input pixel that contains the
    centre (j + 0.5) * in / out (pixel-centre convention, as the intrinsics are adjusted)."""
    mask = np.asarray(mask)
    h, w = mask.shape[-2:]
    cut = mask[..., crop["top"]:h - crop["bottom"], crop["left"]:w - crop["right"]]
    ch, cw = cut.shape[-2:]
    if ch <= 0 or cw <= 0:
        raise ValueError(f"crop {crop} leaves nothing of a {w}x{h} mask")
    out_w, out_h = int(out_size[0]), int(out_size[1])
    rows = np.minimum(((np.arange(out_h) + 0.5) * ch / out_h).astype(np.int64), ch - 1)
    cols = np.minimum(((np.arange(out_w) + 0.5) * cw / out_w).astype(np.int64), cw - 1)
    return cut[..., rows[:, None], cols[None, :]]


def resize_depth(pred: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(H, W) = size: the prediction resized bilinearly *in disparity* (Monodepth2), back to depth.
    Non-positive or non-finite depths stay non-finite where they influence the result."""
    import cv2

    pred = np.asarray(pred, dtype=np.float32)
    if pred.shape == tuple(size):
        return pred.astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        disp = np.where(np.isfinite(pred) & (pred > 0), 1.0 / pred, np.nan).astype(np.float32)
    disp = cv2.resize(disp, (int(size[1]), int(size[0])), interpolation=cv2.INTER_LINEAR)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(disp > 0, 1.0 / disp.astype(np.float64), np.nan)


def load_scene(pred_path: str | Path, gt_path: str | Path | None = None, road_path: str | Path | None = None, *,
               crop: dict | None = None, name: str | None = None) -> SceneInputs:
    """Read one scene (see the module docstring). ``crop`` (the dataset's raw crop) is needed with
    ``road_path``; the road masks are resized to the prediction's resolution. Frame counts and sizes are
    checked against each other (ValueError naming the files)."""
    with np.load(pred_path, allow_pickle=False) as data:
        if "depth" not in data.files or "K" not in data.files:
            raise ValueError(f"{pred_path}: needs arrays 'depth' and 'K', has {data.files}")
        pred = np.asarray(data["depth"], dtype=np.float32)
        K = np.asarray(data["K"], dtype=np.float64)[:3, :3]
    if pred.ndim != 3:
        raise ValueError(f"{pred_path}: depth must be (T, H, W), got {pred.shape}")
    scene = SceneInputs(name or Path(pred_path).stem, pred, K)
    if gt_path is not None:
        with np.load(gt_path, allow_pickle=False) as data:
            gt = np.asarray(data["depth"], dtype=np.float32)
            scene.gt_K = np.asarray(data["K"], dtype=np.float64)[:3, :3] if "K" in data.files else None
        if len(gt) != len(pred):
            raise ValueError(f"{gt_path}: {len(gt)} ground-truth frames but {pred_path} has {len(pred)}")
        scene.gt = gt
    if road_path is not None:
        if crop is None:
            raise ValueError("load_scene: road masks need the dataset's crop")
        road = masks_io.load_road(road_path)
        n = len(road["road"])
        if n != len(pred):
            raise ValueError(f"{road_path}: {n} road masks but {pred_path} has {len(pred)} frames")
        out_size = (pred.shape[2], pred.shape[1])
        raw_w, raw_h = (int(v) for v in road["image_size"])
        if scene.gt is not None:
            expect = (raw_h - crop["top"] - crop["bottom"], raw_w - crop["left"] - crop["right"])
            if tuple(scene.gt.shape[1:]) != expect:
                raise ValueError(f"{road_path}: masks of {raw_w}x{raw_h} cropped by {crop} give {expect[::-1]} "
                                 f"but the ground truth {gt_path} is {scene.gt.shape[2]}x{scene.gt.shape[1]}")
        raw = np.stack([masks_io.road_of(road, i) for i in range(n)])
        scene.road = crop_resize_nearest(raw, crop, out_size)
        if scene.gt is not None:
            scene.road_gt = crop_resize_nearest(raw, crop, (scene.gt.shape[2], scene.gt.shape[1]))
    return scene


def camera_geometry(scene_dir: str | Path, camera: str) -> dict:
    """{"camera_height": m above the road, "fps": frames per second} of one raw scene: the height is the
    camera's z in the vehicle frame (whose origin lies on the road, README "The canonical raw-scene
    format"); ValueError naming the file when the camera is absent or not above the road."""
    scene_dir = Path(scene_dir)
    path = scene_dir / "extrinsics.json"
    extrinsics = read_extrinsics(path)
    if camera not in extrinsics:
        raise ValueError(f"{path}: no extrinsics for camera '{camera}' (has {sorted(extrinsics)})")
    height = float(extrinsics[camera][2, 3])
    if not np.isfinite(height) or height <= 0:
        raise ValueError(f"{path}: camera '{camera}' is at z = {height} m; the camera height must be > 0")
    return {"camera_height": height, "fps": float(read_meta(scene_dir)["fps"])}
