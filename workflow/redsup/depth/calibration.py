"""Depth scale from the known camera height (McCraith ch. 5 §3.3) and the scaling baselines of ch. 5 Table 1.

Method: road pixels (semantic segmentation) within a metric box in front of the camera are back-projected with
the *raw* predicted depth; a plane n.X + c = 0 (|n| = 1) is fitted by Least Median of Squares; the camera
centre is at distance |c| from that plane in network units, so the metric scale is s = h / |c|.

Reading of ch. 5 eq. 5: the thesis prints alpha_I = c / h, but it defines the scale by d_I = alpha_I Phi(I)
(eq. 4: alpha = median gt / median prediction, metres per network unit). A road plane at distance c (network
units) below a camera mounted h metres above the road gives h = alpha c, i.e. alpha = h / c; we implement that
(the printed ratio is the reciprocal, i.e. the factor from metres to network units).

Coordinates: OpenCV camera frame (x right, y down, z forward); the road right below the camera is at Y = +h
(the thesis writes [0, -h, 0] with y up). Pixel filter of §3.3 / footnote 2: |X| < max_width and
Z < max_length, with X, Z obtained by intersecting the pixel ray with the flat road Y = +h (metric without
any depth; pixels at or above the horizon are dropped). Everything here is numpy and pure.
"""
from __future__ import annotations

from collections.abc import Iterable
from typing import NamedTuple

import numpy as np

from redsup.depth import evaluation


class Plane(NamedTuple):
    normal: np.ndarray  # (3,), unit; oriented so that offset >= 0 (points from the plane towards the camera)
    offset: float  # c in n.X + c = 0: distance of the camera centre from the plane
    inlier_mask: np.ndarray  # (N,) bool


def fit_plane_lmeds(points: np.ndarray, n_iter: int = 300, seed: int = 0, refine: bool = True,
                    chunk: int = 64) -> Plane:
    """Least Median of Squares plane (Rousseeuw 1984) with orthogonal residuals.

    ``n_iter`` random 3-point hypotheses (vectorised), the one with the smallest median squared residual wins.
    Inliers: |r| <= 2.5 s0 with Rousseeuw's robust scale s0 = 1.4826 (1 + 5 / (N - 3)) sqrt(med r^2).
    ``refine`` re-fits the plane to the inliers by total least squares (Rousseeuw's reweighted step) and
    recomputes the inliers. Needs at least 3 non-collinear points (ValueError otherwise).
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 3:
        raise ValueError(f"need an (N >= 3, 3) array of points, got shape {pts.shape}")
    n = len(pts)
    rng = np.random.default_rng(seed)
    idx = np.stack([rng.choice(n, 3, replace=False) for _ in range(n_iter)]) if n < 64 else \
        rng.integers(0, n, size=(n_iter, 3))
    a, b, c = pts[idx[:, 0]], pts[idx[:, 1]], pts[idx[:, 2]]
    normals = np.cross(b - a, c - a)
    norms = np.linalg.norm(normals, axis=1)
    scale = np.max(np.linalg.norm(pts - pts.mean(0), axis=1)) ** 2 + 1e-300
    ok = norms > 1e-9 * scale
    if not ok.any():
        raise ValueError("all sampled point triples are collinear")
    normals = normals[ok] / norms[ok, None]
    offsets = -np.einsum("ij,ij->i", normals, a[ok])
    best_med, best = np.inf, 0
    pts_t = np.ascontiguousarray(pts.T)
    for start in range(0, len(normals), chunk):
        res = normals[start:start + chunk] @ pts_t  # (chunk, N): medians along contiguous rows
        res += offsets[start:start + chunk, None]
        med = np.median(np.square(res, out=res), axis=1)
        j = int(np.argmin(med))
        if med[j] < best_med:
            best_med, best = float(med[j]), start + j
    normal, offset = normals[best], float(offsets[best])
    inliers = _inliers(pts, normal, offset, best_med)
    if refine and inliers.sum() >= 3:
        centroid = pts[inliers].mean(0)
        normal = np.linalg.svd(pts[inliers] - centroid, full_matrices=False)[2][-1]
        offset = float(-normal @ centroid)
        inliers = _inliers(pts, normal, offset, float(np.median((pts @ normal + offset) ** 2)))
    if offset < 0:
        normal, offset = -normal, -offset
    return Plane(normal, offset, inliers)


def _inliers(pts: np.ndarray, normal: np.ndarray, offset: float, med_sq: float) -> np.ndarray:
    s0 = 1.4826 * (1.0 + 5.0 / max(len(pts) - 3, 1)) * np.sqrt(med_sq)
    return np.abs(pts @ normal + offset) <= max(2.5 * s0, 1e-12)


def flat_road_coordinates(K: np.ndarray, height: int, width: int, camera_height: float) -> np.ndarray:
    """(H, W, 3) intersection of every pixel ray with the flat road Y = +camera_height (NaN at/above horizon)."""
    v, u = np.mgrid[0:height, 0:width].astype(np.float64)
    rays = np.stack([u, v, np.ones_like(u)], axis=-1) @ np.linalg.inv(np.asarray(K, dtype=np.float64)[:3, :3]).T
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(rays[..., 1] > 1e-9, camera_height / rays[..., 1], np.nan)
    return rays * t[..., None]


def road_selection(road_mask: np.ndarray, K: np.ndarray, camera_height: float, max_length: float = 30.0,
                   max_width: float = 3.0) -> np.ndarray:
    """Road pixels whose flat-road position has |X| < max_width and 0 < Z < max_length (ch. 5 Tables 3/4)."""
    mask = np.asarray(road_mask, dtype=bool)
    flat = flat_road_coordinates(K, *mask.shape, camera_height)
    with np.errstate(invalid="ignore"):
        box = (np.abs(flat[..., 0]) < max_width) & (flat[..., 2] > 0) & (flat[..., 2] < max_length)
    return mask & box


def road_points(depth: np.ndarray, road_mask: np.ndarray, K: np.ndarray, max_length: float = 30.0,
                max_width: float = 3.0, *, camera_height: float) -> np.ndarray:
    """(N, 3) camera-frame points of the selected road pixels, back-projected with the raw ``depth``."""
    depth = np.asarray(depth, dtype=np.float64)
    sel = road_selection(road_mask, K, camera_height, max_length, max_width) & np.isfinite(depth) & (depth > 0)
    v, u = np.nonzero(sel)
    rays = np.stack([u, v, np.ones_like(u)], axis=1).astype(np.float64) @ np.linalg.inv(
        np.asarray(K, dtype=np.float64)[:3, :3]).T
    return rays * depth[v, u][:, None]


def scale_from_camera_height(plane: Plane, camera_height: float) -> float:
    """Metric scale s = h / c (see the module docstring for the reading of ch. 5 eq. 5)."""
    if not (np.isfinite(plane.offset) and plane.offset > 0):
        raise ValueError(f"plane offset {plane.offset} must be positive and finite")
    return float(camera_height) / float(plane.offset)


def plane_tilt_deg(normal: np.ndarray) -> float:
    """Angle (degrees) between a plane normal and the camera's up axis -y (either orientation)."""
    n = np.asarray(normal, dtype=np.float64)
    return float(np.degrees(np.arccos(min(1.0, abs(float(n[1])) / max(float(np.linalg.norm(n)), 1e-300)))))


