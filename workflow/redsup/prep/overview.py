"""The overview picture of one rendered frame: image, depth buffer, LiDAR overlay, 2D detections."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from redsup import geometry, sceneio  # noqa: E402
from redsup.prep.depthmap import LIDAR, frame_depth  # noqa: E402
from redsup.prep.masks_io import load_detections, mask_of  # noqa: E402


def frame_overview(scene_dir: str | Path, detections_path: str | Path, frame: int | None = None,
                   camera: str = "cam_front", depth_range: tuple[float, float] = (0.1, 80.0)):
    """A matplotlib figure with four panels for one frame (the middle one by default)."""
    scene_dir = Path(scene_dir)
    meta = sceneio.read_meta(scene_dir)
    frame = meta["n_frames"] // 2 if frame is None else frame
    image = sceneio.read_image(scene_dir / camera / sceneio.frame_name(frame, "png"))
    buffer = sceneio.read_depth_png(scene_dir / "gt" / "depth" / camera / sceneio.frame_name(frame, "png"))
    K, size = sceneio.read_intrinsics(scene_dir / f"{camera}.txt")
    poses = sceneio.read_poses(scene_dir / "ego_poses.txt")
    ext = sceneio.read_extrinsics(scene_dir / "extrinsics.json")
    points = sceneio.read_lidar(scene_dir / LIDAR / sceneio.frame_name(frame, "bin"))
    T = geometry.lidar_to_camera(ext[LIDAR], poses[frame], poses[frame], ext[camera])
    lidar = frame_depth(points, T, K, size, depth_range)
    dets = load_detections(detections_path)
    mine = np.flatnonzero(dets["frame"] == frame)

    fig, axes = plt.subplots(2, 2, figsize=(12, 12 * size[1] / size[0] + 1.0), constrained_layout=True)
    axes[0, 0].imshow(image)
    axes[0, 0].set_title(f"{meta['scene']} frame {frame}: {camera}")
    axes[0, 1].imshow(np.where(buffer > 0, buffer, np.nan), cmap="magma_r", vmin=0, vmax=depth_range[1])
    axes[0, 1].set_title("renderer depth buffer (m)")
    v, u = np.nonzero(lidar)
    axes[1, 0].imshow(image)
    sc = axes[1, 0].scatter(u, v, c=lidar[v, u], s=0.6, cmap="turbo", vmin=0, vmax=depth_range[1], linewidths=0)
    rel = geometry.median_relative_error(lidar, buffer)
    axes[1, 0].set_title(f"LiDAR projected (median rel. error vs buffer {100 * rel:.2f} %)")
    fig.colorbar(sc, ax=axes[1, 0], fraction=0.03, label="depth (m)")
    overlay = image.astype(float) / 255
    colours = plt.cm.tab10(np.arange(len(mine)) % 10)[:, :3]
    for colour, det in zip(colours, mine):
        m = mask_of(dets, det)
        overlay[m] = 0.5 * overlay[m] + 0.5 * colour
    axes[1, 1].imshow(overlay)
    for colour, det in zip(colours, mine):
        x1, y1, x2, y2 = dets["box"][det]
        axes[1, 1].add_patch(plt.Rectangle((x1, y1), x2 - x1, y2 - y1, fill=False, color=colour, lw=1))
        axes[1, 1].text(x1, y1 - 2, f"{dets['score'][det]:.2f}", color=colour, fontsize=7)
        lo, hi = dets["point_offsets"][det], dets["point_offsets"][det + 1]
        pts = dets["points"][lo:hi]
        if len(pts):
            uv, _ = geometry.project(K, geometry.transform_points(T, pts[:, :3].astype(float)))
            inlier = dets["point_inlier_gt"][lo:hi]
            axes[1, 1].scatter(uv[inlier, 0], uv[inlier, 1], s=0.6, c="lime", linewidths=0)
            axes[1, 1].scatter(uv[~inlier, 0], uv[~inlier, 1], s=0.6, c="red", linewidths=0)
    axes[1, 1].set_title("stand-in 2D masks + scores; L_m points: green on the car, red background", fontsize=9)
    for ax in axes.ravel():
        ax.set_axis_off()
    return fig
