"""The pillar grid (input) and the BEV output grid of the detector.

Pillars are infinite-height voxels of `pillar` metres in x (forward) and y (left); points outside
`x_range` x `y_range` x `z_range` (vehicle frame) are dropped. The CNN's first convolution has stride
`stride`, so the output map (heatmap, offsets, yaw bins) has cells of `pillar * stride` metres:
the thesis uses 10 cm voxels and 4x downsampling (40 cm cells, 200 x 176 over 80 x 70.4 m); our CPU
default is 20 cm pillars and 2x downsampling (the same 40 cm cells) over x in [0, 51.2) and y in
[-12.8, 12.8), i.e. 256 x 128 pillars and a 128 x 64 output map: the world's street cars (parked and
moving) lie within |y| < 9 m, and with 2D boxes in KITTI pixels the moderate / hard cut (25 px) ends
near 45 m.

Output cell (r, c) covers x in [x_min + c cell, x_min + (c + 1) cell), y in [y_min + r cell, ...), rows
along y, columns along x, as `redsup.det3d.voting.BevGrid`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from redsup.det3d.voting import BevGrid


@dataclass(frozen=True)
class GridSpec:
    x_range: tuple[float, float] = (0.0, 51.2)
    y_range: tuple[float, float] = (-12.8, 12.8)
    z_range: tuple[float, float] = (-1.0, 4.0)
    pillar: float = 0.2
    stride: int = 2
    z_ref: float = 0.0          # z of the cell corner that the z offset is measured from

    def __post_init__(self):
        for name, (lo, hi) in (("x_range", self.x_range), ("y_range", self.y_range), ("z_range", self.z_range)):
            if not hi > lo:
                raise ValueError(f"grid {name} must be increasing, got {(lo, hi)}")
        if self.pillar <= 0 or self.stride < 1:
            raise ValueError(f"grid needs pillar > 0 and stride >= 1, got {self.pillar}, {self.stride}")
        for name, (lo, hi) in (("x_range", self.x_range), ("y_range", self.y_range)):
            n = (hi - lo) / self.cell
            if abs(n - round(n)) > 1e-6:
                raise ValueError(f"grid {name} {(lo, hi)} is not a whole number of {self.cell:g} m output cells "
                                 f"(pillar {self.pillar:g} m x stride {self.stride})")

    @classmethod
    def from_config(cls, cfg: dict) -> "GridSpec":
        return cls(x_range=tuple(cfg["x_range"]), y_range=tuple(cfg["y_range"]), z_range=tuple(cfg["z_range"]),
                   pillar=float(cfg["pillar"]), stride=int(cfg["stride"]), z_ref=float(cfg.get("z_ref", 0.0)))

    @property
    def cell(self) -> float:
        return self.pillar * self.stride

    @property
    def nx(self) -> int:
        """Pillar columns (x)."""
        return int(round((self.x_range[1] - self.x_range[0]) / self.pillar))

    @property
    def ny(self) -> int:
        """Pillar rows (y)."""
        return int(round((self.y_range[1] - self.y_range[0]) / self.pillar))

    @property
    def out_width(self) -> int:
        return math.ceil(self.nx / self.stride)

    @property
    def out_height(self) -> int:
        return math.ceil(self.ny / self.stride)

    def bev(self) -> BevGrid:
        """The output grid as used by the voting and the decoding."""
        return BevGrid(x_min=self.x_range[0], y_min=self.y_range[0], cell=self.cell, height=self.out_height,
                       width=self.out_width, z_ref=self.z_ref)
