"""A simulated Mask R-CNN (class car) standing in for the pretrained 2D instance segmenter of McCraith ch. 6.

Derived from the ground-truth instance buffer with the faults real detectors make, at a quality level
from config (`coco`: generic, `cityscapes`: driving domain, ch. 6 Table III):
- misses: probability rising as the visible pixel count and the visible fraction fall;
- merged neighbours: touching / overlapping detected instances merged into one mask;
- boundary errors: a random per-mask dilation (> 0) or erosion (< 0) plus ragged edge pixels;
- false positives: blobs on background labels (facades, vegetation, poles), scored like detections with a
  lower logit offset;
- a confidence score that never sees the true instance: a logistic function of what a detector can know,
  the detected mask's size and its instance's visible fraction, and of a latent per-detection quality ``u``
  (how clearly the network sees the object), plus score noise. The same latent scales the mask's boundary
  faults (``mask_quality_coupling``), so the score correlates with the mask's true IoU without being computed
  from it (see ``score_of``). Measured on rendered kitti_like training scenes (tests/test_detection_score.py):
  Spearman rank correlation between score and the best IoU with a ground-truth car 0.69 (coco) / 0.71
  (cityscapes) over all output detections, false positives included (6 scenes x 4 frames); detections
  scoring >= 0.8 have IoU >= 0.5 in 96-100 % of cases, those in 0.4-0.6 in 45-67 %.
Pixel-valued settings are given at `reference_height` and scaled with the image height. Deterministic
given the seed: every frame draws from its own stream `SeedSequence([seed, frame])`.
"""
from __future__ import annotations

import cv2
import numpy as np

SILHOUETTE_FILL = 0.8  # share of a car's projected 3D-box rectangle its silhouette covers, unoccluded
KIND_SINGLE, KIND_MERGED, KIND_FALSE_POSITIVE = 0, 1, 2


