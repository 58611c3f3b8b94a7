"""Target assignment of ch. 7: heatmap cells from 2D masks (median of L_m + multi-cell voting) or, for the
fully supervised reference, from ground-truth boxes.

Weak targets (S 3.3): the coordinate-wise median (x, y) of a mask's L_m picks a cell; the predictions of
the (2w+1)^2 cells around it are evaluated with the alignment loss against L_m
(`redsup.det3d.voting.vote`) and the lowest-loss cell becomes the object's cell: the heatmap peak, the
cell whose offset is trained by the template alignment and whose yaw logits get the best-bin target.
Masks whose median falls outside the grid are skipped (counted).

What "the loss of a cell's prediction" is (`vote_yaw`): "predicted" evaluates the alignment loss at the
cell's own arg-max yaw (`voting.vote`, yaw_mode "predicted"); "best" at the best of the K bins at the
cell's centre (eq. 8; `voting.vote`, yaw_mode "best"); "loss" the whole per-object loss of eq. (9) for
that cell: alignment at the best bin + the cross-entropy of the cell's yaw logits to that bin
(`vote_eq9`). "best" and "loss" evaluate every bin of every candidate cell, on a random subset of at most
`vote_points` points of each L_m.

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

import torch.nn.functional as F

from redsup.det3d.losses import masked_mean, yaw_bin_centers, yaw_to_bin
from redsup.det3d.pointsets import pad_point_sets
from redsup.det3d.template import Template, distance_to_template
from redsup.det3d.voting import BevGrid, VoteResult, median_cell, vote, window_offsets


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


def _subsample(points: torch.Tensor, mask: torch.Tensor, k: int | None, generator: torch.Generator | None):
    """At most k real points per padded set (random without replacement, deterministic for a seeded
    generator); returns (points (N, k', 3), mask (N, k'))."""
    if k is None or points.shape[1] <= k:
        return points, mask
    keys = torch.rand(mask.shape, generator=generator, device=mask.device) if generator is not None \
        else torch.rand(mask.shape, device=mask.device)
    keys = torch.where(mask, keys, torch.full_like(keys, 2.0))           # padding sorts last
    idx = keys.argsort(dim=1)[:, :k]
    return torch.gather(points, 1, idx[..., None].expand(-1, -1, 3)), torch.gather(mask, 1, idx)


def vote_eq9(grid: BevGrid, offsets: torch.Tensor, yaw_logits: torch.Tensor, points: torch.Tensor,
             mask: torch.Tensor | None, cells: torch.Tensor, frame_index: torch.Tensor, window: int,
             loss_fn: Callable[[torch.Tensor], torch.Tensor], template: Template) -> VoteResult:
    """Multi-cell voting with the per-object loss of ch. 7 eq. (9) as the cell's score: alignment at the
    cell's best yaw bin (eq. 8) + cross-entropy of its yaw logits to that bin. Same arguments and result
    as `voting.vote` (yaw = the best bin's yaw); ties go to the first cell in row-major order."""
    with torch.no_grad():
        n, n_bins = points.shape[0], yaw_logits.shape[1]
        win = window_offsets(window, device=points.device)
        cand = cells[:, None, :] + win[None]                                      # (N, C, 2)
        rows, cols = cand[..., 0], cand[..., 1]
        inside = (rows >= 0) & (rows < grid.height) & (cols >= 0) & (cols < grid.width) \
            & (cells[:, None, 0] >= 0)
        r, c = rows.clamp(0, grid.height - 1), cols.clamp(0, grid.width - 1)
        f = frame_index[:, None].expand_as(r)
        centre = grid.decode(r, c, offsets.permute(0, 2, 3, 1)[f, r, c].to(points.dtype))     # (N, C, 3)
        bins = yaw_bin_centers(n_bins, dtype=points.dtype, device=points.device)
        d = distance_to_template(template, points[:, None, None], centre[:, :, None],
                                 bins.expand(n, cand.shape[1], n_bins))          # (N, C, K, P)
        per_bin = masked_mean(loss_fn(d), None if mask is None else mask[:, None, None, :])
        align, best = per_bin.min(dim=-1)                                         # (N, C)
        logp = F.log_softmax(yaw_logits.permute(0, 2, 3, 1)[f, r, c].to(points.dtype), dim=-1)   # (N, C, K)
        loss = align - logp.gather(-1, best[..., None])[..., 0]
        loss = torch.where(inside, loss, torch.full_like(loss, float("inf")))
        k = loss.argmin(dim=1)
        idx = torch.arange(n, device=points.device)
        found = torch.isfinite(loss[idx, k])
        cell = torch.where(found[:, None], cand[idx, k], torch.full_like(cand[idx, k], -1))
        return VoteResult(cell, centre[idx, k], bins[best[idx, k]], loss[idx, k], cand, loss)


def assign_weak(grid: BevGrid, outputs: dict[str, torch.Tensor], objs: WeakObjects, window: int,
                loss_fn: Callable[[torch.Tensor], torch.Tensor], template: Template,
                yaw_mode: str = "predicted", vote_points: int | None = None,
                generator: torch.Generator | None = None, recentre: int = 0) -> WeakAssignment:
    """Median cell of each L_m, then multi-cell voting over the (2 window + 1)^2 neighbourhood using the
    current predictions (no gradients); `yaw_mode` "predicted" | "best" | "loss" (module docstring).

    ``recentre`` k > 0: k more votes, each over the window around the cell that holds the previous winner's
    predicted centre (ch. 7 sec. 3.3: "the center of the best prediction is used as an updated center"), so
    the chosen cell can reach (k + 1) window cells from the median; an object whose predicted centre leaves
    the grid keeps its last winner."""
    if recentre < 0:
        raise ValueError(f"recentre must be >= 0, got {recentre}")
    pts = objs.points.to(outputs["offset"].device)
    mask = objs.mask.to(pts.device)
    med = median_cell(grid, pts, mask)
    off, logits, frame = outputs["offset"].detach(), outputs["yaw"].detach(), objs.frame.to(pts.device)
    if yaw_mode not in ("predicted", "best", "loss"):
        raise ValueError(f"vote yaw mode must be 'predicted', 'best' or 'loss', got {yaw_mode!r}")
    vp, vm = (pts, mask) if yaw_mode == "predicted" else _subsample(pts, mask, vote_points, generator)
    cells = med
    for k in range(recentre + 1):
        if yaw_mode == "loss":
            res = vote_eq9(grid, off, logits, vp, vm, cells, frame, window, loss_fn, template)
        else:
            res = vote(grid, off, logits, vp, vm, cells, frame, window, loss_fn, template, yaw_mode=yaw_mode)
        if k < recentre:
            moved = grid.cell_of(res.centre)
            cells = torch.where((moved[:, :1] >= 0) & (res.cell[:, :1] >= 0), moved, res.cell)
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
    cells, frame, radius = cells.cpu(), frame.cpu(), radius.cpu()   # read as numbers; the voted cells are on the device
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
