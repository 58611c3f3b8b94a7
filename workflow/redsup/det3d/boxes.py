"""Box geometry: corners, rotated-box IoU in the ground plane (BEV) and in 3D, 2D image-box overlap.

Boxes are (N, 7) float arrays (x, y, z, l, w, h, yaw): geometric centre in the vehicle frame (x forward,
y left, z up), length along the heading, width across it, height along z, yaw about +z (0 = facing +x).

BEV intersection of two rotated rectangles (both convex) is computed in plain vectorised numpy: the
intersection polygon's vertices are the corners of each rectangle that lie inside the other plus the
crossings of their edges (at most 4 + 4 + 16 candidates); the valid candidates are sorted by angle around
their centroid and the shoelace formula gives the area. `benchmarks/bench_det3d.py` compares it with
shapely 2's vectorised `intersection` + `area`: numpy took 5 us per overlapping pair vs 21 us for shapely
(20k pairs), 41 vs 123 ms for a 500 x 500 scene, and the two agree to 1e-12 m^2, so numpy is the default
and shapely stays available as `method="shapely"` for cross-checks.

Pairwise matrices (N x M) first drop pairs whose circumscribed circles do not touch, then evaluate the
remaining pairs at once, so sparse scenes cost little. Non-finite boxes give IoU 0.
"""
from __future__ import annotations

import numpy as np

from redsup import geometry

_EPS = 1e-9