def _disk(radius: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


def _window(mask: np.ndarray, pad: int) -> tuple[slice, slice]:
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    height, width = mask.shape
    return (slice(max(rows[0] - pad, 0), min(rows[-1] + pad + 1, height)),
            slice(max(cols[0] - pad, 0), min(cols[-1] + pad + 1, width)))


def miss_probability(visible_px: float, visible_fraction: float, level: dict, scale: float = 1.0) -> float:
    """P(instance not detected) = 1 - (1 - base)(1 - p_small)(1 - p_occluded).

    p_small = 1 / (1 + (px / miss_small_px)^2): one half at `miss_small_px` visible pixels (scaled by
    scale^2); p_occluded = 1 / (1 + (fraction / miss_occluded_fraction)^3): one half at that visible
    fraction. A zero setting switches its term off.
    """
    small_px = level["miss_small_px"] * scale ** 2
    p_small = 0.0 if small_px <= 0 else 1.0 / (1.0 + (visible_px / small_px) ** 2)
    frac = level["miss_occluded_fraction"]
    p_occ = 0.0 if frac <= 0 else 1.0 / (1.0 + (max(visible_fraction, 0.0) / frac) ** 3)
    return float(1.0 - (1.0 - level["miss_base"]) * (1.0 - p_small) * (1.0 - p_occ))


def perturb_boundary(mask: np.ndarray, offset_px: int, edge_flip: float, rng: np.random.Generator) -> np.ndarray:
    """Dilate (offset > 0) or erode (offset < 0) by |offset| px with a disk, then flip each pixel of the
    one-pixel band around the boundary with probability `edge_flip`. Returns a new full-size mask."""
    out = np.zeros_like(mask)
    if not mask.any():
        return out
    window = _window(mask, abs(offset_px) + 2)
    m = mask[window].astype(np.uint8)
    if offset_px > 0:
        m = cv2.dilate(m, _disk(offset_px))
    elif offset_px < 0:
        m = cv2.erode(m, _disk(-offset_px))  # image borders do not erode: truncated cars stay cut off
    if edge_flip > 0 and m.any():
        kernel = np.ones((3, 3), np.uint8)
        band = cv2.dilate(m, kernel) != cv2.erode(m, kernel)
        flip = band & (rng.random(m.shape) < edge_flip)
        m[flip] ^= 1
    out[window] = m.astype(bool)
    return out


def adjacent_pairs(masks: list[np.ndarray], gap_px: int) -> list[tuple[int, int]]:
    """Index pairs (i < j) of masks that overlap or come within `gap_px` pixels of each other."""
    boxes = []
    for m in masks:
        rows = np.flatnonzero(m.any(axis=1))
        cols = np.flatnonzero(m.any(axis=0))
        boxes.append((rows[0], rows[-1], cols[0], cols[-1]))
    pairs = []
    for i in range(len(masks)):
        for j in range(i + 1, len(masks)):
            a, b = boxes[i], boxes[j]
            if a[0] > b[1] + gap_px + 1 or b[0] > a[1] + gap_px + 1 or a[2] > b[3] + gap_px + 1 \
                    or b[2] > a[3] + gap_px + 1:
                continue
            window = _window(masks[i], gap_px + 1)
            grown = cv2.dilate(masks[i][window].astype(np.uint8), _disk(gap_px + 1)).astype(bool)
            if (grown & masks[j][window]).any():
                pairs.append((i, j))
    return pairs


def merge_groups(n: int, pairs: list[tuple[int, int]], merge_prob: float,
                 rng: np.random.Generator) -> list[list[int]]:
    """Groups of indices after merging each adjacent pair with probability `merge_prob` (transitively)."""
    parent = list(range(n))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    draws = rng.random(len(pairs))
    for (i, j), draw in zip(pairs, draws):
        if draw < merge_prob:
            parent[root(j)] = root(i)
    groups: dict[int, list[int]] = {}
    for i in range(n):
        groups.setdefault(root(i), []).append(i)
    return sorted(groups.values())


def score_of(visible_px: float, visible_fraction: float, latent: float, level: dict, rng: np.random.Generator,
             scale: float = 1.0, offset: float = 0.0) -> float:
    """Confidence of one detection: sigmoid(logit) with

        logit = score_bias + offset + score_size_gain * log2(px / (score_size_px * scale^2))
                + score_visibility_gain * (visible_fraction - 1) + score_latent_gain * latent + N(0, score_noise)

    (px: the detected mask's pixels; ``offset``: ``fp_score_offset`` for false positives). Nothing here
    depends on the ground-truth mask; clipped to [0.001, 0.999]."""
    size_px = max(level["score_size_px"] * scale ** 2, 1e-9)
    logit = (level["score_bias"] + offset + level["score_size_gain"] * np.log2(max(visible_px, 1.0) / size_px)
             + level["score_visibility_gain"] * (min(max(visible_fraction, 0.0), 1.0) - 1.0)
             + level["score_latent_gain"] * latent)
    if level["score_noise"] > 0:
        logit += rng.normal(0.0, level["score_noise"])
    return float(np.clip(1.0 / (1.0 + np.exp(-logit)), 0.001, 0.999))


def fault_scale(latent: float, coupling: float) -> float:
    """Factor on a detection's boundary faults from its latent quality: exp(-c u - c^2 / 2), mean 1 over
    u ~ N(0, 1), smaller for a clearly seen object (u > 0)."""
    return float(np.exp(-coupling * latent - 0.5 * coupling * coupling))


def false_positive_masks(instance: np.ndarray, semantic: np.ndarray | None, level: dict,
                         rng: np.random.Generator, scale: float) -> list[np.ndarray]:
    """Elliptic blobs centred on a random pixel of a background label in `fp_labels`, kept off objects.
    Their number per frame is Poisson(fp_per_frame)."""
    n = rng.poisson(level["fp_per_frame"]) if level["fp_per_frame"] > 0 else 0
    if n == 0:
        return []
    free = instance == 0
    if semantic is not None:
        free &= np.isin(semantic, level["fp_labels"])
    rows, cols = np.nonzero(free)
    if len(rows) == 0:
        return []
    out = []
    lo, hi = level["fp_height_px"]
    for _ in range(n):
        k = rng.integers(len(rows))
        half_h = max(1, int(round(rng.uniform(lo, hi) * scale / 2)))
        half_w = max(1, int(round(half_h * rng.uniform(0.8, 2.0))))
        blob = np.zeros(instance.shape, dtype=np.uint8)
        cv2.ellipse(blob, (int(cols[k]), int(rows[k])), (half_w, half_h), float(rng.uniform(0, 180)),
                    0, 360, 1, thickness=-1)
        blob = blob.astype(bool) & (instance == 0)
        if blob.any():
            out.append(blob)
    return out


def simulate_frame(instance: np.ndarray, semantic: np.ndarray | None, objects: list[dict], level: dict,
                   rng: np.random.Generator, scale: float) -> tuple[list[dict], dict]:
    """Detections of one frame.

    objects: one dict per ground-truth car visible in the frame: `track`, `visible_fraction`
    (`visible_px` is counted on the buffer). Returns (detections, counts); a detection is a dict with
    `mask` (H, W) bool, `score`, `kind` (KIND_*), `members` (tracks merged into it, empty for a false
    positive).
    """
    masks = [instance == obj["track"] for obj in objects]
    counts = {"gt": len(objects), "missed": 0, "eroded_away": 0, "merged_groups": 0, "false_positive": 0}
    kept = []
    for i, (obj, m) in enumerate(zip(objects, masks)):
        p = miss_probability(np.count_nonzero(m), obj["visible_fraction"], level, scale)
        if rng.random() < p:
            counts["missed"] += 1
        else:
            kept.append(i)
    kept_masks = [masks[i] for i in kept]
    groups = merge_groups(len(kept), adjacent_pairs(kept_masks, int(round(level["merge_gap_px"] * scale))),
                          level["merge_prob"], rng)
    detections = []
    for group in groups:
        members = [kept[g] for g in group]
        union = np.logical_or.reduce([masks[i] for i in members])
        main = max(members, key=lambda i: np.count_nonzero(masks[i]))
        latent = float(rng.standard_normal())
        fault = fault_scale(latent, level["mask_quality_coupling"])
        offset = int(np.round(rng.normal(level["boundary_mean_px"], level["boundary_std_px"]) * fault * scale))
        mask = perturb_boundary(union, offset, min(level["edge_flip"] * fault, 1.0), rng)
        if not mask.any():
            counts["eroded_away"] += 1
            continue
        kind = KIND_MERGED if len(members) > 1 else KIND_SINGLE
        counts["merged_groups"] += kind == KIND_MERGED
        score = score_of(np.count_nonzero(mask), objects[main]["visible_fraction"], latent, level, rng, scale)
        detections.append({"mask": mask, "score": score, "kind": kind,
                           "members": [objects[i]["track"] for i in members]})
    for blob in false_positive_masks(instance, semantic, level, rng, scale):
        mask = perturb_boundary(blob, 0, level["edge_flip"], rng)
        if mask.any():
            counts["false_positive"] += 1
            score = score_of(np.count_nonzero(mask), 1.0, float(rng.standard_normal()), level, rng, scale,
                             offset=level["fp_score_offset"])
            detections.append({"mask": mask, "score": score, "kind": KIND_FALSE_POSITIVE, "members": []})
    return detections, counts


def match_to_gt(mask: np.ndarray, instance: np.ndarray, tracks: list[int], min_iou: float) -> tuple[int, float]:
    """(track id of the best-IoU ground-truth mask among `tracks`, that IoU); track -1 below `min_iou`."""
    ids, inter = np.unique(instance[mask], return_counts=True)
    area = np.count_nonzero(mask)
    best, best_iou = -1, 0.0
    for track, n in zip(ids, inter):
        if track == 0 or int(track) not in tracks:
            continue
        iou = n / (area + np.count_nonzero(instance == track) - n)
        if iou > best_iou:
            best, best_iou = int(track), float(iou)
    return (best if best_iou >= min_iou else -1), best_iou
