"""View synthesis by back-projection, rigid transform, projection and bilinear sampling (pure torch).

Conventions (README, "The canonical raw-scene format"): OpenCV cameras (x right, y down, z forward), pixel (0, 0) is the centre of
the top-left pixel, so pixel u lies at normalised coordinate (2u + 1) / W - 1 for ``grid_sample`` with
``align_corners=False``. ``T`` (B, 4, 4) maps points of the target camera into the source camera
(Monodepth2's ``cam_T_cam``). ``K`` is per sample, (B, 3, 3) or (B, 4, 4) (only its 3x3 block is used,
cast to the depth's dtype).
"""
from __future__ import annotations

import torch
import torch.nn.functional as F


def _k3(K: torch.Tensor) -> torch.Tensor:
    if K.dim() != 3 or K.shape[-2:] not in ((3, 3), (4, 4)):
        raise ValueError(f"intrinsics must be (B, 3, 3) or (B, 4, 4), got {tuple(K.shape)}")
    return K[:, :3, :3]


def pixel_grid(height: int, width: int, like: torch.Tensor) -> torch.Tensor:
    """(3, H*W) homogeneous pixel coordinates (u, v, 1), row-major, on ``like``'s device and dtype."""
    v, u = torch.meshgrid(torch.arange(height, device=like.device, dtype=like.dtype),
                          torch.arange(width, device=like.device, dtype=like.dtype), indexing="ij")
    return torch.stack([u.reshape(-1), v.reshape(-1), torch.ones_like(u).reshape(-1)])


def backproject(depth: torch.Tensor, inv_K: torch.Tensor) -> torch.Tensor:
    """Depth (B, 1, H, W) and K^-1 (B, 3, 3)/(B, 4, 4) to camera-frame points (B, 3, H*W): X = d K^-1 [u, v, 1]."""
    b, _, h, w = depth.shape
    rays = _k3(inv_K).to(depth.dtype) @ pixel_grid(h, w, depth)  # (B, 3, N)
    return rays * depth.reshape(b, 1, h * w)


def project(points: torch.Tensor, K: torch.Tensor, T: torch.Tensor | None = None, eps: float = 1e-7
            ) -> tuple[torch.Tensor, torch.Tensor]:
    """Points (B, 3, N) -> pixel coordinates (B, 2, N) and depth z (B, 1, N) in the camera ``T`` maps to.

    z is clamped to ``eps`` in the division (points behind the camera land far away, as in Monodepth2).
    """
    if T is not None:
        points = T[:, :3, :3] @ points + T[:, :3, 3:4]
    cam = _k3(K).to(points.dtype) @ points
    z = cam[:, 2:3]
    return cam[:, :2] / (z + eps), z


def pixels_to_grid(pixels: torch.Tensor, height: int, width: int) -> torch.Tensor:
    """Pixel coordinates (B, 2, H*W) to a ``grid_sample`` grid (B, H, W, 2), pixel-centre convention."""
    b = pixels.shape[0]
    x = (2.0 * pixels[:, 0] + 1.0) / width - 1.0
    y = (2.0 * pixels[:, 1] + 1.0) / height - 1.0
    return torch.stack([x, y], dim=-1).reshape(b, height, width, 2)


def sampling_grid(depth: torch.Tensor, K: torch.Tensor, T: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Grid (B, H, W, 2) sampling the source view for every target pixel, and a (B, 1, H, W) validity mask
    (point in front of the source camera and projecting inside the source image)."""
    _, _, h, w = depth.shape
    K3 = _k3(K).to(depth.dtype)
    pix, z = project(backproject(depth, torch.linalg.inv(K3)), K3, T)
    grid = pixels_to_grid(pix, h, w)
    inside = (grid.abs() <= 1.0).all(dim=-1) & (z.reshape(-1, h, w) > 0)
    return grid, inside.unsqueeze(1)


def warp(image: torch.Tensor, depth: torch.Tensor, K: torch.Tensor, T: torch.Tensor) -> torch.Tensor:
    """Synthesise the target view from source ``image`` (B, C, H, W), target ``depth`` (B, 1, H, W), ``T``
    target->source. Bilinear sampling, border padding.

    The grid is clamped to [-2, 2] (NaN -> 2) before sampling. With border padding this changes neither the
    samples nor their gradients (both are clipped to the border beyond +-1), but it keeps huge coordinates
    away from torch 2.13's CPU grid-sampler backward, which crashes (SIGSEGV) on them after a diverging step."""
    grid, _ = sampling_grid(depth, K, T)
    grid = torch.nan_to_num(grid, nan=2.0).clamp(-2.0, 2.0)
    return F.grid_sample(image, grid, mode="bilinear", padding_mode="border", align_corners=False)


def rot_from_axisangle(axisangle: torch.Tensor) -> torch.Tensor:
    """Rodrigues: axis-angle (B, 3) to rotation (B, 3, 3); the angle is the vector's norm."""
    angle = torch.sqrt((axisangle ** 2).sum(-1, keepdim=True).clamp_min(1e-14))  # (B, 1), smooth at 0
    axis = axisangle / angle
    zero = torch.zeros_like(angle[:, 0])
    x, y, z = axis[:, 0], axis[:, 1], axis[:, 2]
    skew = torch.stack([zero, -z, y, z, zero, -x, -y, x, zero], dim=-1).reshape(-1, 3, 3)
    eye = torch.eye(3, device=axisangle.device, dtype=axisangle.dtype).expand_as(skew)
    s, c = torch.sin(angle)[..., None], torch.cos(angle)[..., None]
    return eye + s * skew + (1.0 - c) * (skew @ skew)


def transformation_from_parameters(axisangle: torch.Tensor, translation: torch.Tensor, invert: bool = False
                                   ) -> torch.Tensor:
    """[R | t] (B, 4, 4) from axis-angle (B, 3) and translation (B, 3); ``invert`` gives [R^T | -R^T t]."""
    R = rot_from_axisangle(axisangle)
    t = translation.reshape(-1, 3, 1)
    if invert:
        R = R.transpose(1, 2)
        t = -R @ t
    bottom = torch.zeros_like(R[:, :1, :])
    top = torch.cat([R, t], dim=2)
    out = torch.cat([top, torch.cat([bottom, torch.ones_like(bottom[:, :, :1])], dim=2)], dim=1)
    return out


def translation_transform(translation: torch.Tensor) -> torch.Tensor:
    """Pure translation (B, 4, 4) from (B, 3); e.g. a rectified stereo pair whose source camera centre is at
    x = +b in the target frame has translation (-b, 0, 0)."""
    zeros = torch.zeros_like(translation)
    return transformation_from_parameters(zeros, translation)