def _as_boxes(boxes) -> np.ndarray:
    arr = np.asarray(boxes, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 7:
        raise ValueError(f"boxes must be (N, 7) (x, y, z, l, w, h, yaw), got shape {arr.shape}")
    return arr


def bev_corners(boxes) -> np.ndarray:
    """(N, 4, 2) ground-plane corners, counter-clockwise: front-left, rear-left, rear-right, front-right."""
    b = _as_boxes(boxes)
    half_l, half_w = b[:, 3] / 2, b[:, 4] / 2
    local_x = np.stack([half_l, -half_l, -half_l, half_l], axis=1)
    local_y = np.stack([half_w, half_w, -half_w, -half_w], axis=1)
    c, s = np.cos(b[:, 6])[:, None], np.sin(b[:, 6])[:, None]
    x = b[:, 0:1] + c * local_x - s * local_y
    y = b[:, 1:2] + s * local_x + c * local_y
    return np.stack([x, y], axis=-1)


def box_corners_3d(boxes) -> np.ndarray:
    """(N, 8, 3) corners: the 4 bottom corners (order of `bev_corners`) then the 4 top corners."""
    b = _as_boxes(boxes)
    xy = bev_corners(b)
    z0 = (b[:, 2] - b[:, 5] / 2)[:, None, None]
    z1 = (b[:, 2] + b[:, 5] / 2)[:, None, None]
    bottom = np.concatenate([xy, np.broadcast_to(z0, xy.shape[:2] + (1,))], axis=-1)
    top = np.concatenate([xy, np.broadcast_to(z1, xy.shape[:2] + (1,))], axis=-1)
    return np.concatenate([bottom, top], axis=1)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _inside_convex(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """(P, K) bool: points (P, K, 2) inside or on the counter-clockwise convex polygons (P, 4, 2)."""
    edge = np.roll(poly, -1, axis=1) - poly                          # (P, 4, 2)
    rel = points[:, :, None, :] - poly[:, None, :, :]                  # (P, K, 4, 2)
    side = _cross(edge[:, None, :, :], rel)                            # (P, K, 4)
    scale = np.linalg.norm(edge, axis=-1)[:, None, :] + _EPS
    return (side / scale >= -1e-9).all(axis=-1)


def _intersection_area_numpy(ca: np.ndarray, cb: np.ndarray) -> np.ndarray:
    """Areas (P,) of the intersections of aligned pairs of counter-clockwise convex quads (P, 4, 2)."""
    p = len(ca)
    if p == 0:
        return np.zeros(0)
    a_in_b = _inside_convex(ca, cb)                                    # (P, 4)
    b_in_a = _inside_convex(cb, ca)
    # edge crossings: edge i of a (a_i -> a_i+1) with edge j of b
    a0, da = ca, np.roll(ca, -1, axis=1) - ca                          # (P, 4, 2)
    b0, db = cb, np.roll(cb, -1, axis=1) - cb
    denom = _cross(da[:, :, None, :], db[:, None, :, :])               # (P, 4, 4)
    diff = b0[:, None, :, :] - a0[:, :, None, :]                       # (P, 4, 4, 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = _cross(diff, db[:, None, :, :]) / denom
        u = _cross(diff, da[:, :, None, :]) / denom
    tol = 1e-9
    cross_ok = (np.abs(denom) > 1e-12) & (t >= -tol) & (t <= 1 + tol) & (u >= -tol) & (u <= 1 + tol)
    t = np.where(cross_ok, t, 0.0)
    cross_pts = a0[:, :, None, :] + t[..., None] * da[:, :, None, :]   # (P, 4, 4, 2)
    pts = np.concatenate([ca, cb, cross_pts.reshape(p, 16, 2)], axis=1)             # (P, 24, 2)
    valid = np.concatenate([a_in_b, b_in_a, cross_ok.reshape(p, 16)], axis=1)       # (P, 24)
    pts = np.where(valid[..., None], pts, 0.0)
    count = valid.sum(axis=1)
    centre = pts.sum(axis=1) / np.maximum(count, 1)[:, None]
    rel = pts - centre[:, None, :]
    angle = np.where(valid, np.arctan2(rel[..., 1], rel[..., 0]), np.inf)
    order = np.argsort(angle, axis=1)
    rel = np.take_along_axis(rel, order[..., None], axis=1)
    valid = np.take_along_axis(valid, order, axis=1)
    # invalid slots (sorted last) repeat the first vertex: they add zero area to the closed fan
    rel = np.where(valid[..., None], rel, rel[:, :1, :])
    area = 0.5 * _cross(rel, np.roll(rel, -1, axis=1)).sum(axis=1)
    return np.where(count >= 3, np.abs(area), 0.0)


def _intersection_area_shapely(ca: np.ndarray, cb: np.ndarray) -> np.ndarray:
    import shapely  # local import: only the cross-check / benchmark path needs it

    pa = shapely.polygons(ca)
    pb = shapely.polygons(cb)
    return shapely.area(shapely.intersection(pa, pb))


def bev_intersection_pairs(a, b, method: str = "numpy") -> np.ndarray:
    """(P,) ground-plane intersection areas of aligned box pairs a[i], b[i] (each (P, 7))."""
    a, b = _as_boxes(a), _as_boxes(b)
    if a.shape != b.shape:
        raise ValueError(f"aligned pairs need equal shapes, got {a.shape} and {b.shape}")
    ok = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
    out = np.zeros(len(a))
    if ok.any():
        ca, cb = bev_corners(a[ok]), bev_corners(b[ok])
        if method == "numpy":
            out[ok] = _intersection_area_numpy(ca, cb)
        elif method == "shapely":
            out[ok] = _intersection_area_shapely(ca, cb)
        else:
            raise ValueError(f"method must be 'numpy' or 'shapely', got {method!r}")
    return out


def _vertical_overlap(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    top = np.minimum(a[:, 2] + a[:, 5] / 2, b[:, 2] + b[:, 5] / 2)
    bottom = np.maximum(a[:, 2] - a[:, 5] / 2, b[:, 2] - b[:, 5] / 2)
    return np.maximum(top - bottom, 0.0)


def overlap_pairs(a, b, kind: str = "bev", criterion: int = -1, method: str = "numpy") -> np.ndarray:
    """(P,) overlap of aligned pairs in the ground plane (`kind="bev"`) or in 3D (`kind="3d"`).

    criterion -1: intersection over union; 0: intersection over the size of a; 1: over the size of b
    (the KITTI devkit's convention, used for DontCare regions). 3D intersection = BEV intersection x
    vertical overlap.
    """
    a, b = _as_boxes(a), _as_boxes(b)
    inter = bev_intersection_pairs(a, b, method=method)
    size_a, size_b = a[:, 3] * a[:, 4], b[:, 3] * b[:, 4]
    if kind == "3d":
        inter = inter * _vertical_overlap(a, b)
        size_a, size_b = size_a * a[:, 5], size_b * b[:, 5]
    elif kind != "bev":
        raise ValueError(f"kind must be 'bev' or '3d', got {kind!r}")
    if criterion == -1:
        denom = size_a + size_b - inter
    elif criterion == 0:
        denom = size_a
    elif criterion == 1:
        denom = size_b
    else:
        raise ValueError(f"criterion must be -1, 0 or 1, got {criterion}")
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(denom > 0, inter / np.where(denom > 0, denom, 1.0), 0.0)
    return np.nan_to_num(out, nan=0.0)


def candidate_pairs(a, b) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs (i, j) of boxes of a (N, 7) and b (M, 7) whose circumscribed BEV circles touch."""
    a, b = _as_boxes(a), _as_boxes(b)
    ra = 0.5 * np.hypot(a[:, 3], a[:, 4])
    rb = 0.5 * np.hypot(b[:, 3], b[:, 4])
    d2 = (a[:, None, 0] - b[None, :, 0]) ** 2 + (a[:, None, 1] - b[None, :, 1]) ** 2
    close = d2 <= (ra[:, None] + rb[None, :]) ** 2      # NaN compares False
    return np.nonzero(close)


def overlap_matrix(a, b, kind: str = "bev", criterion: int = -1, method: str = "numpy") -> np.ndarray:
    """(N, M) pairwise overlap (see `overlap_pairs`) between boxes a (N, 7) and b (M, 7)."""
    a, b = _as_boxes(a), _as_boxes(b)
    out = np.zeros((len(a), len(b)))
    i, j = candidate_pairs(a, b)
    if len(i):
        out[i, j] = overlap_pairs(a[i], b[j], kind=kind, criterion=criterion, method=method)
    return out


def bev_iou(a, b, method: str = "numpy") -> np.ndarray:
    """(N, M) IoU of rotated boxes in the ground plane."""
    return overlap_matrix(a, b, kind="bev", method=method)


def iou_3d(a, b, method: str = "numpy") -> np.ndarray:
    """(N, M) 3D IoU = BEV intersection x vertical overlap / union of volumes."""
    return overlap_matrix(a, b, kind="3d", method=method)


def image_box_overlap(a, b, criterion: int = -1) -> np.ndarray:
    """(..., N, M) overlap of 2D boxes (x1, y1, x2, y2) a (..., N, 4) and b (..., M, 4) as the KITTI
    devkit computes it (no +1 on widths); leading dimensions broadcast.

    criterion -1: IoU; 0: intersection / area(a); 1: intersection / area(b). Non-finite boxes give 0.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    a = a[None] if a.ndim == 1 else a
    b = b[None] if b.ndim == 1 else b
    A, Bq = a[..., :, None, :], b[..., None, :, :]
    iw = np.minimum(A[..., 2], Bq[..., 2]) - np.maximum(A[..., 0], Bq[..., 0])
    ih = np.minimum(A[..., 3], Bq[..., 3]) - np.maximum(A[..., 1], Bq[..., 1])
    inter = np.where((iw > 0) & (ih > 0), iw * ih, 0.0)
    area_a = (A[..., 2] - A[..., 0]) * (A[..., 3] - A[..., 1])
    area_b = (Bq[..., 2] - Bq[..., 0]) * (Bq[..., 3] - Bq[..., 1])
    if criterion == -1:
        denom = area_a + area_b - inter
    elif criterion == 0:
        denom = np.broadcast_to(area_a, inter.shape)
    elif criterion == 1:
        denom = np.broadcast_to(area_b, inter.shape)
    else:
        raise ValueError(f"criterion must be -1, 0 or 1, got {criterion}")
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(inter > 0, inter / denom, 0.0)
    return np.nan_to_num(out, nan=0.0)


def overlap_matrix_batched(a: np.ndarray, b: np.ndarray, kind: str = "bev", criterion: int = -1,
                           method: str = "numpy") -> np.ndarray:
    """(F, N, M) overlap of padded per-frame box sets a (F, N, 7) and b (F, M, 7) within each frame;
    NaN rows (padding) give 0. All candidate pairs of all frames are evaluated in one call."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    out = np.zeros(a.shape[:2] + (b.shape[1],))
    ra = 0.5 * np.hypot(a[..., 3], a[..., 4])
    rb = 0.5 * np.hypot(b[..., 3], b[..., 4])
    d2 = (a[:, :, None, 0] - b[:, None, :, 0]) ** 2 + (a[:, :, None, 1] - b[:, None, :, 1]) ** 2
    f, i, j = np.nonzero(d2 <= (ra[:, :, None] + rb[:, None, :]) ** 2)
    if len(f):
        out[f, i, j] = overlap_pairs(a[f, i], b[f, j], kind=kind, criterion=criterion, method=method)
    return out


def boxes_to_image_bbox(boxes, T_camera_vehicle: np.ndarray, K: np.ndarray, image_size: tuple[int, int],
                        min_depth: float = 0.1) -> np.ndarray:
    """(N, 4) image boxes (x1, y1, x2, y2) enclosing the projected corners of vehicle-frame 3D boxes,
    clipped to the image (width, height); NaN rows for boxes with no corner in front of the camera or
    entirely outside the image. Corners behind `min_depth` are dropped (KITTI-style approximation)."""
    b = _as_boxes(boxes)
    out = np.full((len(b), 4), np.nan)
    if len(b) == 0:
        return out
    corners = box_corners_3d(b).reshape(-1, 3)
    cam = geometry.transform_points(np.asarray(T_camera_vehicle, dtype=np.float64), corners)
    uv, z = geometry.project(np.asarray(K, dtype=np.float64), cam)
    uv, z = uv.reshape(len(b), 8, 2), z.reshape(len(b), 8)
    front = z > min_depth
    has = front.any(axis=1)
    width, height = image_size
    x1 = np.clip(np.where(front, uv[..., 0], np.inf).min(axis=1), 0, width - 1)
    x2 = np.clip(np.where(front, uv[..., 0], -np.inf).max(axis=1), 0, width - 1)
    y1 = np.clip(np.where(front, uv[..., 1], np.inf).min(axis=1), 0, height - 1)
    y2 = np.clip(np.where(front, uv[..., 1], -np.inf).max(axis=1), 0, height - 1)
    box = np.stack([x1, y1, x2, y2], axis=1)
    keep = has & (x2 > x1) & (y2 > y1)
    out[keep] = box[keep]
    return out
