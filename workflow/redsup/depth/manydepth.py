"""Manydepth (Watson et al., CVPR 2021; Galteland §2.4 / §3.3): multi-frame depth from a cost volume.

Pieces (pure functions for the geometry and the masks, small modules whose shape follows the input):

- ``depth_bins``: bin depths spaced uniformly in inverse depth between ``d_min`` and ``d_max``
  (index 0 = the far end, as Manydepth).
- ``DepthRange``: ``d_min`` / ``d_max`` learned from the batch: running averages (momentum) of the batch-mean
  per-image minimum and maximum of the single-frame teacher's depth; frozen by not calling ``update``.
- ``cost_volume``: for every bin, the previous frame's features warped into the target view as if every pixel
  lay at that depth (one fronto-parallel plane per bin, ``warping.sampling_grid``), cost = mean absolute feature
  difference; bins that project outside the previous frame take the pixel's largest valid cost (they never win);
  pixels without any valid bin are flagged ``missing`` and their volume is zeroed.
- ``CostVolumeEncoder``: the ResNet-18 of ``networks`` split after layer1 (stride 4): target and previous frame
  share the stem, the cost volume is concatenated to the target's stride-4 features, reduced (3x3 conv + ReLU)
  and fed through layers 2-4. Its features go to the ordinary ``networks.DepthDecoder``.
- ``consistency_mask``: where the cost volume is unreliable: its best-bin depth and the teacher's depth differ by
  more than a factor 2 (Manydepth: (d_cv - d_t) / d_t >= 1 or (d_t - d_cv) / d_cv >= 1), pixels without a valid
  bin, and whole augmented samples.
- ``ManydepthLoss``: the training criterion (a component of ``training.train``): the teacher's Monodepth2 loss,
  the multi-frame network's Monodepth2 loss with its photometric term restricted to the reliable pixels, and the
  consistency loss |D_multi - D_teacher.detach()| on the unreliable ones. Static-camera / start-of-sequence
  augmentation: with probability ``static_prob`` a sample's previous frame is replaced by the target itself,
  with ``zero_prob`` its cost volume is zeroed. After ``freeze_at`` steps the teacher, the pose network and the
  depth range are frozen (Galteland §4.2.1.1: after epoch 15 of 20) and only the multi-frame network learns.
- ``predict_depth`` (test time: previous + target frame; no previous frame = zeroed cost volume) and
  ``predict_teacher_depth`` (the single-frame teacher).

Pose network, sources (prev, next) and auto-masking are Monodepth2's (``pipeline``). The cost volume's pose
(target -> previous) comes from the pose network without gradient, and the lookup frame's cost volume carries
no gradient into the teacher: the consistency target is detached and the best bin is an argmin.
"""
from __future__ import annotations

from collections.abc import Mapping

import torch
import torch.nn.functional as F
from torch import nn

from redsup.depth import losses, networks, pipeline, warping

TEACHER = {"depth_encoder": "teacher_encoder", "depth_decoder": "teacher_decoder"}
FROZEN = ("teacher_encoder", "teacher_decoder", "pose_encoder", "pose_decoder")  # after ManydepthLoss.freeze_at


# ------------------------------------------------------------------------------------------------ bins
def depth_bins(d_min: torch.Tensor | float, d_max: torch.Tensor | float, n_bins: int) -> torch.Tensor:
    """(n_bins,) depths 1 / linspace(1 / d_max, 1 / d_min, n_bins): uniform in inverse depth, far to near."""
    if n_bins < 2:
        raise ValueError(f"a cost volume needs at least 2 depth bins, got {n_bins}")
    d_min = torch.as_tensor(d_min, dtype=torch.float32)
    d_max = torch.as_tensor(d_max, dtype=torch.float32, device=d_min.device)
    if not bool(0 < d_min < d_max):
        raise ValueError(f"depth bins need 0 < d_min < d_max, got {float(d_min)}, {float(d_max)}")
    steps = torch.linspace(0.0, 1.0, n_bins, device=d_min.device)
    return 1.0 / (1.0 / d_max + steps * (1.0 / d_min - 1.0 / d_max))


