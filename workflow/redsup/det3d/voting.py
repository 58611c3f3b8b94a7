"""Multi-cell voting of McCraith ch. 7 (S 3.3, Table 3).

The centre of an object is unknown during training; the median of its mask points L_m picks a BEV cell,
the boxes predicted by the (2w+1)^2 cells around it are evaluated with the alignment loss against L_m,
and the cell whose prediction has the lowest loss becomes the object's cell (heatmap target, regression
and yaw-classification cell). w = 0 is CenterPoint's single cell.

BEV grid: H rows along y and W columns along x (the thesis' 200 x 176 map with x forward); cell (r, c)
covers x in [x_min + c cell, x_min + (c + 1) cell) and y in [y_min + r cell, y_min + (r + 1) cell).
Per-cell predictions are the network's channel-first maps: offsets (B, 3, H, W) in metres from the cell's
corner (x_min + c cell, y_min + r cell, z_ref) to the object centre, and yaw logits (B, K, H, W) over the
bins of `losses.yaw_bin_centers`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import torch

from redsup.det3d.losses import masked_mean, yaw_bin_centers
from redsup.det3d.template import Template, distance_to_template


@dataclass(frozen=True)
class BevGrid:
    x_min: float
    y_min: float
    cell: float
    height: int        # H rows (y)
    width: int         # W columns (x)
    z_ref: float = 0.0

    def cell_of(self, xy: torch.Tensor) -> torch.Tensor:
        """(..., 2) long (row, col) of points (..., >=2); -1 where outside the grid or not finite."""
        col = torch.floor((xy[..., 0] - self.x_min) / self.cell)
        row = torch.floor((xy[..., 1] - self.y_min) / self.cell)
        ok = torch.isfinite(col) & torch.isfinite(row) & (col >= 0) & (col < self.width) & (row >= 0) \
            & (row < self.height)
        rc = torch.stack([row, col], dim=-1)
        return torch.where(ok[..., None], rc, torch.full_like(rc, -1)).long()

    def decode(self, rows: torch.Tensor, cols: torch.Tensor, offsets: torch.Tensor) -> torch.Tensor:
        """Centres (..., 3) from cells and their offsets (..., 3) in metres."""
        corner = torch.stack([self.x_min + cols.to(offsets.dtype) * self.cell,
                              self.y_min + rows.to(offsets.dtype) * self.cell,
                              torch.full_like(offsets[..., 0], self.z_ref)], dim=-1)
        return corner + offsets


def median_cell(grid: BevGrid, points: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
    """(N, 2) (row, col) of the coordinate-wise median (x, y) of each padded point set (N, P, 3);
    -1 rows for sets without points or medians outside the grid."""
    xy = points[..., :2]
    if mask is not None:
        xy = torch.where(mask[..., None], xy, torch.full_like(xy, float("nan")))
    med = torch.nanmedian(xy, dim=1).values
    return grid.cell_of(med)


@dataclass
class VoteResult:
    cell: torch.Tensor        # (N, 2) long (row, col) of the lowest-loss cell
    centre: torch.Tensor      # (N, 3) its predicted centre
    yaw: torch.Tensor         # (N,) the yaw used to evaluate it
    loss: torch.Tensor        # (N,) its mean per-point loss
    window_cells: torch.Tensor   # (N, C, 2) all evaluated cells, C = (2w + 1)^2, row-major
    window_loss: torch.Tensor    # (N, C) their losses (+inf outside the grid)


def window_offsets(window: int, device=None) -> torch.Tensor:
    """(C, 2) (drow, dcol) of the (2w+1)^2 window, row-major."""
    r = torch.arange(-window, window + 1, device=device)
    dr, dc = torch.meshgrid(r, r, indexing="ij")
    return torch.stack([dr.reshape(-1), dc.reshape(-1)], dim=-1)


def vote(grid: BevGrid, offsets: torch.Tensor, yaw_logits: torch.Tensor, points: torch.Tensor,
         mask: torch.Tensor | None, cells: torch.Tensor, frame_index: torch.Tensor, window: int,
         loss_fn: Callable[[torch.Tensor], torch.Tensor], template: Template,
         yaw_mode: str = "predicted") -> VoteResult:
    """Pick, for each of N objects, the lowest-loss cell among the (2w+1)^2 around `cells` (N, 2).

    offsets (B, 3, H, W), yaw_logits (B, K, H, W): predictions of B frames; frame_index (N,) long says
    which frame each object belongs to; points (N, P, 3) its padded L_m with mask (N, P) (None = all real);
    loss_fn maps distances (..., P) to per-point losses (e.g. SIC). yaw_mode "predicted" evaluates each
    cell's box at its arg-max yaw bin (the predicted box); "best" at the bin that minimises the loss at
    that cell's centre (the regression part of ch. 7 eq. 9). Runs without gradients; ties go to the first
    cell in row-major order. Objects whose `cells` row is -1 get cell -1 and loss +inf.
    """
    if yaw_mode not in ("predicted", "best"):
        raise ValueError(f"yaw_mode must be 'predicted' or 'best', got {yaw_mode!r}")
    with torch.no_grad():
        n = points.shape[0]
        n_bins = yaw_logits.shape[1]
        win = window_offsets(window, device=points.device)                       # (C, 2)
        cand = cells[:, None, :] + win[None]                                      # (N, C, 2)
        rows, cols = cand[..., 0], cand[..., 1]
        inside = (rows >= 0) & (rows < grid.height) & (cols >= 0) & (cols < grid.width) \
            & (cells[:, None, 0] >= 0)
        r = rows.clamp(0, grid.height - 1)
        c = cols.clamp(0, grid.width - 1)
        f = frame_index[:, None].expand_as(r)
        off = offsets.permute(0, 2, 3, 1)[f, r, c]                                # (N, C, 3)
        centre = grid.decode(r, c, off.to(points.dtype))
        bins = yaw_bin_centers(n_bins, dtype=points.dtype, device=points.device)
        m = None if mask is None else mask[:, None, :]
        if yaw_mode == "predicted":
            yaw = bins[yaw_logits.permute(0, 2, 3, 1)[f, r, c].argmax(dim=-1)]   # (N, C)
            d = distance_to_template(template, points[:, None], centre, yaw)     # (N, C, P)
            loss = masked_mean(loss_fn(d), m)
        else:
            d = distance_to_template(template, points[:, None, None], centre[:, :, None],
                                     bins.expand(n, cand.shape[1], n_bins))      # (N, C, K, P)
            per_bin = masked_mean(loss_fn(d), None if m is None else m[:, :, None])
            loss, best = per_bin.min(dim=-1)
            yaw = bins[best]
        loss = torch.where(inside, loss, torch.full_like(loss, float("inf")))
        k = loss.argmin(dim=1)
        idx = torch.arange(n, device=points.device)
        found = torch.isfinite(loss[idx, k])
        cell = torch.where(found[:, None], cand[idx, k], torch.full_like(cand[idx, k], -1))
        return VoteResult(cell, centre[idx, k], yaw[idx, k], loss[idx, k], cand, loss)

