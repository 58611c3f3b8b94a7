"""Monodepth2 networks written in the project (torchvision is not available; no pretrained weights exist).

- ``ResNetEncoder``: ResNet-18 (He et al. 2016) with configurable input channels (3 for the depth network, 6 for
  the pose network on two stacked frames) and a width multiplier (``base_channels`` 64 = the paper's network).
  Random (Kaiming) initialisation. Returns the five feature maps Monodepth2 uses
  (strides 2, 4, 8, 16, 32).
- ``DepthDecoder``: the U-Net decoder of Monodepth2 (reflection-padded 3x3 conv + ELU, nearest upsampling, skip
  connections), sigmoid disparity at 4 scales (scale s has resolution H / 2^s).
- ``PoseDecoder``: squeeze 1x1 conv, 2 3x3 convs, 1x1 conv to 6 numbers, spatial mean, scaled by 0.01;
  returns axis-angle and translation.
- ``disp_to_depth``: sigmoid output to depth in [min_depth, max_depth].

Every module reads the spatial size from its input: upsampling goes to the size of the skip feature, so any
H, W works (multiples of 32 give the exact Monodepth2 pyramid) and batch size 1 is fine.

Sub-modules named for test-time adaptation (McCraith ch. 4 Table 1): ``encoder.first_layer`` (conv1 + bn1)
and ``encoder.last_block`` (layer4).
"""
from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

IMAGE_MEAN = 0.45  # Monodepth2 normalises inputs as (x - 0.45) / 0.225
IMAGE_STD = 0.225
MODULE_NAMES = ("depth_encoder", "depth_decoder", "pose_encoder", "pose_decoder")


class BasicBlock(nn.Module):
    """ResNet basic block: two 3x3 convs with BatchNorm, identity (or 1x1 projection) shortcut."""

    def __init__(self, in_ch: int, out_ch: int, stride: int = 1):
        super().__init__()
        self.conv1 = nn.Conv2d(in_ch, out_ch, 3, stride, 1, bias=False)
        self.bn1 = nn.BatchNorm2d(out_ch)
        self.conv2 = nn.Conv2d(out_ch, out_ch, 3, 1, 1, bias=False)
        self.bn2 = nn.BatchNorm2d(out_ch)
        self.downsample = None
        if stride != 1 or in_ch != out_ch:
            self.downsample = nn.Sequential(nn.Conv2d(in_ch, out_ch, 1, stride, bias=False), nn.BatchNorm2d(out_ch))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out = F.relu(self.bn1(self.conv1(x)))
        out = self.bn2(self.conv2(out))
        shortcut = x if self.downsample is None else self.downsample(x)
        return F.relu(out + shortcut)


def _layer(in_ch: int, out_ch: int, blocks: int, stride: int) -> nn.Sequential:
    return nn.Sequential(BasicBlock(in_ch, out_ch, stride), *[BasicBlock(out_ch, out_ch) for _ in range(blocks - 1)])


class ResNetEncoder(nn.Module):
    """ResNet-18 feature pyramid. ``num_ch_enc`` = [b, b, 2b, 4b, 8b] for ``base_channels`` b."""

    def __init__(self, in_channels: int = 3, base_channels: int = 64, blocks: tuple[int, ...] = (2, 2, 2, 2)):
        super().__init__()
        b = base_channels
        self.in_channels = in_channels
        self.num_ch_enc = (b, b, 2 * b, 4 * b, 8 * b)
        self.conv1 = nn.Conv2d(in_channels, b, 7, 2, 3, bias=False)
        self.bn1 = nn.BatchNorm2d(b)
        self.layer1 = _layer(b, b, blocks[0], 1)
        self.layer2 = _layer(b, 2 * b, blocks[1], 2)
        self.layer3 = _layer(2 * b, 4 * b, blocks[2], 2)
        self.layer4 = _layer(4 * b, 8 * b, blocks[3], 2)
        for m in self.modules():
            if isinstance(m, nn.Conv2d):
                nn.init.kaiming_normal_(m.weight, mode="fan_out", nonlinearity="relu")
            elif isinstance(m, nn.BatchNorm2d):
                nn.init.ones_(m.weight)
                nn.init.zeros_(m.bias)

    @property
    def first_layer(self) -> nn.ModuleList:
        """conv1 + bn1 (the "first layer" rows of ch. 4 Table 1)."""
        return nn.ModuleList([self.conv1, self.bn1])

    @property
    def last_block(self) -> nn.Module:
        """layer4 (the "last residual block" rows of ch. 4 Table 1)."""
        return self.layer4

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        if x.shape[1] != self.in_channels:
            raise ValueError(f"encoder expects {self.in_channels} input channels, got {x.shape[1]}")
        x = (x - IMAGE_MEAN) / IMAGE_STD
        f0 = F.relu(self.bn1(self.conv1(x)))
        f1 = self.layer1(F.max_pool2d(f0, 3, 2, 1))
        f2 = self.layer2(f1)
        f3 = self.layer3(f2)
        return [f0, f1, f2, f3, self.layer4(f3)]


def pad1(x: torch.Tensor) -> torch.Tensor:
    """Reflection padding by 1 (Monodepth2); replicate where a side is a single pixel (tiny inputs)."""
    return F.pad(x, (1, 1, 1, 1), mode="reflect" if min(x.shape[-2:]) > 1 else "replicate")


