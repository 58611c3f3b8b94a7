"""Per-point alignment losses of McCraith ch. 6 / ch. 7, multi-frame consistency and the best-yaw search.

All functions are pure torch (differentiable) and unreduced: per point, per keypoint or per bin. Means over
L_m, masks for padded point sets, weights and the cross-entropy are the caller's.

`d` is always the distance from a LiDAR point to the nearest point of the posed template
(`template.distance_to_template`), i.e. ||p - p'|| with p' = argmin over the template of ||p - p'||.

Yaw bins: bin k of K stands for yaw -pi + 2 pi k / K (k = 0..K-1), covering [-pi, pi); yaw 0 is bin K/2
for even K, and quarter turns are bins when 4 divides K.
"""
from __future__ import annotations

import math
from typing import Callable

import torch

from redsup.det3d.template import Template, distance_to_template


def squared_distance(d: torch.Tensor) -> torch.Tensor:
    """||p - p'||^2 per point: the one-sided Chamfer term of ch. 6 eq. (1) / ch. 7 eq. (4) (the L2 row)."""
    return d * d


def soft_inlier_count(d: torch.Tensor, alpha: float, beta: float) -> torch.Tensor:
    """Soft Inlier Count per point, ch. 7 eq. (6)-(7): -sigmoid(beta - alpha ||p - p'||^2).

    Reading of the printed eq. (7): it is written -1 / (1 + exp(-alpha ||p-p'||^2 + beta)) =
    -sigmoid(alpha ||p-p'||^2 - beta), which is lowest for points *far* from the template, so minimising
    it would push the template away from the points. The text ("we maximize the number of points
    sufficiently close to the template") and Fig. 3 need the opposite sign inside the exponential:
    -1 / (1 + exp(alpha ||p-p'||^2 - beta)) = -sigmoid(beta - alpha ||p-p'||^2). A point on the surface
    then scores -sigmoid(beta) (the minimum), a far point tends to 0, so the loss is minus a soft count of
    inliers whose "radius" is set by alpha (sharpness) and beta (offset). Eq. (6) sums SIC over all template
    points p'; as in eq. (4) and the issue, we use the nearest template point p' only.
    """
    return -torch.sigmoid(beta - alpha * d * d)


def outlier_aware(d: torch.Tensor, log_var: torch.Tensor) -> torch.Tensor:
    """Ch. 6 eq. (3) per point: ||X' - X||^2 / sigma^2(X) + log sigma^2(X), with log_var = log sigma^2.

    The network predicts log sigma^2 per point (numerically stable; sigma^2 = exp(log_var)). For a fixed
    fitting error the minimum over sigma is at sigma^2 = d^2 (as the thesis notes), so likely outliers are
    discounted by a large predicted variance. log_var broadcasts against d (e.g. (B, 1, P) vs (B, K, P)).
    """
    return d * d * torch.exp(-log_var) + log_var


