"""KITTI Eigen-split depth evaluation as used by Monodepth2 and McCraith ch. 4 §4.2 / ch. 5 (numpy, pure).

Per frame: valid pixels are min_depth < gt < max_depth inside the Garg crop; the prediction is multiplied by
``fixed_scale`` (stereo models: the known-baseline factor) and/or by the per-image median ratio
median(gt) / median(pred) (monocular models), then clamped to [min_depth, max_depth]; the seven metrics are
computed on the valid pixels. Datasets average the per-frame metrics (``aggregate``). A frame that cannot be
evaluated is returned as ``FrameEval(None, reason)`` and counted by ``aggregate``, never turned into NaN.

Named protocols (``protocol=`` of `valid_mask` / `evaluate_frame`, `PROTOCOLS`; they replace min/max depth
and crop):

- ``eigen``: Monodepth2's ``eigen`` split: 1e-3 < gt < 80 m inside the Garg crop, prediction clamped to
  [1e-3, 80] m.
- ``eigen_benchmark``: Monodepth2's ``eigen_benchmark`` split (improved ground truth): every ``gt > 0``
  pixel, no crop, no range cap on the ground truth (the prediction is still clamped to [1e-3, 80] m, as
  Monodepth2's ``evaluate_depth.py`` does for every split).
- ``ddad``, ``lyft``: Galteland (2021): 0.1 < gt < 80 m, no crop, prediction clamped to [0.1, 80] m.

Without a protocol the explicit ``min_depth`` / ``max_depth`` / ``crop`` apply (range on gt and clamp).
"""
from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import NamedTuple

import numpy as np

GARG_CROP = (0.40810811, 0.99189189, 0.03594771, 0.96405229)  # rows top/bottom, cols left/right (fractions)
METRICS = ("abs_rel", "sq_rel", "rmse", "rmse_log", "a1", "a2", "a3")


class Protocol(NamedTuple):
    min_depth: float     # prediction clamp (and gt range when cap_gt)
    max_depth: float
    crop: str | None
    cap_gt: bool         # False: every gt > 0 pixel is valid (eigen_benchmark)


PROTOCOLS = {
    "eigen": Protocol(1e-3, 80.0, "garg", True),
    "eigen_benchmark": Protocol(1e-3, 80.0, None, False),
    "ddad": Protocol(0.1, 80.0, None, True),
    "lyft": Protocol(0.1, 80.0, None, True),
}


def protocol(name: str) -> Protocol:
    try:
        return PROTOCOLS[name]
    except KeyError:
        raise ValueError(f"unknown depth evaluation protocol {name!r}; expected one of {sorted(PROTOCOLS)}") from None


class FrameEval(NamedTuple):
    metrics: dict | None
    reason: str | None


def garg_crop_mask(height: int, width: int) -> np.ndarray:
    """Boolean (H, W) mask of the Garg et al. crop, with Monodepth2's integer truncation."""
    top, bottom, left, right = (np.array(GARG_CROP) * [height, height, width, width]).astype(np.int32)
    mask = np.zeros((height, width), dtype=bool)
    mask[top:bottom, left:right] = True
    return mask


def compute_depth_metrics(gt: np.ndarray, pred: np.ndarray) -> dict[str, float]:
    """The seven Eigen metrics on matching 1-D arrays of positive depths (Monodepth2's ``compute_errors``)."""
    gt = np.asarray(gt, dtype=np.float64)
    pred = np.asarray(pred, dtype=np.float64)
    thresh = np.maximum(gt / pred, pred / gt)
    return {
        "abs_rel": float(np.mean(np.abs(gt - pred) / gt)),
        "sq_rel": float(np.mean((gt - pred) ** 2 / gt)),
        "rmse": float(np.sqrt(np.mean((gt - pred) ** 2))),
        "rmse_log": float(np.sqrt(np.mean((np.log(gt) - np.log(pred)) ** 2))),
        "a1": float(np.mean(thresh < 1.25)),
        "a2": float(np.mean(thresh < 1.25 ** 2)),
        "a3": float(np.mean(thresh < 1.25 ** 3)),
    }