class DepthRange(nn.Module):
    """Running ``d_min`` / ``d_max`` (buffers, saved with the checkpoint). Manydepth starts from 0.1 / 10 and
    moves 1 % towards each batch's value (``momentum`` 0.01)."""

    def __init__(self, d_min: float = 0.1, d_max: float = 10.0, momentum: float = 0.01):
        super().__init__()
        self.momentum = float(momentum)
        self.register_buffer("d_min", torch.tensor(float(d_min)))
        self.register_buffer("d_max", torch.tensor(float(d_max)))

    @torch.no_grad()
    def update(self, depth: torch.Tensor) -> None:
        """Move towards the batch mean of the per-image minimum and maximum of ``depth`` (B, 1, H, W)."""
        b = depth.shape[0]
        lo = depth.detach().reshape(b, -1).min(1).values.mean()
        hi = depth.detach().reshape(b, -1).max(1).values.mean()
        m = self.momentum
        self.d_min.mul_(1 - m).add_(m * lo.to(self.d_min))
        self.d_max.mul_(1 - m).add_(m * hi.to(self.d_max))

    def bins(self, n_bins: int) -> torch.Tensor:
        return depth_bins(self.d_min, self.d_max.clamp_min(self.d_min * 1.01), n_bins)


# ------------------------------------------------------------------------------------------ cost volume
def scale_intrinsics(K: torch.Tensor, size: tuple[int, int], new_size: tuple[int, int]) -> torch.Tensor:
    """K (B, 3, 3)/(B, 4, 4) of an image of ``size`` (H, W) for the same view resampled to ``new_size``, with
    pixel (0, 0) at the centre of the top-left pixel: u' = (u + 0.5) s - 0.5."""
    K3 = K[:, :3, :3].clone()
    sy, sx = new_size[0] / size[0], new_size[1] / size[1]
    K3[:, 0, :] *= sx
    K3[:, 1, :] *= sy
    K3[:, 0, 2] += 0.5 * sx - 0.5
    K3[:, 1, 2] += 0.5 * sy - 0.5
    return K3


