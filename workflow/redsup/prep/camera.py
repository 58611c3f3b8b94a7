"""Cropped and resized camera images with adjusted intrinsics (Galteland §3.6.2.4, eq. 3.33-3.35)."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from redsup import geometry, sceneio
from redsup.fileio import save_npz_atomic


def crop_resize(image: np.ndarray, crop: dict, out_size: tuple[int, int]) -> np.ndarray:
    """Cut crop[top/bottom/left/right] pixels, then resize to out_size = (width, height) (area filter)."""
    h, w = image.shape[:2]
    cut = image[crop["top"]:h - crop["bottom"], crop["left"]:w - crop["right"]]
    if cut.shape[0] <= 0 or cut.shape[1] <= 0:
        raise ValueError(f"crop {crop} leaves nothing of a {w}x{h} image")
    if (cut.shape[1], cut.shape[0]) == tuple(out_size):
        return np.ascontiguousarray(cut)
    return cv2.resize(cut, tuple(out_size), interpolation=cv2.INTER_AREA)


def prepare_camera(scene_dir: str | Path, camera: str, crop: dict, resize: dict,
                   out_path: str | Path) -> dict:
    """Write `<camera>.npz`: images (T, H, W, 3) uint8, K (adjusted), K_raw, raw_size, crop.

    Returns summary numbers for tracking.
    """
    scene_dir = Path(scene_dir)
    meta = sceneio.read_meta(scene_dir)
    K_raw, raw_size = sceneio.read_intrinsics(scene_dir / f"{camera}.txt")
    frames = sceneio.sensor_frames(scene_dir, camera, "png", meta["n_frames"])
    out_size = (resize["width"], resize["height"])
    images = np.empty((len(frames), out_size[1], out_size[0], 3), dtype=np.uint8)
    for i, path in enumerate(tqdm(frames, desc=f"{scene_dir.name}/{camera}", mininterval=5)):
        image = sceneio.read_image(path)
        if (image.shape[1], image.shape[0]) != raw_size:
            raise sceneio.SceneError(f"{path}: image is {image.shape[1]}x{image.shape[0]} but "
                                     f"{scene_dir / (camera + '.txt')} says {raw_size[0]}x{raw_size[1]}")
        images[i] = crop_resize(image, crop, out_size)
    K = geometry.crop_resize_intrinsics(K_raw, crop, raw_size, out_size)
    save_npz_atomic(out_path, images=images, K=K, K_raw=K_raw, raw_size=np.array(raw_size),
                    crop=np.array([crop["top"], crop["bottom"], crop["left"], crop["right"]]),
                    fps=np.array(meta["fps"]))
    return {"frames": len(frames), "width": out_size[0], "height": out_size[1],
            "fx": float(K[0, 0]), "fy": float(K[1, 1]), "cx": float(K[0, 2]), "cy": float(K[1, 2]),
            "mean_intensity": float(images.mean())}