def valid_mask(gt_depth: np.ndarray, *, min_depth: float = 1e-3, max_depth: float = 80.0, crop: str | None = "garg",
               protocol_name: str | None = None) -> np.ndarray:
    """GT pixels used for evaluation: finite, inside (min_depth, max_depth), inside the crop; with a named
    protocol its own rule (`PROTOCOLS`)."""
    gt = np.asarray(gt_depth)
    cap = True
    if protocol_name is not None:
        min_depth, max_depth, crop, cap = protocol(protocol_name)
    with np.errstate(invalid="ignore"):
        mask = np.isfinite(gt) & ((gt > min_depth) & (gt < max_depth) if cap else gt > 0)
    if crop == "garg":
        mask &= garg_crop_mask(*gt.shape)
    elif crop is not None:
        raise ValueError(f"unknown crop {crop!r} (use 'garg' or None)")
    return mask


def median_scale(gt_depth: np.ndarray, pred_depth: np.ndarray, mask: np.ndarray) -> float:
    """median(gt) / median(pred) over ``mask`` (ch. 5 eq. 4): the per-frame GT scale factor."""
    return float(np.median(np.asarray(gt_depth)[mask]) / np.median(np.asarray(pred_depth)[mask]))


def evaluate_frame(gt_depth: np.ndarray, pred_depth: np.ndarray, *, min_depth: float = 1e-3, max_depth: float = 80.0,
                   median_scaling: bool = True, fixed_scale: float | None = None, crop: str | None = "garg",
                   protocol_name: str | None = None) -> FrameEval:
    """Metrics of one frame, or ``FrameEval(None, reason)``. ``pred_depth`` must already be at GT resolution.

    The returned dict holds the seven metrics, ``scale`` (total factor applied to the prediction),
    ``median_ratio`` (the GT median ratio, 1.0 without median scaling) and ``n_valid`` (pixels evaluated).
    """
    gt = np.asarray(gt_depth, dtype=np.float64)
    pred = np.asarray(pred_depth, dtype=np.float64)
    if gt.shape != pred.shape:
        raise ValueError(f"prediction {pred.shape} and ground truth {gt.shape} differ; resize the prediction first")
    if protocol_name is not None:
        min_depth, max_depth, crop, _ = protocol(protocol_name)
    mask = valid_mask(gt, min_depth=min_depth, max_depth=max_depth, crop=crop, protocol_name=protocol_name)
    if not mask.any():
        return FrameEval(None, f"no valid ground-truth pixel in ({min_depth}, {max_depth}) m"
                               + (" inside the Garg crop" if crop else "")
                               + (f" (protocol {protocol_name})" if protocol_name else ""))
    gt_v, pred_v = gt[mask], pred[mask]
    if not np.all(np.isfinite(pred_v)):
        return FrameEval(None, f"{int(np.sum(~np.isfinite(pred_v)))} non-finite predicted depths")
    scale = 1.0 if fixed_scale is None else float(fixed_scale)
    pred_v = pred_v * scale
    ratio = 1.0
    if median_scaling:
        med = np.median(pred_v)
        if not med > 0:
            return FrameEval(None, f"median predicted depth {med} is not positive")
        ratio = float(np.median(gt_v) / med)
        pred_v = pred_v * ratio
    pred_v = np.clip(pred_v, min_depth, max_depth)
    metrics = compute_depth_metrics(gt_v, pred_v)
    metrics.update(scale=scale * ratio, median_ratio=ratio, n_valid=int(mask.sum()))
    return FrameEval(metrics, None)


def aggregate(results: Iterable[Mapping | FrameEval | None]) -> dict:
    """Per-image mean of every numeric key; skipped frames (``None`` or ``FrameEval(None, ...)``) are counted.

    Returns ``n_frames`` (evaluated) and ``n_skipped``; with no evaluated frame only the counts are returned.
    """
    rows, skipped = [], 0
    for r in results:
        if isinstance(r, FrameEval):
            r = r.metrics
        if r is None:
            skipped += 1
        else:
            rows.append(r)
    out: dict = {}
    if rows:
        keys = [k for k in rows[0] if all(isinstance(row.get(k), (int, float)) for row in rows)]
        out = {k: float(np.mean([row[k] for row in rows])) for k in keys}
    out.update(n_frames=len(rows), n_skipped=skipped)
    return out
