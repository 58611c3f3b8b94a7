"""Target assignment of ch. 7: heatmap cells from 2D masks (median of L_m + multi-cell voting) or, for the
fully supervised reference, from ground-truth boxes.

Weak targets (S 3.3): the coordinate-wise median (x, y) of a mask's L_m picks a cell; the predictions of
the (2w+1)^2 cells around it are evaluated with the alignment loss against L_m
(`redsup.det3d.voting.vote`) and the lowest-loss cell becomes the object's cell: the heatmap peak, the
cell whose offset is trained by the template alignment and whose yaw logits get the best-bin target.
Masks whose median falls outside the grid are skipped (counted).

Heatmap targets are CenterNet Gaussians, max-merged, peak exactly 1 at the object's cell, radius from
the object's BEV size in cells (`gaussian_radius`, min_overlap 0.1, at least `min_radius` cells, as
CenterPoint); weak objects use the template size.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from redsup.det3d.losses import yaw_to_bin
from redsup.det3d.pointsets import pad_point_sets
from redsup.det3d.template import Template
from redsup.det3d.voting import BevGrid, VoteResult, median_cell, vote


@dataclass
class WeakObjects:
    """Padded L_m sets of a batch of frames."""
    points: torch.Tensor     # (N, P, 3)
    mask: torch.Tensor       # (N, P) bool
    frame: torch.Tensor      # (N,) long, frame of the batch
    n_skipped: int           # sets dropped by pad_point_sets (fewer than min_points finite points)
    n_nonfinite: int

    def __len__(self) -> int:
        return self.points.shape[0]


def weak_objects(sets_per_frame: list[list[np.ndarray]], min_points: int, max_points: int | None,
                 rng: np.random.Generator) -> WeakObjects:
    """Pad the L_m sets of B frames (list of lists of (n, >=3) arrays); sets with fewer than `min_points`
    finite points are skipped (counted), larger ones subsampled to `max_points`."""
    flat = [s for sets in sets_per_frame for s in sets]
    frame = np.array([b for b, sets in enumerate(sets_per_frame) for _ in sets], dtype=np.int64)
    padded = pad_point_sets(flat, min_points=min_points, max_points=max_points, rng=rng)
    return WeakObjects(padded.points, padded.mask, torch.as_tensor(frame[padded.keep], dtype=torch.long),
                       len(padded.skipped), padded.n_nonfinite)


@dataclass
class WeakAssignment:
    cell: torch.Tensor       # (N, 2) long (row, col), -1 where the object is skipped
    valid: torch.Tensor      # (N,) bool: median inside the grid (a cell was chosen)
    median: torch.Tensor     # (N, 2) the median cells
    vote: VoteResult


def assign_weak(grid: BevGrid, outputs: dict[str, torch.Tensor], objs: WeakObjects, window: int,
                loss_fn: Callable[[torch.Tensor], torch.Tensor], template: Template,
                yaw_mode: str = "predicted") -> WeakAssignment:
    """Median cell of each L_m, then multi-cell voting over the (2 window + 1)^2 neighbourhood using the
    current predictions (no gradients)."""
    pts = objs.points.to(outputs["offset"].device)
    mask = objs.mask.to(pts.device)
    med = median_cell(grid, pts, mask)
    res = vote(grid, outputs["offset"].detach(), outputs["yaw"].detach(), pts, mask, med,
               objs.frame.to(pts.device), window, loss_fn, template, yaw_mode=yaw_mode)
    valid = res.cell[:, 0] >= 0
    return WeakAssignment(res.cell, valid, med, res)


def gaussian_radius(length_cells: float, width_cells: float, min_overlap: float = 0.1) -> float:
    """CenterNet / CenterPoint `gaussian_radius` for a box of (length, width) cells."""
    h, w = length_cells, width_cells
    b1, c1 = h + w, w * h * (1 - min_overlap) / (1 + min_overlap)
    r1 = (b1 + math.sqrt(b1 ** 2 - 4 * c1)) / 2
    b2, c2 = 2 * (h + w), (1 - min_overlap) * w * h
    r2 = (b2 + math.sqrt(b2 ** 2 - 16 * c2)) / 2
    a3, b3, c3 = 4 * min_overlap, -2 * min_overlap * (h + w), (min_overlap - 1) * w * h
    r3 = (b3 + math.sqrt(b3 ** 2 - 4 * a3 * c3)) / 2
    return min(r1, r2, r3)


def object_radius(length: float, width: float, cell: float, min_radius: int = 2) -> int:
    return max(int(min_radius), int(gaussian_radius(length / cell, width / cell)))


def heatmap_target(batch: int, height: int, width: int, frame: torch.Tensor, cells: torch.Tensor,
                   radius: torch.Tensor, dtype=torch.float32, device=None) -> torch.Tensor:
    """(B, 1, H, W) max of Gaussians exp(-(dr^2 + dc^2) / (2 sigma^2)), sigma = (2 r + 1) / 6, cut at
    |dr|, |dc| <= r, one per object (frame (N,), cells (N, 2) long, radius (N,) cells); rows with cell -1
    are ignored."""
    heat = torch.zeros((batch, 1, height, width), dtype=dtype, device=device)
    ok = cells[:, 0] >= 0
    rows = torch.arange(height, device=device, dtype=dtype)
    cols = torch.arange(width, device=device, dtype=dtype)
    for (r, c), b, rad in zip(cells[ok].tolist(), frame[ok].tolist(), radius[ok].tolist()):
        sigma = (2 * rad + 1) / 6.0
        dr = (rows - r)[:, None]
        dc = (cols - c)[None, :]
        g = torch.exp(-(dr * dr + dc * dc) / (2 * sigma * sigma))
        g = torch.where((dr.abs() <= rad) & (dc.abs() <= rad), g, torch.zeros_like(g))
        heat[b, 0] = torch.maximum(heat[b, 0], g)
    return heat


@dataclass
class SupervisedTargets:
    frame: torch.Tensor      # (N,) long
    cell: torch.Tensor       # (N, 2) long (row, col)
    offset: torch.Tensor     # (N, 3) centre - cell corner (x, y, z_ref)
    yaw_bin: torch.Tensor    # (N,) long
    log_size: torch.Tensor   # (N, 3) log(size / template size)
    radius: torch.Tensor     # (N,) heatmap radius in cells


def assign_supervised(grid: BevGrid, boxes_per_frame: list[np.ndarray], n_bins: int, template_size: np.ndarray,
                      min_radius: int = 2) -> SupervisedTargets:
    """CenterPoint's targets from ground-truth boxes (x, y, z, l, w, h, yaw) per frame; boxes whose centre
    lies outside the grid are dropped."""
    boxes = np.concatenate([np.asarray(b, dtype=np.float64).reshape(-1, 7) for b in boxes_per_frame] or
                           [np.zeros((0, 7))])
    frame = np.concatenate([np.full(len(np.asarray(b).reshape(-1, 7)), i) for i, b in enumerate(boxes_per_frame)]
                           or [np.zeros(0)]).astype(np.int64)
    t = torch.as_tensor(boxes, dtype=torch.float32)
    cell = grid.cell_of(t[:, :2]) if len(t) else torch.zeros((0, 2), dtype=torch.long)
    ok = cell[:, 0] >= 0
    t, cell, frame = t[ok], cell[ok], torch.as_tensor(frame)[ok]
    corner = torch.stack([grid.x_min + cell[:, 1].float() * grid.cell, grid.y_min + cell[:, 0].float() * grid.cell,
                          torch.full((len(t),), grid.z_ref)], dim=-1)
    size = torch.as_tensor(np.asarray(template_size, dtype=np.float32))
    radius = torch.tensor([object_radius(float(b[3]), float(b[4]), grid.cell, min_radius) for b in t],
                          dtype=torch.float32)
    return SupervisedTargets(frame=frame, cell=cell, offset=t[:, :3] - corner, yaw_bin=yaw_to_bin(t[:, 6], n_bins),
                             log_size=torch.log(t[:, 3:6].clamp_min(1e-3) / size), radius=radius)
