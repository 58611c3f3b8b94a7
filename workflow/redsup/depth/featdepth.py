"""Feature Depth (FeatDepth; Shu et al., ECCV 2020; Galteland §2.5 / §3.4): the feature-metric loss.

- ``FeatureNet``: an auto-encoder on single images, the project's ResNet encoder (``networks.ResNetEncoder``)
  and a decoder of five "upconv" layers (3x3 conv + ELU, bilinear upsampling; no skip connections, so the
  image must pass through the code) ending in a sigmoid RGB image. The features phi used by the loss are the
  encoder's first (stride 2) feature map.
- Per-pixel losses (pure; no reduction inside, weights are arguments):
  ``reconstruction_error`` |I - I_rec|_1 (eq. 3.17);
  ``discriminative_map`` -e^{-|d I|} |d phi| for d = d_x, d_y (eq. 3.18: large first-order feature gradients,
  weighted towards low-texture image regions);
  ``convergent_map`` |d_xx phi| + 2 |d_xy phi| + |d_yy phi| (eq. 3.19: small second-order gradients);
  ``feature_metric_error`` |phi_s(p^) - phi_t(p)|_1 (eq. 3.21) of a warped source feature map.
  Gradients are forward differences, averaged over channels.
- ``featurenet_loss`` L_s = L_rec + alpha L_dis + beta L_cvt (eq. 3.20; alpha = beta = 1e-3).
- ``FeatDepthLoss``: the training criterion (a component of ``training.train``): L_s on the target image plus
  Monodepth2's photometric loss (``pipeline``, auto-masking, minimum over sources) plus ``feature_weight`` x the
  feature-metric loss (minimum over sources). FeatureNet, depth and pose networks train
  together (Galteland §4.2.2.1); the features enter the feature-metric loss detached, so the depth and pose
  losses cannot flatten them (the FeatureNet learns from L_s only). The feature-metric term uses the scale-0 depth
  resized to the feature resolution, and its minimum over sources is taken apart from the photometric one.
- Single-frame inference: ``pipeline.predict_depth`` on the depth networks.
"""
from __future__ import annotations

from collections.abc import Mapping

import torch
import torch.nn.functional as F
from torch import nn

from redsup.depth import losses, manydepth, networks, pipeline, warping


# ------------------------------------------------------------------------------------------ per-pixel losses
def _dx(x: torch.Tensor) -> torch.Tensor:
    return x[..., :, 1:] - x[..., :, :-1]


def _dy(x: torch.Tensor) -> torch.Tensor:
    return x[..., 1:, :] - x[..., :-1, :]


def reconstruction_error(image: torch.Tensor, reconstruction: torch.Tensor) -> torch.Tensor:
    """|I - I_rec| averaged over channels, (B, 1, H, W)."""
    return (image - reconstruction).abs().mean(1, keepdim=True)