def masked_mean(per_point: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
    """Mean over the last (point) axis of the entries where mask (broadcastable) is True; 0 where a set
    has no real point. Masked-out entries never change the value; pad with finite values (as
    `pointsets.pad_point_sets` does) to keep gradients finite too."""
    if mask is None:
        return per_point.mean(dim=-1)
    mask = mask.expand_as(per_point)
    total = torch.where(mask, per_point, torch.zeros((), dtype=per_point.dtype, device=per_point.device))
    return total.sum(dim=-1) / mask.sum(dim=-1).clamp_min(1).to(per_point.dtype)


def yaw_bin_centers(n_bins: int, dtype=torch.float32, device=None) -> torch.Tensor:
    """(K,) yaw of each bin: -pi + 2 pi k / K."""
    return -math.pi + 2 * math.pi * torch.arange(n_bins, dtype=dtype, device=device) / n_bins


def yaw_to_bin(yaw: torch.Tensor, n_bins: int) -> torch.Tensor:
    """Nearest bin index (long) of yaw angles (any range)."""
    wrapped = torch.remainder(yaw + math.pi, 2 * math.pi)
    return torch.remainder(torch.round(wrapped * n_bins / (2 * math.pi)), n_bins).long()


def best_yaw_bin(points: torch.Tensor, translation: torch.Tensor, n_bins: int,
                 loss_fn: Callable[[torch.Tensor], torch.Tensor], template: Template,
                 mask: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """Direct optimisation over yaw (ch. 6 eq. 4-6, ch. 7 eq. 8-9): evaluate every bin at the given
    translation and return (best bin (B,) long, per-bin mean loss (B, K)).

    points (B, P, 3) padded L_m sets in the frame of `translation` (B, 3); mask (B, P) bool marks real
    points (None = all). loss_fn maps distances (B, K, P) to per-point losses of the same shape, e.g.
    ``lambda d: soft_inlier_count(d, 5.0, 0.0)`` or ``lambda d: outlier_aware(d, log_var[:, None])``.
    Padded entries may hold anything (NaN included: no gradients here). The search runs without gradients (the arg-min is
    a classification target); train the translation through the loss re-evaluated at the best bin's yaw
    (`masked_mean(loss_fn(distance_to_template(...)), mask)` with `yaw_bin_centers(K)[best]`).
    Objects without points get loss 0 in every bin and bin 0: skip them before calling (see
    `pointsets.pad_point_sets`). Ties go to the lowest bin index. Memory: a few (B, K, P) temporaries
    (64 x 64 x 256 float32 = 4 MB each); split very large batches in the caller.
    """
    with torch.no_grad():
        yaws = yaw_bin_centers(n_bins, dtype=points.dtype, device=points.device)
        d = distance_to_template(template, points[:, None], translation[:, None],
                                 yaws[None, :].expand(points.shape[0], n_bins))      # (B, K, P)
        per_bin = masked_mean(loss_fn(d), None if mask is None else mask[:, None, :])
        return per_bin.argmin(dim=1), per_bin


def posed_keypoints(translation: torch.Tensor, yaw: torch.Tensor, keypoints: torch.Tensor) -> torch.Tensor:
    """g X_0 for template keypoints (Q, 3) and poses (translation (..., 3), yaw (...)): (..., Q, 3)."""
    c, s = torch.cos(yaw)[..., None], torch.sin(yaw)[..., None]
    kx, ky, kz = keypoints[:, 0], keypoints[:, 1], keypoints[:, 2]
    x = c * kx - s * ky + translation[..., 0:1]
    y = s * kx + c * ky + translation[..., 1:2]
    z = (kz + translation[..., 2:3]).expand_as(x)
    return torch.stack([x, y, z], dim=-1)


def centre_front_keypoints(length: float, dtype=torch.float32, device=None) -> torch.Tensor:
    """(2, 3) template keypoints of ch. 6 eq. (8): the car centre and the centre of its front face."""
    return torch.tensor([[0.0, 0.0, 0.0], [length / 2, 0.0, 0.0]], dtype=dtype, device=device)


def multiframe_consistency(translation_i: torch.Tensor, yaw_i: torch.Tensor, translation_j: torch.Tensor,
                           yaw_j: torch.Tensor, T_i_from_j: torch.Tensor, keypoints: torch.Tensor) -> torch.Tensor:
    """Ch. 6 eq. (7) per keypoint: ||g_{i<-j} X_0^j - X_0^i||^2 for each pair of frames (..., Q).

    Poses of the same (static) object predicted in frames i and j, each in its own vehicle frame;
    T_i_from_j (..., 4, 4) is the known ego-motion mapping frame-j vehicle coordinates to frame i
    (inv(T_world_vehicle_i) @ T_world_vehicle_j). Sum over j = i+1..i+K and over the centre and front
    keypoints (eq. 8) is the caller's.
    """
    xi = posed_keypoints(translation_i, yaw_i, keypoints)                    # (..., Q, 3)
    xj = posed_keypoints(translation_j, yaw_j, keypoints)
    R = T_i_from_j[..., :3, :3]
    t = T_i_from_j[..., :3, 3]
    xj_in_i = xj @ R.transpose(-1, -2) + t[..., None, :]
    return ((xj_in_i - xi) ** 2).sum(dim=-1)
