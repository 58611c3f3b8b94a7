"""Losses of the detector, unreduced (per cell / per object); the training loop weights and averages.

- `focal_heatmap_loss`: CenterNet's penalty-reduced focal loss on the heatmap logits (alpha 2, beta 4),
  per cell; normalise by the number of objects (`num_pos`).
- `weak_alignment` (ch. 7 eq. 8-9): at each object's chosen cell the predicted centre T_m (cell corner +
  offset) poses the template; the best of the K yaw bins at T_m (no gradient) is the target of the yaw
  cross-entropy, and the alignment loss (SIC or L2, mean over L_m) at that yaw trains the offset.
- `supervised_terms`: the fully supervised reference: L1 offset to the gt centre, cross-entropy to the gt
  yaw bin, L1 on log(size / template size) when the model predicts size.
"""
from __future__ import annotations

from collections.abc import Callable

import torch
import torch.nn.functional as F

from redsup.det3d.losses import best_yaw_bin, masked_mean, soft_inlier_count, squared_distance, yaw_bin_centers
from redsup.det3d.template import Template, distance_to_template
from redsup.det3d.voting import BevGrid
from redsup.lidar_detector.targets import SupervisedTargets, WeakAssignment, WeakObjects


def alignment_loss(kind: str, alpha: float = 5.0, beta: float = 0.0) -> Callable[[torch.Tensor], torch.Tensor]:
    """Per-point loss of the distance d = ||p - p'|| to the posed template: "sic" (-sigmoid(beta - alpha
    d^2), `losses.soft_inlier_count`) or "l2" (d^2)."""
    if kind == "sic":
        return lambda d: soft_inlier_count(d, alpha, beta)
    if kind == "l2":
        return squared_distance
    raise ValueError(f"alignment loss must be 'sic' or 'l2', got {kind!r}")


def focal_heatmap_loss(logits: torch.Tensor, target: torch.Tensor, alpha: float = 2.0,
                       beta: float = 4.0) -> tuple[torch.Tensor, torch.Tensor]:
    """(per-cell loss like logits, number of positive cells (target == 1)). p is clamped to [1e-4, 1 - 1e-4]
    as in CenterPoint."""
    p = torch.sigmoid(logits).clamp(1e-4, 1 - 1e-4)
    pos = target.eq(1).to(logits.dtype)
    neg = 1 - pos
    pos_loss = -torch.log(p) * (1 - p) ** alpha * pos
    neg_loss = -torch.log(1 - p) * p ** alpha * (1 - target) ** beta * neg
    return pos_loss + neg_loss, pos.sum()


def _at_cells(maps: torch.Tensor, frame: torch.Tensor, cells: torch.Tensor) -> torch.Tensor:
    """(N, C) values of channel-first maps (B, C, H, W) at (frame, row, col). Indexed in place, not through a
    channel-last view: the gradient stays contiguous (a permuted one costs a full copy of every map per step in
    the backward, 9 % of a default training step with the 64-bin yaw map; the values and the maps' gradients are
    the same, but the convolution backward then rounds differently: trainings differ at float precision)."""
    return maps[frame, :, cells[:, 0], cells[:, 1]]


def weak_alignment(outputs: dict[str, torch.Tensor], grid: BevGrid, assign: WeakAssignment, objs: WeakObjects,
                   loss_fn: Callable[[torch.Tensor], torch.Tensor], template: Template) -> dict[str, torch.Tensor]:
    """Per valid object (assign.valid): `alignment` (mean per-point loss at the best yaw bin, differentiable
    w.r.t. the offset), `yaw_ce` (cross-entropy of the cell's yaw logits to the best bin), `best_bin`."""
    device = outputs["offset"].device
    sel = assign.valid.to(device)
    frame = objs.frame.to(device)[sel]
    cells = assign.cell.to(device)[sel]
    pts = objs.points.to(device)[sel]
    mask = objs.mask.to(device)[sel]
    n_bins = outputs["yaw"].shape[1]
    if len(frame) == 0:
        zero = outputs["offset"].sum() * 0.0
        return {"alignment": zero[None][:0], "yaw_ce": zero[None][:0], "best_bin": torch.zeros(0, dtype=torch.long)}
    off = _at_cells(outputs["offset"], frame, cells)
    centre = grid.decode(cells[:, 0], cells[:, 1], off)
    best, _ = best_yaw_bin(pts, centre.detach(), n_bins, loss_fn, template, mask)
    yaw = yaw_bin_centers(n_bins, dtype=pts.dtype, device=device)[best]
    d = distance_to_template(template, pts, centre, yaw)                         # (n, P)
    alignment = masked_mean(loss_fn(d), mask)
    ce = F.cross_entropy(_at_cells(outputs["yaw"], frame, cells), best, reduction="none")
    return {"alignment": alignment, "yaw_ce": ce, "best_bin": best}


def supervised_terms(outputs: dict[str, torch.Tensor], targets: SupervisedTargets) -> dict[str, torch.Tensor]:
    """Per object: `offset_l1` (sum over x, y, z), `yaw_ce`, and `size_l1` when the model predicts size."""
    device = outputs["offset"].device
    frame, cells = targets.frame.to(device), targets.cell.to(device)
    off = _at_cells(outputs["offset"], frame, cells)
    out = {"offset_l1": (off - targets.offset.to(device)).abs().sum(dim=1),
           "yaw_ce": F.cross_entropy(_at_cells(outputs["yaw"], frame, cells), targets.yaw_bin.to(device),
                                     reduction="none")}
    if "size" in outputs:
        out["size_l1"] = (_at_cells(outputs["size"], frame, cells) - targets.log_size.to(device)).abs().sum(dim=1)
    return out