def cost_volume(target_feat: torch.Tensor, source_feat: torch.Tensor, K: torch.Tensor, T: torch.Tensor,
                bins: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Plane-sweep cost volume (B, N, h, w) and the ``missing`` mask (B, 1, h, w) (no bin projects inside).

    ``target_feat`` / ``source_feat`` (B, C, h, w); ``K`` the intrinsics at the feature resolution; ``T``
    (B, 4, 4) target -> source; ``bins`` (N,) or (B, N) depths. cost[b, n, p] = mean_c |F_t(p) - F_s(warp(p, d_n))|.
    """
    b, c, h, w = target_feat.shape
    bins = bins.to(target_feat).expand(b, -1) if bins.dim() == 1 else bins.to(target_feat)
    n = bins.shape[1]
    planes = bins.reshape(b * n, 1, 1, 1).expand(b * n, 1, h, w)
    rep = lambda x: x.unsqueeze(1).expand(b, n, *x.shape[1:]).reshape(b * n, *x.shape[1:])  # noqa: E731
    grid, inside = warping.sampling_grid(planes, rep(K[:, :3, :3].to(target_feat)), rep(T.to(target_feat)))
    grid = torch.nan_to_num(grid, nan=2.0).clamp(-2.0, 2.0)
    warped = F.grid_sample(rep(source_feat), grid, mode="bilinear", padding_mode="zeros", align_corners=False)
    cost = (warped - rep(target_feat)).abs().mean(1).reshape(b, n, h, w)
    valid = inside.reshape(b, n, h, w)
    worst = torch.where(valid, cost, torch.zeros_like(cost)).amax(1, keepdim=True)
    cost = torch.where(valid, cost, worst)
    missing = ~valid.any(1, keepdim=True)
    return cost * (~missing).to(cost), missing


def best_bin_depth(cost: torch.Tensor, bins: torch.Tensor) -> torch.Tensor:
    """(B, 1, h, w) depth of the lowest-cost bin (an argmin: no gradient)."""
    bins = bins.expand(cost.shape[0], -1) if bins.dim() == 1 else bins
    idx = cost.detach().argmin(1)  # (B, h, w)
    return torch.gather(bins.to(cost).unsqueeze(-1).unsqueeze(-1).expand_as(cost), 1, idx.unsqueeze(1))


def consistency_mask(cv_depth: torch.Tensor, teacher_depth: torch.Tensor, missing: torch.Tensor | None = None,
                     augmented: torch.Tensor | None = None) -> torch.Tensor:
    """Bool (B, 1, H, W): True where the cost volume is unreliable, i.e. its best-bin depth ``cv_depth`` and the
    teacher's depth differ by a factor of 2 or more in either direction, or the pixel is ``missing``, or the
    sample is ``augmented`` ((B,) bool). Inputs at the same resolution."""
    cv, t = cv_depth.detach(), teacher_depth.detach()
    mask = ((cv - t) / t >= 1.0) | ((t - cv) / cv >= 1.0)
    if missing is not None:
        mask = mask | missing
    if augmented is not None:
        mask = mask | augmented.reshape(-1, 1, 1, 1).to(torch.bool)
    return mask


class CostVolumeEncoder(nn.Module):
    """ResNet-18 (``networks.ResNetEncoder``) with a cost volume after layer1. ``num_ch_enc`` as the encoder's,
    so ``networks.DepthDecoder`` decodes it."""

    def __init__(self, base_channels: int = 64, n_bins: int = 96):
        super().__init__()
        self.resnet = networks.ResNetEncoder(3, base_channels)
        self.n_bins = int(n_bins)
        self.num_ch_enc = self.resnet.num_ch_enc
        self.reduce = nn.Sequential(nn.Conv2d(self.num_ch_enc[1] + self.n_bins, self.num_ch_enc[1], 3, 1, 1),
                                    nn.ReLU(inplace=True))

    def stem(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        r = self.resnet
        f0 = F.relu(r.bn1(r.conv1((x - networks.IMAGE_MEAN) / networks.IMAGE_STD)))
        return f0, r.layer1(F.max_pool2d(f0, 3, 2, 1))

    def forward(self, target: torch.Tensor, lookup: torch.Tensor, K: torch.Tensor, T: torch.Tensor,
                bins: torch.Tensor, zero_volume: torch.Tensor | None = None) -> dict:
        """``K`` at the input resolution; ``T`` target -> lookup; ``zero_volume`` (B,) bool zeroes a sample's
        volume. Returns features (list of 5), cost, missing and the best-bin depth (stride 4)."""
        f0, f1 = self.stem(target)
        _, l1 = self.stem(lookup)
        Kf = scale_intrinsics(K, tuple(target.shape[-2:]), tuple(f1.shape[-2:]))
        cost, missing = cost_volume(f1, l1, Kf, T, bins)
        best = best_bin_depth(cost, bins)
        if zero_volume is not None:
            cost = cost * (~zero_volume.to(torch.bool)).to(cost).reshape(-1, 1, 1, 1)
        x = self.reduce(torch.cat([f1, cost], 1))
        f2 = self.resnet.layer2(x)
        f3 = self.resnet.layer3(f2)
        return {"features": [f0, x, f2, f3, self.resnet.layer4(f3)], "cost": cost, "missing": missing,
                "best_depth": best}


def build_models(base_channels: int = 64, num_scales: int = 4, n_bins: int = 96, init_disparity: float | None = None,
                 range_init: tuple[float, float] = (0.1, 10.0), range_momentum: float = 0.01) -> nn.ModuleDict:
    """Multi-frame depth network, single-frame teacher, Monodepth2 pose network and the learned depth range."""
    enc = CostVolumeEncoder(base_channels, n_bins)
    teacher = networks.build_models(base_channels, num_scales, init_disparity)
    return nn.ModuleDict({
        "depth_encoder": enc,
        "depth_decoder": networks.DepthDecoder(enc.num_ch_enc, num_scales=num_scales, init_disparity=init_disparity),
        "pose_encoder": teacher["pose_encoder"], "pose_decoder": teacher["pose_decoder"],
        "teacher_encoder": teacher["depth_encoder"], "teacher_decoder": teacher["depth_decoder"],
        "depth_range": DepthRange(*range_init, momentum=range_momentum),
    })


def teacher_view(models: Mapping[str, nn.Module]) -> dict[str, nn.Module]:
    """The teacher as a Monodepth2 model dict (``pipeline`` functions read ``depth_encoder``/``depth_decoder``)."""
    return {**models, **{k: models[v] for k, v in TEACHER.items()}}


# ------------------------------------------------------------------------------------------- prediction
def lookup_transform(models: Mapping[str, nn.Module], target: torch.Tensor, lookup: torch.Tensor) -> torch.Tensor:
    """Target -> lookup (previous frame) transform from the pose network, without gradient."""
    with torch.no_grad():
        return pipeline.pose_transform(*pipeline.predict_pose_parameters(models, target, lookup, "prev"), "prev")


def multi_disparities(models: Mapping[str, nn.Module], target: torch.Tensor, lookup: torch.Tensor, K: torch.Tensor,
                      zero_volume: torch.Tensor | None = None, T: torch.Tensor | None = None
                      ) -> tuple[list[torch.Tensor], dict]:
    """Disparities of the multi-frame network and the encoder's outputs (cost, missing, best_depth)."""
    T = lookup_transform(models, target, lookup) if T is None else T
    bins = models["depth_range"].bins(models["depth_encoder"].n_bins)
    out = models["depth_encoder"](target, lookup, K, T, bins, zero_volume)
    return models["depth_decoder"](out["features"], output_size=tuple(target.shape[-2:])), out


def predict_depth(models: Mapping[str, nn.Module], target: torch.Tensor, prev: torch.Tensor | None, K: torch.Tensor,
                  min_depth: float = 0.1, max_depth: float = 100.0) -> torch.Tensor:
    """Test-time depth (B, 1, H, W) from the previous and the target frame; without a previous frame (start of a
    sequence) the target is its own lookup and the cost volume is zeroed, as in training's augmentation."""
    zero = None
    if prev is None:
        prev = target
        zero = torch.ones(target.shape[0], dtype=torch.bool, device=target.device)
    with torch.no_grad():
        disps, _ = multi_disparities(models, target, prev, K, zero)
    return networks.disp_to_depth(disps[0], min_depth, max_depth)[1]


def predict_teacher_depth(models: Mapping[str, nn.Module], target: torch.Tensor, min_depth: float = 0.1,
                          max_depth: float = 100.0) -> torch.Tensor:
    with torch.no_grad():
        return pipeline.predict_depth(teacher_view(models), target, min_depth, max_depth)


# ---------------------------------------------------------------------------------------------- training
def _up(x: torch.Tensor, size, mode: str = "bilinear") -> torch.Tensor:
    if tuple(x.shape[-2:]) == tuple(size):
        return x
    return F.interpolate(x.float(), size=tuple(size), mode=mode, **({} if mode == "nearest" else
                                                                    {"align_corners": False}))


class ManydepthLoss:
    """The Manydepth criterion ``(models, batch, step) -> loss dict`` for ``training.train``.

    ``loss_kwargs`` go to ``losses.self_supervised_loss`` (smoothness, SSIM weight, auto-masking, noise), with
    auto-masking off for the teacher's and the multi-frame loss up to step ``automask_after`` (every pixel in the
    loss before, as the M mode's ``automask_after``); ``generator`` draws the augmentation (reproducible). The
    batch needs the temporal source ``prev``."""

    def __init__(self, *, min_depth: float = 0.1, max_depth: float = 100.0, static_prob: float = 0.25,
                 zero_prob: float = 0.25, consistency_weight: float = 1.0, freeze_at: int | None = None,
                 generator: torch.Generator | None = None, automask_after: int = 0, **loss_kwargs):
        self.min_depth, self.max_depth = float(min_depth), float(max_depth)
        self.static_prob, self.zero_prob = float(static_prob), float(zero_prob)
        self.consistency_weight = float(consistency_weight)
        self.freeze_at = freeze_at
        self.generator = generator
        self.automask_after = int(automask_after)
        self.loss_kwargs = loss_kwargs

    def frozen(self, step: int) -> bool:
        return self.freeze_at is not None and step > self.freeze_at

    def augmentation(self, b: int, device) -> tuple[torch.Tensor, torch.Tensor]:
        """(static (B,) bool, zero (B,) bool): static samples see the target as their previous frame."""
        u = torch.rand(b, generator=self.generator) if self.generator is not None else torch.rand(b)
        static = u < self.static_prob
        zero = (u >= self.static_prob) & (u < self.static_prob + self.zero_prob)
        return static.to(device), zero.to(device)

    def __call__(self, models: Mapping[str, nn.Module], batch: Mapping, step: int = 1) -> dict[str, torch.Tensor]:
        frozen = self.frozen(step)
        kw = dict(min_depth=self.min_depth, max_depth=self.max_depth,
                  **losses.masking_at(self.loss_kwargs, step, self.automask_after))
        target, size = batch["target"], tuple(batch["target"].shape[-2:])
        teacher = teacher_view(models)
        if frozen:
            for name in FROZEN:  # frozen networks also keep their BatchNorm statistics
                models[name].eval()
            with torch.no_grad():
                transforms = pipeline.source_transforms(models, batch)
                t_disps = pipeline.predict_disparities(teacher, target)
        else:
            transforms = pipeline.source_transforms(models, batch)
            t_disps = pipeline.predict_disparities(teacher, target)
        t_depth = networks.disp_to_depth(t_disps[0], self.min_depth, self.max_depth)[1]
        if not frozen:
            models["depth_range"].update(t_depth)
        static, zero = self.augmentation(target.shape[0], target.device)
        prev = batch["sources"]["prev"]
        lookup = torch.where(static.reshape(-1, 1, 1, 1), target, prev)
        T = lookup_transform(models, target, lookup) if bool(static.any()) else transforms["prev"].detach()
        m_disps, enc = multi_disparities(models, target, lookup, batch["K"], zero, T)
        unreliable = consistency_mask(_up(enc["best_depth"], size, "nearest"), t_depth.detach(),
                                      _up(enc["missing"], size, "nearest").bool(), static | zero)
        weight = (~unreliable).to(target.dtype)
        m_transforms = {k: v.detach() for k, v in transforms.items()} if frozen else transforms
        multi = pipeline.loss_from_outputs(batch, m_disps, m_transforms, pixel_weight=weight, **kw)
        consistency = 0.0
        for d in m_disps:
            m_depth = networks.disp_to_depth(_up(d, size), self.min_depth, self.max_depth)[1]
            consistency = consistency + ((m_depth - t_depth.detach()).abs() * unreliable).mean()
        consistency = consistency / len(m_disps)
        terms = {"multi_loss": multi["loss"], "consistency": consistency,
                 "photometric": multi["photometric"], "automask_fraction": multi["automask_fraction"],
                 "unreliable_fraction": unreliable.float().mean(),
                 "d_min": models["depth_range"].d_min.clone(), "d_max": models["depth_range"].d_max.clone()}
        loss = multi["loss"] + self.consistency_weight * consistency
        if not frozen:
            t_loss = pipeline.loss_from_outputs(batch, t_disps, transforms, **kw)
            terms["teacher_loss"] = t_loss["loss"]
            loss = loss + t_loss["loss"]
        terms["loss"] = loss
        return terms