def calibrate_frame(depth: np.ndarray, road_mask: np.ndarray, K: np.ndarray, camera_height: float, *,
                    max_length: float = 30.0, max_width: float = 3.0, min_points: int = 20, n_iter: int = 300,
                    seed: int = 0, max_tilt_deg: float | None = None) -> tuple[float | None, str | None]:
    """Our method for one frame: (scale, None) or (None, reason) when no plane can be fitted.

    Reasons: too few selected road points, a degenerate fit (collinear points, zero offset: the plane passes
    through the camera) or, with ``max_tilt_deg``, a plane whose normal is tilted more than that from the
    camera's vertical (a wall or a car fitted instead of the road).
    """
    pts = road_points(depth, road_mask, K, max_length, max_width, camera_height=camera_height)
    if len(pts) < min_points:
        return None, f"{len(pts)} road points within |X| < {max_width:g} m, Z < {max_length:g} m (< {min_points})"
    try:
        plane = fit_plane_lmeds(pts, n_iter=n_iter, seed=seed)
        if max_tilt_deg is not None and plane_tilt_deg(plane.normal) > max_tilt_deg:
            return None, (f"degenerate road plane: normal {plane_tilt_deg(plane.normal):.1f} deg from the camera's "
                          f"vertical (> {max_tilt_deg:g})")
        return scale_from_camera_height(plane, camera_height), None
    except ValueError as err:
        return None, f"degenerate road plane: {err}"


def fixed_plane_scale(depth: np.ndarray, road_mask: np.ndarray, K: np.ndarray, camera_height: float, *,
                      max_length: float = 30.0, max_width: float = 3.0) -> tuple[float | None, str | None]:
    """Baseline (c) of ch. 5 Table 1: the road is the horizontal plane at the canonical camera height; its
    depths are pseudo ground truth for median scaling on the selected road pixels."""
    depth = np.asarray(depth, dtype=np.float64)
    sel = road_selection(road_mask, K, camera_height, max_length, max_width) & np.isfinite(depth) & (depth > 0)
    if not sel.any():
        return None, f"no road pixel within {max_width} m x {max_length} m"
    pseudo = flat_road_coordinates(K, *sel.shape, camera_height)[..., 2]
    return evaluation.median_scale(pseudo, depth, sel), None


def per_frame_gt_scale(gt_depth: np.ndarray, pred_depth: np.ndarray, *, min_depth: float = 1e-3,
                       max_depth: float = 80.0, crop: str | None = "garg") -> tuple[float | None, str | None]:
    """Reference row: the per-frame GT median ratio (ch. 5 eq. 4) on the evaluation pixels; also ch. 5 Fig. 1."""
    mask = evaluation.valid_mask(gt_depth, min_depth=min_depth, max_depth=max_depth, crop=crop)
    mask &= np.isfinite(pred_depth) & (np.asarray(pred_depth) > 0)
    if not mask.any():
        return None, "no valid ground-truth pixel"
    return evaluation.median_scale(gt_depth, pred_depth, mask), None


def single_gt_scale(pairs: Iterable[tuple[np.ndarray, np.ndarray]], **kwargs) -> tuple[float, int]:
    """Baselines (a)/(b) of ch. 5 Table 1: one factor for a set of frames (train or test), the median of the
    per-frame GT ratios (as Monodepth2 reports it). ``pairs`` yields (gt, pred); returns (scale, frames used)."""
    ratios = [r for r, _ in (per_frame_gt_scale(gt, pred, **kwargs) for gt, pred in pairs) if r is not None]
    if not ratios:
        raise ValueError("no frame with valid ground truth to compute a single scale")
    return float(np.median(ratios)), len(ratios)