def discriminative_map(features: torch.Tensor, image: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(x term (B, 1, h, w-1), y term (B, 1, h-1, w)) of -e^{-|d I|} |d phi|; ``image`` is resized to the
    features' size (area) first."""
    if tuple(image.shape[-2:]) != tuple(features.shape[-2:]):
        image = F.interpolate(image, size=tuple(features.shape[-2:]), mode="area")
    gx = _dx(features).abs().mean(1, keepdim=True)
    gy = _dy(features).abs().mean(1, keepdim=True)
    wx = torch.exp(-_dx(image).abs().mean(1, keepdim=True))
    wy = torch.exp(-_dy(image).abs().mean(1, keepdim=True))
    return -wx * gx, -wy * gy


def convergent_map(features: torch.Tensor) -> torch.Tensor:
    """|d_xx phi| + 2 |d_xy phi| + |d_yy phi| on the common (h-2, w-2) grid, (B, 1, h-2, w-2)."""
    dxx = _dx(_dx(features)).abs().mean(1, keepdim=True)[..., 1:-1, :]
    dyy = _dy(_dy(features)).abs().mean(1, keepdim=True)[..., :, 1:-1]
    dxy = _dy(_dx(features)).abs().mean(1, keepdim=True)[..., :-1, :-1]
    return dxx + 2.0 * dxy + dyy


def feature_metric_error(warped_features: torch.Tensor, target_features: torch.Tensor) -> torch.Tensor:
    """|phi_s(p^) - phi_t(p)| averaged over channels, (B, 1, h, w)."""
    return (warped_features - target_features).abs().mean(1, keepdim=True)


# ------------------------------------------------------------------------------------------------ FeatureNet
class FeatureDecoder(nn.Module):
    """Five upconv layers (3x3 conv + ELU, bilinear x2 to the next size) from the stride-32 code to an RGB image."""

    def __init__(self, num_ch_enc: tuple[int, ...], channels: tuple[int, ...] | None = None):
        super().__init__()
        channels = tuple(channels) if channels is not None else networks.decoder_channels(num_ch_enc[0])[::-1]
        ins = (num_ch_enc[-1],) + channels[:-1]
        self.upconv = nn.ModuleList([networks.ConvBlock(i, o) for i, o in zip(ins, channels)])
        self.out = nn.Conv2d(channels[-1], 3, 3)

    def forward(self, code: torch.Tensor, output_size: tuple[int, int]) -> torch.Tensor:
        x = code
        n = len(self.upconv)
        for k, conv in enumerate(self.upconv):
            x = conv(x)
            scale = 2 ** (n - 1 - k)  # sizes of the encoder pyramid: ceil(H / 2^s), the last one the image's
            size = output_size if scale == 1 else (-(-output_size[0] // scale), -(-output_size[1] // scale))
            x = F.interpolate(x, size=size, mode="bilinear", align_corners=False)
        return torch.sigmoid(self.out(networks.pad1(x)))


def build_models(base_channels: int = 64, num_scales: int = 4, init_disparity: float | None = None,
                 feature_channels: int | None = None) -> nn.ModuleDict:
    """Monodepth2's depth and pose networks plus the FeatureNet auto-encoder (``feature_channels`` = its
    encoder width; default ``base_channels``)."""
    models = networks.build_models(base_channels, num_scales, init_disparity)
    enc = networks.ResNetEncoder(3, feature_channels or base_channels)
    models["feature_encoder"] = enc
    models["feature_decoder"] = FeatureDecoder(enc.num_ch_enc)
    return models


def features(models: Mapping[str, nn.Module], image: torch.Tensor) -> torch.Tensor:
    """phi: the FeatureNet encoder's stride-2 feature map (B, C, ceil(H/2), ceil(W/2))."""
    return models["feature_encoder"](image)[0]


def featurenet_loss(models: Mapping[str, nn.Module], image: torch.Tensor, alpha: float = 1e-3, beta: float = 1e-3
                    ) -> dict[str, torch.Tensor]:
    """L_s = mean L_rec + alpha mean L_dis + beta mean L_cvt on single images (B, 3, H, W)."""
    feats = models["feature_encoder"](image)
    rec = models["feature_decoder"](feats[-1], output_size=tuple(image.shape[-2:]))
    l_rec = reconstruction_error(image, rec).mean()
    dx, dy = discriminative_map(feats[0], image)
    l_dis = dx.mean() + dy.mean()
    l_cvt = convergent_map(feats[0]).mean()
    return {"featurenet_loss": l_rec + alpha * l_dis + beta * l_cvt, "reconstruction": l_rec,
            "discriminative": l_dis, "convergent": l_cvt}


def feature_metric_loss(target_feat: torch.Tensor, source_feats: Mapping[str, torch.Tensor], depth: torch.Tensor,
                        K: torch.Tensor, transforms: Mapping[str, torch.Tensor], image_size: tuple[int, int],
                        weight: torch.Tensor | None = None) -> torch.Tensor:
    """mean over pixels of weight x min over sources of |phi_s(p^) - phi_t(p)|, at the feature resolution:
    ``depth`` (B, 1, H, W) is resized there and K rescaled (pixel centres); ``weight`` (B, 1, H, W) too."""
    size = tuple(target_feat.shape[-2:])
    d = F.interpolate(depth, size=size, mode="bilinear", align_corners=False)
    Kf = manydepth.scale_intrinsics(K, image_size, size)
    errs = [feature_metric_error(warping.warp(source_feats[n], d, Kf, transforms[n]), target_feat)
            for n in source_feats]
    err = losses.min_reprojection(errs)
    if weight is not None:
        err = err * F.interpolate(weight.to(err.dtype), size=size, mode="nearest")
    return err.mean()


class FeatDepthLoss:
    """The Feature Depth criterion ``(models, batch, step) -> loss dict`` for ``training.train``.

    ``dis_weight`` / ``cvt_weight``: the thesis' alpha / beta (eq. 3.20; ``alpha`` of ``loss_kwargs`` is the
    SSIM weight of the photometric error). ``loss_kwargs`` go to ``losses.self_supervised_loss``, with auto-masking
    off up to step ``automask_after`` (as the M mode's); temporal sources only (the feature-metric term warps
    the FeatureNet features of every source)."""

    def __init__(self, *, min_depth: float = 0.1, max_depth: float = 100.0, dis_weight: float = 1e-3,
                 cvt_weight: float = 1e-3, feature_weight: float = 1.0, automask_after: int = 0, **loss_kwargs):
        self.min_depth, self.max_depth = float(min_depth), float(max_depth)
        self.dis_weight, self.cvt_weight, self.feature_weight = float(dis_weight), float(cvt_weight), float(feature_weight)
        self.automask_after = int(automask_after)
        self.loss_kwargs = loss_kwargs

    def __call__(self, models: Mapping[str, nn.Module], batch: Mapping, step: int = 1) -> dict[str, torch.Tensor]:
        target = batch["target"]
        fnet = featurenet_loss(models, target, self.dis_weight, self.cvt_weight)
        disps = pipeline.predict_disparities(models, target)
        transforms = pipeline.source_transforms(models, batch)
        photo = pipeline.loss_from_outputs(batch, disps, transforms, min_depth=self.min_depth,
                                           max_depth=self.max_depth,
                                           **losses.masking_at(self.loss_kwargs, step, self.automask_after))
        names = list(batch["sources"])
        with torch.no_grad():
            phi = features(models, torch.cat([target] + [batch["sources"][n] for n in names]))
        phi_t, phi_s = phi[:target.shape[0]], dict(zip(names, phi[target.shape[0]:].chunk(len(names))))
        depth = networks.disp_to_depth(disps[0], self.min_depth, self.max_depth)[1]
        fm = feature_metric_loss(phi_t, phi_s, depth, batch["K"], transforms, tuple(target.shape[-2:]))
        loss = fnet["featurenet_loss"] + photo["loss"] + self.feature_weight * fm
        return {"loss": loss, "depth_loss": photo["loss"], "photometric": photo["photometric"],
                "feature_metric": fm, "automask_fraction": photo["automask_fraction"], **fnet}
