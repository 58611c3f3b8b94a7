"""Self-supervised depth losses (Monodepth2, Godard et al. 2019; McCraith ch. 4 eq. 1, 4-6).

Every function except ``self_supervised_loss`` is per pixel: no reduction inside, weights are arguments.
Shapes: images (B, C, H, W); error maps (B, 1, H, W); stacks of error maps over source frames (B, S, H, W).
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import torch
import torch.nn.functional as F

C1 = 0.01 ** 2
C2 = 0.03 ** 2


def _pool3(x: torch.Tensor) -> torch.Tensor:
    """3x3 mean with reflection padding, as a separable box filter (same values as ``avg_pool2d(3, 1)``,
    about 3x faster on CPU)."""
    p = F.pad(x, (1, 1, 1, 1), mode="reflect")
    r = p[..., :-2] + p[..., 1:-1] + p[..., 2:]
    return (r[..., :-2, :] + r[..., 1:-1, :] + r[..., 2:, :]) / 9.0


def ssim_stats(y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """3x3 local mean and variance of ``y`` (reusable when one target meets many predictions)."""
    mu_y = _pool3(y)
    return mu_y, _pool3(y * y) - mu_y ** 2


def ssim(x: torch.Tensor, y: torch.Tensor, c1: float = C1, c2: float = C2,
         y_stats: tuple[torch.Tensor, torch.Tensor] | None = None) -> torch.Tensor:
    """Per-pixel, per-channel SSIM (B, C, H, W) over 3x3 windows, reflection padded (Monodepth2's SSIM).
    ``y_stats`` = ``ssim_stats(y)`` when already computed."""
    mu_x = _pool3(x)
    mu_y, sigma_y = y_stats if y_stats is not None else ssim_stats(y)
    sigma_x = _pool3(x * x) - mu_x ** 2
    sigma_xy = _pool3(x * y) - mu_x * mu_y
    num = (2 * mu_x * mu_y + c1) * (2 * sigma_xy + c2)
    den = (mu_x ** 2 + mu_y ** 2 + c1) * (sigma_x + sigma_y + c2)
    return num / den


def photometric_error(pred: torch.Tensor, target: torch.Tensor, alpha: float = 0.85,
                      target_stats: tuple[torch.Tensor, torch.Tensor] | None = None) -> torch.Tensor:
    """P = alpha (1 - SSIM) / 2 + (1 - alpha) |pred - target|, averaged over channels: (B, 1, H, W).
    ``target_stats`` = ``ssim_stats(target)`` when already computed."""
    l1 = (pred - target).abs().mean(1, keepdim=True)
    dssim = ((1.0 - ssim(pred, target, y_stats=target_stats)) / 2.0).clamp(0.0, 1.0).mean(1, keepdim=True)
    return alpha * dssim + (1.0 - alpha) * l1


def _stack(errors: torch.Tensor | Sequence[torch.Tensor]) -> torch.Tensor:
    return errors if isinstance(errors, torch.Tensor) else torch.cat(list(errors), dim=1)


def min_reprojection(errors: torch.Tensor | Sequence[torch.Tensor]) -> torch.Tensor:
    """Per-pixel minimum over source frames: (B, S, H, W) or a list of (B, 1, H, W) -> (B, 1, H, W)."""
    return _stack(errors).min(dim=1, keepdim=True).values


def automask(reproj_errors: torch.Tensor | Sequence[torch.Tensor],
             identity_errors: torch.Tensor | Sequence[torch.Tensor],
             noise_std: float = 0.0, generator: torch.Generator | Callable | None = None) -> torch.Tensor:
    """Monodepth2 auto-mask (B, 1, H, W), bool: True where the minimum reprojection error is below the minimum
    identity error (the un-warped source), i.e. where the pixel moves relative to the camera.

    ``noise_std`` > 0 adds Gaussian noise to the identity errors to break ties (Monodepth2 uses 1e-5);
    pass a ``generator`` for reproducible noise (otherwise torch's global RNG is used), or a callable
    ``(shape, dtype, device) -> standard normal tensor`` (``adaptation.adapt_batched``: each sample's draws from
    its own generator under ``torch.func.vmap``).
    """
    reproj = min_reprojection(reproj_errors)
    identity = _stack(identity_errors)
    if noise_std > 0:
        if callable(generator):
            noise = generator(identity.shape, identity.dtype, identity.device)
        else:
            noise = torch.randn(identity.shape, generator=generator, device=identity.device, dtype=identity.dtype)
        identity = identity + noise_std * noise
    return reproj < identity.min(dim=1, keepdim=True).values


def masking_at(loss_kwargs: Mapping, step: int, automask_after: int) -> dict:
    """The loss settings of training step ``step`` (from 1) when auto-masking starts after step ``automask_after``:
    ``loss_kwargs`` from step ``automask_after + 1`` on, before that the same with ``automasking`` off (every pixel
    in the loss, as while a from-scratch network cannot yet tell a moving pixel from a static one)."""
    return dict(loss_kwargs) if step > automask_after else {**loss_kwargs, "automasking": False}


def edge_aware_smoothness(disp: torch.Tensor, image: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """|d_x d*| e^{-|d_x I|} and |d_y d*| e^{-|d_y I|} on mean-normalised disparity d* = d / mean(d).

    Returns the x term (B, 1, H, W-1) and the y term (B, 1, H-1, W); ``image`` must match ``disp``'s size.
    """
    norm = disp / (disp.mean(dim=(2, 3), keepdim=True) + 1e-7)
    gdx = (norm[:, :, :, :-1] - norm[:, :, :, 1:]).abs()
    gdy = (norm[:, :, :-1, :] - norm[:, :, 1:, :]).abs()
    gix = (image[:, :, :, :-1] - image[:, :, :, 1:]).abs().mean(1, keepdim=True)
    giy = (image[:, :, :-1, :] - image[:, :, 1:, :]).abs().mean(1, keepdim=True)
    return gdx * torch.exp(-gix), gdy * torch.exp(-giy)


def self_supervised_loss(target: torch.Tensor, warped: torch.Tensor | Sequence[Sequence[torch.Tensor]],
                         identity: torch.Tensor | Sequence[torch.Tensor], disps: Sequence[torch.Tensor], *,
                         smoothness_weight: float = 1e-3, alpha: float = 0.85, automasking: bool = True,
                         noise_std: float = 1e-5, generator: torch.Generator | Callable | None = None,
                         pixel_weight: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
    """Monodepth2's multi-scale loss for one target frame (B, 3, H, W).

    ``warped[s][k]``: source k warped with the scale-s disparity upsampled to input resolution (B, 3, H, W),
    as nested lists or one tensor (S, K, B, 3, H, W); ``identity[k]``: the un-warped source k (list or
    (K, B, 3, H, W)); ``disps[s]``: the network disparity at scale s (any resolution; the smoothness term compares
    it with the target resized to that resolution, weighted by 1 / 2^s). Photometric term per scale =
    mean(mu * min_k P(target, warped_k)) (ch. 4 eq. 4; mu = 1 without auto-masking). All scales and sources go
    through one photometric-error call. ``pixel_weight`` (B, 1, H, W), optional, multiplies the photometric mask
    (Manydepth: 0 where the cost volume is unreliable). Returns scalars: ``loss`` (mean over scales of photometric +
    w * smoothness / 2^s), ``photometric``, ``smoothness`` (means over scales, unweighted), ``automask_fraction``.
    """
    warped_t = warped if isinstance(warped, torch.Tensor) else torch.stack([torch.stack(list(w)) for w in warped])
    identity_t = identity if isinstance(identity, torch.Tensor) else torch.stack(list(identity))
    n_scales, n_src, b, c, h, w = warped_t.shape
    if n_scales != len(disps):
        raise ValueError(f"{n_scales} scales of warped images but {len(disps)} disparities")

    # One photometric-error call per (scale, source): the chunks stay in the CPU caches (one call on the whole
    # (S*N*B, 3, H, W) stack is several times slower on CPU for the same arithmetic).
    # unbind, not indexing: the backward of warped_t[s, k] fills a zero tensor of the whole stack per chunk
    # (S * N full-size fills and adds per step); unbind's backward is one stack (5 % less CPU per default-profile
    # step, benchmarks/ab_depth_step.py).
    stats = ssim_stats(target)
    chunks = [scale.unbind(0) for scale in warped_t.unbind(0)]
    reproj = torch.stack([torch.cat([photometric_error(chunks[s][k], target, alpha, stats) for k in range(n_src)], 1)
                          for s in range(n_scales)])  # (S, B, N, H, W)
    min_err = min_reprojection(reproj.reshape(n_scales * b, n_src, h, w))  # (S*B, 1, H, W)
    if automasking:
        with torch.no_grad():  # the sources are inputs: no gradient flows through the identity errors
            ident = torch.cat([photometric_error(identity_t[k], target, alpha, stats) for k in range(n_src)], 1)
        ident = ident.repeat(n_scales, 1, 1, 1)  # (S*B, N, H, W)
        mask = automask(min_err, ident, noise_std, generator).to(min_err.dtype)
    else:
        mask = torch.ones_like(min_err)
    if pixel_weight is not None:
        mask = mask * pixel_weight.to(mask.dtype).repeat(n_scales, 1, 1, 1)
    photo = (mask * min_err).reshape(n_scales, -1).mean(1)
    total, smooth_sum = 0.0, 0.0
    for s, disp in enumerate(disps):
        image_s = target if target.shape[-2:] == disp.shape[-2:] else F.interpolate(
            target, size=disp.shape[-2:], mode="area")
        sx, sy = edge_aware_smoothness(disp, image_s)
        smooth = sx.mean() + sy.mean()
        total = total + photo[s] + smoothness_weight * smooth / (2 ** s)
        smooth_sum = smooth_sum + smooth
    return {"loss": total / n_scales, "photometric": photo.mean(), "smoothness": smooth_sum / n_scales,
            "automask_fraction": mask.mean()}
