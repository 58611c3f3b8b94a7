"""Figures of a training run: loss curves and one bird's-eye view of test detections."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from redsup.det3d.boxes import bev_corners  # noqa: E402
from redsup.lidar_detector.grid import GridSpec  # noqa: E402


def curves_figure(history: dict[str, list[tuple[int, float]]], title: str):
    """One panel per curve (`history[name] = [(step, value), ...]`)."""
    names = [k for k in history if k != "train/lr"]
    fig, axes = plt.subplots(1, max(1, len(names)), figsize=(3.2 * max(1, len(names)), 2.6), squeeze=False)
    for ax, name in zip(axes[0], names):
        steps, values = zip(*history[name]) if history[name] else ((), ())
        ax.plot(steps, values)
        ax.set_title(name.replace("train/", ""), fontsize=9)
        ax.set_xlabel("step", fontsize=8)
        ax.tick_params(labelsize=7)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def bev_figure(points: np.ndarray, gt_boxes: np.ndarray, det_boxes: np.ndarray, det_scores: np.ndarray,
               grid: GridSpec, title: str):
    """LiDAR points (grey), ground-truth boxes (green) and detections (red, alpha = score) in BEV."""
    fig, ax = plt.subplots(figsize=(7, 7 * (grid.y_range[1] - grid.y_range[0]) / (grid.x_range[1] - grid.x_range[0]) + 0.6))
    ax.scatter(points[:, 0], points[:, 1], s=0.2, c="0.6")
    for boxes, colour, alphas in ((gt_boxes, "tab:green", None), (det_boxes, "tab:red", det_scores)):
        if len(boxes) == 0:
            continue
        for k, c in enumerate(bev_corners(boxes)):
            loop = np.vstack([c, c[:1]])
            a = 1.0 if alphas is None else float(np.clip(alphas[k], 0.15, 1.0))
            ax.plot(loop[:, 0], loop[:, 1], color=colour, alpha=a, lw=1)
            ax.plot([boxes[k, 0], (c[0, 0] + c[3, 0]) / 2], [boxes[k, 1], (c[0, 1] + c[3, 1]) / 2], color=colour,
                    alpha=a, lw=1)
    ax.set_xlim(*grid.x_range)
    ax.set_ylim(*grid.y_range)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, forward)")
    ax.set_ylabel("y (m, left)")
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    return fig
