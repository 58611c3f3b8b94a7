"""Global augmentation of a training frame (ch. 7 S 4.1: rotation, translation, left-right flip, scaling).

One `GlobalTransform` per frame is applied to the whole sweep, to every L_m set of the frame and to the
ground-truth boxes (supervised rows), so targets stay consistent with the points: p' = s R(angle) F p + t,
with F the left-right flip (y -> -y) when `flip`, R a rotation about +z, s a uniform scale and t a
translation. Boxes: centre as a point, yaw -> angle + (-yaw if flipped else yaw), sizes x s.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class AugmentSpec:
    rotation: float = math.pi / 18           # max |angle| (rad), uniform
    flip: bool = True                        # left-right flip with probability 1/2
    scale: tuple[float, float] = (0.95, 1.05)
    translation_std: tuple[float, float, float] = (0.2, 0.2, 0.2)   # m

    @classmethod
    def from_config(cls, cfg: dict) -> "AugmentSpec":
        return cls(rotation=math.radians(float(cfg["rotation_deg"])), flip=bool(cfg["flip"]),
                   scale=tuple(float(v) for v in cfg["scale"]),
                   translation_std=tuple(float(v) for v in cfg["translation_std"]))


@dataclass(frozen=True)
class GlobalTransform:
    angle: float = 0.0
    flip: bool = False
    scale: float = 1.0
    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def matrix(self) -> np.ndarray:
        """3 x 3 linear part s R F."""
        c, s = math.cos(self.angle), math.sin(self.angle)
        R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        F = np.diag([1.0, -1.0 if self.flip else 1.0, 1.0])
        return self.scale * R @ F

    def points(self, pts: np.ndarray) -> np.ndarray:
        """(N, >=3) points: xyz transformed, further columns (reflectance) kept; dtype kept."""
        pts = np.asarray(pts)
        out = pts.copy()
        out[:, :3] = (pts[:, :3].astype(np.float64) @ self.matrix().T + np.asarray(self.translation)).astype(pts.dtype)
        return out

    def boxes(self, boxes: np.ndarray) -> np.ndarray:
        """(N, 7) boxes (x, y, z, l, w, h, yaw); yaw wrapped to [-pi, pi)."""
        b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7).copy()
        b[:, :3] = b[:, :3] @ self.matrix().T + np.asarray(self.translation)
        b[:, 3:6] *= self.scale
        yaw = -b[:, 6] if self.flip else b[:, 6]
        b[:, 6] = np.remainder(yaw + self.angle + math.pi, 2 * math.pi) - math.pi
        return b


IDENTITY = GlobalTransform()


def sample_transform(rng: np.random.Generator, spec: AugmentSpec) -> GlobalTransform:
    angle = float(rng.uniform(-spec.rotation, spec.rotation)) if spec.rotation > 0 else 0.0
    flip = bool(spec.flip and rng.random() < 0.5)
    lo, hi = spec.scale
    scale = float(rng.uniform(lo, hi)) if hi > lo else float(lo)
    t = tuple(float(rng.normal(0.0, s)) if s > 0 else 0.0 for s in spec.translation_std)
    return GlobalTransform(angle, flip, scale, t)