class ConvBlock(nn.Module):
    """Reflection-padded 3x3 conv + ELU (Monodepth2's decoder block)."""

    def __init__(self, in_ch: int, out_ch: int):
        super().__init__()
        self.conv = nn.Conv2d(in_ch, out_ch, 3)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.elu(self.conv(pad1(x)))


def decoder_channels(base_channels: int) -> tuple[int, ...]:
    """Monodepth2's (16, 32, 64, 128, 256) scaled by base_channels / 64 (at least 4 channels)."""
    return tuple(max(4, c * base_channels // 64) for c in (16, 32, 64, 128, 256))


class DepthDecoder(nn.Module):
    """U-Net decoder with skip connections; ``forward`` returns [disp_0, ..., disp_{n-1}] (scale s: H / 2^s)."""

    def __init__(self, num_ch_enc: tuple[int, ...], num_ch_dec: tuple[int, ...] | None = None, num_scales: int = 4,
                 init_disparity: float | None = None):
        """``init_disparity`` in (0, 1): the sigmoid output of an untrained network, set through the bias of
        the disparity convolutions (None: zero bias, 0.5 as Monodepth2)."""
        super().__init__()
        self.num_ch_enc = tuple(num_ch_enc)
        self.num_ch_dec = tuple(num_ch_dec) if num_ch_dec is not None else decoder_channels(num_ch_enc[0])
        self.num_scales = num_scales
        self.upconv0 = nn.ModuleList()
        self.upconv1 = nn.ModuleList()
        for i in range(5):  # index i produces features at stride 2^i
            in0 = self.num_ch_enc[-1] if i == 4 else self.num_ch_dec[i + 1]
            self.upconv0.append(ConvBlock(in0, self.num_ch_dec[i]))
            in1 = self.num_ch_dec[i] + (self.num_ch_enc[i - 1] if i > 0 else 0)
            self.upconv1.append(ConvBlock(in1, self.num_ch_dec[i]))
        self.dispconv = nn.ModuleList([nn.Conv2d(self.num_ch_dec[s], 1, 3) for s in range(num_scales)])
        if init_disparity is not None:
            if not 0.0 < init_disparity < 1.0:
                raise ValueError(f"init_disparity must lie in (0, 1), got {init_disparity}")
            for conv in self.dispconv:
                nn.init.constant_(conv.bias, math.log(init_disparity / (1.0 - init_disparity)))

    def forward(self, features: list[torch.Tensor], output_size: tuple[int, int] | None = None) -> list[torch.Tensor]:
        """``output_size`` (H, W) of the input image; default twice the first feature map."""
        if output_size is None:
            output_size = (2 * features[0].shape[-2], 2 * features[0].shape[-1])
        x = features[-1]
        disps: list[torch.Tensor] = [None] * self.num_scales  # type: ignore[list-item]
        for i in range(4, -1, -1):
            x = self.upconv0[i](x)
            size = features[i - 1].shape[-2:] if i > 0 else output_size
            x = F.interpolate(x, size=tuple(size), mode="nearest")
            if i > 0:
                x = torch.cat([x, features[i - 1]], dim=1)
            x = self.upconv1[i](x)
            if i < self.num_scales:
                disps[i] = torch.sigmoid(self.dispconv[i](pad1(x)))
        return disps


class PoseDecoder(nn.Module):
    """Monodepth2 pose decoder for one frame pair: (axisangle (B, 3), translation (B, 3)), outputs scaled 0.01."""

    def __init__(self, num_ch_enc: tuple[int, ...], hidden: int | None = None):
        super().__init__()
        hidden = hidden if hidden is not None else max(8, 256 * num_ch_enc[0] // 64)
        self.squeeze = nn.Conv2d(num_ch_enc[-1], hidden, 1)
        self.pose0 = nn.Conv2d(hidden, hidden, 3, 1, 1)
        self.pose1 = nn.Conv2d(hidden, hidden, 3, 1, 1)
        self.pose2 = nn.Conv2d(hidden, 6, 1)

    def forward(self, features: list[torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        x = F.relu(self.squeeze(features[-1]))
        x = F.relu(self.pose0(x))
        x = F.relu(self.pose1(x))
        out = 0.01 * self.pose2(x).mean(dim=(2, 3))
        return out[:, :3], out[:, 3:]


def build_models(base_channels: int = 64, num_scales: int = 4, init_disparity: float | None = None) -> nn.ModuleDict:
    """The four sub-networks of ch. 4 Fig. 2, keyed by ``MODULE_NAMES``; random initialisation
    (``init_disparity``: see ``DepthDecoder``)."""
    depth_encoder = ResNetEncoder(3, base_channels)
    pose_encoder = ResNetEncoder(6, base_channels)
    return nn.ModuleDict({
        "depth_encoder": depth_encoder,
        "depth_decoder": DepthDecoder(depth_encoder.num_ch_enc, num_scales=num_scales, init_disparity=init_disparity),
        "pose_encoder": pose_encoder,
        "pose_decoder": PoseDecoder(pose_encoder.num_ch_enc),
    })


def disp_to_depth(disp: torch.Tensor, min_depth: float = 0.1, max_depth: float = 100.0
                  ) -> tuple[torch.Tensor, torch.Tensor]:
    """Sigmoid disparity to (scaled disparity, depth): 1/depth = 1/max + (1/min - 1/max) * disp (Monodepth2)."""
    min_disp, max_disp = 1.0 / max_depth, 1.0 / min_depth
    scaled = min_disp + (max_disp - min_disp) * disp
    return scaled, 1.0 / scaled
