"""The detector: pillar features scattered into a BEV grid, a small 2D CNN and CenterPoint-style heads.

- `PillarNet` (PointPillars' PFN): per point (x, y, z)/10 m, reflectance, offsets to the mean of its
  pillar's points and to the pillar centre -> Linear + BatchNorm + ReLU -> max over the pillar, scattered
  into a (C, ny, nx) canvas (empty pillars 0).
- `Backbone`: a stride-`grid.stride` stem (stride-2 3x3 convolutions) and a 3x3 convolution at the output
  resolution, plus a branch at half that resolution (three 3x3 convolutions, wider, for the receptive field
  of a whole car) projected by a 1x1 convolution, upsampled (nearest) and added. Any grid size works (the
  branch is resized to the exact output size).
- Heads on a shared 3x3 convolution: `heatmap` (B, 1, H, W) logits (bias -2.19: prior 0.1, CenterNet),
  `offset` (B, 3, H, W) metres from the cell corner (x_min + c cell, y_min + r cell, z_ref) to the object
  centre (bias: cell centre and a car's centre height), `yaw` (B, K, H, W) bin logits, and with
  `predict_size` `size` (B, 3, H, W) log(size / template size).
"""
from __future__ import annotations

import torch
import torch.nn as nn
import torch.nn.functional as F

from redsup.lidar_detector.grid import GridSpec

N_POINT_FEATURES = 9


def pillar_features(points: torch.Tensor, grid: GridSpec) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-point PFN inputs (N', 9) and flat pillar indices (N',) (iy * nx + ix) of the points (N, >=4)
    inside the grid (others dropped)."""
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    ix = torch.floor((x - grid.x_range[0]) / grid.pillar).long()
    iy = torch.floor((y - grid.y_range[0]) / grid.pillar).long()
    ok = (ix >= 0) & (ix < grid.nx) & (iy >= 0) & (iy < grid.ny) & (z >= grid.z_range[0]) & (z < grid.z_range[1]) \
        & torch.isfinite(points[:, :4]).all(dim=1)
    p, ix, iy = points[ok], ix[ok], iy[ok]
    flat = iy * grid.nx + ix
    n_cells = grid.nx * grid.ny
    count = torch.zeros(n_cells, dtype=p.dtype, device=p.device).index_add_(0, flat, torch.ones_like(p[:, 0]))
    total = torch.zeros((n_cells, 3), dtype=p.dtype, device=p.device).index_add_(0, flat, p[:, :3])
    mean = total[flat] / count[flat, None]
    cx = grid.x_range[0] + (ix.to(p.dtype) + 0.5) * grid.pillar
    cy = grid.y_range[0] + (iy.to(p.dtype) + 0.5) * grid.pillar
    feats = torch.cat([p[:, :3] / 10.0, p[:, 3:4], p[:, :3] - mean, (p[:, 0] - cx)[:, None], (p[:, 1] - cy)[:, None]],
                      dim=1)
    return feats, flat


class PillarNet(nn.Module):
    def __init__(self, grid: GridSpec, channels: int = 16):
        super().__init__()
        self.grid = grid
        self.channels = channels
        self.linear = nn.Linear(N_POINT_FEATURES, channels, bias=False)
        self.norm = nn.BatchNorm1d(channels)

    def forward(self, points: list[torch.Tensor]) -> torch.Tensor:
        g = self.grid
        n_cells = g.nx * g.ny
        feats, idx = [], []
        for b, pts in enumerate(points):
            f, flat = pillar_features(pts, g)
            feats.append(f)
            idx.append(flat + b * n_cells)
        feats = torch.cat(feats)
        idx = torch.cat(idx)
        device = self.linear.weight.device
        canvas = torch.zeros((len(points) * n_cells, self.channels), device=device, dtype=self.linear.weight.dtype)
        if len(feats) > 1 or (len(feats) == 1 and not self.training):   # BatchNorm needs 2 in training
            h = F.relu(self.norm(self.linear(feats.to(device))))
            canvas = canvas.scatter_reduce(0, idx.to(device)[:, None].expand(-1, self.channels), h, reduce="amax",
                                           include_self=True)
        return canvas.view(len(points), g.ny, g.nx, self.channels).permute(0, 3, 1, 2).contiguous()


def _conv(cin: int, cout: int, stride: int = 1) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(cin, cout, 3, stride, 1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True))


class Backbone(nn.Module):
    def __init__(self, cin: int, channels: int = 32, deep_channels: int = 64, stride: int = 2):
        super().__init__()
        # stride 2^k: k stride-2 convolutions (no input pixel skipped); other strides: one strided convolution
        k = stride.bit_length() - 1
        if stride > 1 and stride == 2 ** k:
            self.stem = nn.Sequential(*[_conv(cin if i == 0 else channels, channels, 2) for i in range(k)])
        else:
            self.stem = _conv(cin, channels, stride)
        self.block = _conv(channels, channels)
        self.down = nn.Sequential(_conv(channels, deep_channels, 2), _conv(deep_channels, deep_channels),
                                  _conv(deep_channels, deep_channels))
        self.up = nn.Sequential(nn.Conv2d(deep_channels, channels, 1, bias=False), nn.BatchNorm2d(channels))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        f1 = self.block(self.stem(x))
        up = F.interpolate(self.up(self.down(f1)), size=f1.shape[-2:], mode="nearest")
        return F.relu(f1 + up)


class CenterDetector(nn.Module):
    """outputs = model(list of (N_b, 4) point tensors) -> dict of (B, ., H, W) maps."""

    def __init__(self, grid: GridSpec, n_bins: int = 64, predict_size: bool = False, pillar_channels: int = 8,
                 channels: int = 24, deep_channels: int = 48, centre_height: float = 0.75):
        super().__init__()
        self.grid = grid
        self.n_bins = n_bins
        self.predict_size = predict_size
        self.pillars = PillarNet(grid, pillar_channels)
        self.backbone = Backbone(pillar_channels, channels, deep_channels, grid.stride)
        self.shared = _conv(channels, channels)
        self.heatmap = nn.Conv2d(channels, 1, 1)
        self.offset = nn.Conv2d(channels, 3, 1)
        self.yaw = nn.Conv2d(channels, n_bins, 1)
        self.size = nn.Conv2d(channels, 3, 1) if predict_size else None
        with torch.no_grad():
            self.heatmap.bias.fill_(-2.19)
            self.offset.weight.mul_(0.1)
            self.offset.bias.copy_(torch.tensor([grid.cell / 2, grid.cell / 2, centre_height - grid.z_ref]))
            if self.size is not None:
                self.size.weight.mul_(0.1)
                self.size.bias.zero_()

    def forward(self, points: list[torch.Tensor]) -> dict[str, torch.Tensor]:
        feat = self.shared(self.backbone(self.pillars(points)))
        out = {"heatmap": self.heatmap(feat), "offset": self.offset(feat), "yaw": self.yaw(feat)}
        if self.size is not None:
            out["size"] = self.size(feat)
        return out
