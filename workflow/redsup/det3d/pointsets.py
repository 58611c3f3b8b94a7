"""Padding the per-mask LiDAR point sets L_m into a batch, with the bad-input rules of issue 4.

Non-finite points are dropped (counted), sets left with fewer than `min_points` points are skipped
(counted, with their indices), sets larger than `max_points` are subsampled without replacement with the
caller's generator (deterministic for a seeded generator). Padding entries are 0 and masked out.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch


@dataclass
class PaddedSets:
    points: torch.Tensor      # (N, P, 3) kept sets, zero-padded
    mask: torch.Tensor        # (N, P) bool, True on real points
    keep: np.ndarray          # (N,) indices of the kept sets in the input list
    skipped: np.ndarray       # indices of sets skipped for having < min_points finite points
    n_nonfinite: int          # points dropped for NaN / inf coordinates

    def message(self) -> str:
        return (f"{len(self.keep)} point sets kept; {len(self.skipped)} skipped with fewer than the minimum "
                f"number of finite points; {self.n_nonfinite} non-finite points dropped")


def pad_point_sets(sets: list[np.ndarray], min_points: int = 1, max_points: int | None = None,
                   rng: np.random.Generator | None = None, dtype=torch.float32) -> PaddedSets:
    """Pad sets of (n_i, >=3) points (only x, y, z are kept). `rng` is needed when max_points is set."""
    kept, keep, skipped, n_bad = [], [], [], 0
    for i, s in enumerate(sets):
        arr = np.asarray(s, dtype=np.float64)
        xyz = arr.reshape(-1, arr.shape[-1] if arr.ndim == 2 else 3)[:, :3]
        finite = np.isfinite(xyz).all(axis=1)
        n_bad += int((~finite).sum())
        xyz = xyz[finite]
        if len(xyz) < min_points:
            skipped.append(i)
            continue
        if max_points is not None and len(xyz) > max_points:
            if rng is None:
                raise ValueError("pad_point_sets: pass rng to subsample sets larger than max_points")
            xyz = xyz[np.sort(rng.choice(len(xyz), size=max_points, replace=False))]
        kept.append(xyz)
        keep.append(i)
    width = max([len(x) for x in kept] + [1])
    points = torch.zeros((len(kept), width, 3), dtype=dtype)
    mask = torch.zeros((len(kept), width), dtype=torch.bool)
    for k, xyz in enumerate(kept):
        points[k, :len(xyz)] = torch.as_tensor(xyz, dtype=dtype)
        mask[k, :len(xyz)] = True
    return PaddedSets(points, mask, np.asarray(keep, dtype=np.int64), np.asarray(skipped, dtype=np.int64), n_bad)
