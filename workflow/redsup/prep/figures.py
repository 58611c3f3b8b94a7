"""Diagnostic figures of the preparation stages (logged to MLflow by the Snakemake scripts)."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from redsup import geometry, sceneio  # noqa: E402
from redsup.prep import masks_io  # noqa: E402
from redsup.prep.detections import LIDAR  # noqa: E402


def busiest_frame(d: dict) -> int:
    """The frame with most detections (0 when there are none)."""
    if len(d["frame"]) == 0:
        return 0
    return int(np.bincount(d["frame"]).argmax())


def detection_overlay(scene_dir: str | Path, d: dict, frame: int):
    """Camera image with the frame's masks, boxes and scores, and the L_m points coloured by the
    ground-truth inlier flag (green inside the matched box, red outside)."""
    scene_dir = Path(scene_dir)
    camera = str(d["camera"])
    image = sceneio.read_image(scene_dir / camera / sceneio.frame_name(frame, "png"))
    K, _ = sceneio.read_intrinsics(scene_dir / f"{camera}.txt")
    ext = sceneio.read_extrinsics(scene_dir / "extrinsics.json")
    T = geometry.invert_pose(ext[camera]) @ ext[LIDAR]
    overlay = image.astype(np.float32) / 255.0
    rng = np.random.default_rng(0)
    fig, ax = plt.subplots(figsize=(12, 12 * image.shape[0] / image.shape[1] + 0.6), dpi=100)
    ids = np.flatnonzero(d["frame"] == frame)
    for i in ids:
        colour = rng.uniform(0.2, 1.0, 3)
        m = masks_io.mask_of(d, i)
        overlay[m] = 0.5 * overlay[m] + 0.5 * colour
    ax.imshow(overlay)
    for i in ids:
        x1, y1, x2, y2 = d["box"][i]
        matched = d["matched_track"][i] >= 0
        ax.add_patch(plt.Rectangle((x1, y1), x2 - x1, y2 - y1, fill=False, lw=1,
                                   ec="yellow" if matched else "magenta"))
        ax.text(x1, y1 - 2, f"{d['score'][i]:.2f}", color="yellow" if matched else "magenta", fontsize=7)
        pts = masks_io.points_of(d, i)
        if len(pts):
            uv, _ = geometry.project(K, geometry.transform_points(T, pts[:, :3].astype(np.float64)))
            inl = masks_io.inliers_of(d, i)
            ax.scatter(uv[inl, 0], uv[inl, 1], s=2, c="lime", linewidths=0)
            ax.scatter(uv[~inl, 0], uv[~inl, 1], s=2, c="red", linewidths=0)
    ax.set_title(f"{scene_dir.name} frame {frame}: {len(ids)} detections ({d['level']}); "
                 "yellow = matched, magenta = unmatched; L_m points green = in gt box, red = outlier",
                 fontsize=8)
    ax.set_axis_off()
    fig.tight_layout()
    return fig
