"""Average precision exactly as the KITTI object benchmark (devkit `evaluate_object.cpp` and its common
python port), vectorised over frames and score thresholds.

Per class, difficulty and metric (2d image box, bev, 3d), as in the devkit:

- Ground truth of the class is valid; of the neighbouring class (Van for Car, Person_sitting for
  Pedestrian) or of the class but outside the difficulty it is *ignored* (never a false negative, but a
  detection matched to it is neither TP nor FP); anything else (including DontCare) is not considered.
  Outside the difficulty means occlusion > max, truncation > max, or 2D height (y2 - y1) <= min height
  (easy/moderate/hard: 40/25/25 px, occlusion 0/1/2, truncation 0.15/0.30/0.50). A non-finite 2D box
  counts as height 0 (ignored at every difficulty).
- Detections of the class with 2D height < min height are ignored; other classes are not considered.
- Matching is greedy over ground truth in input order with a strict ``overlap > threshold``. Pass 1
  (all detections): each ground truth takes the highest-scoring unassigned candidate; the scores of
  valid matches are the TP scores. `thresholds` samples them at 41 recall points (devkit
  `getThresholds`). Pass 2, per threshold (detections with score < threshold dropped): each ground truth
  takes the unassigned valid detection of largest overlap, else the first ignored one; unassigned valid
  detections are FP unless their overlap with a DontCare region (criterion 0: intersection over the
  detection's own area/volume, same metric) exceeds the threshold.
- precision[i] = TP / (TP + FP) at threshold i (i < 41), then made monotone with max over i..40;
  R11 = mean of precision[0, 4, ..., 40], R40 = mean of precision[1..40], in percent.
- AOS (average orientation similarity), with the 2d metric: in pass 2 each TP adds
  (1 + cos(alpha_gt - alpha_det)) / 2 to the similarity of its threshold (FP add 0);
  aos[i] = similarity / (TP + FP), made monotone and sampled (R11, R40) exactly as precision. Computed
  when every frame's ground truth and detections carry `alpha` and no detection's alpha is -10 (the
  devkit: "AOS is not evaluated if at least one orientation is invalid"), so AOS <= AP.

DontCare: the devkit measures a detection's overlap with a DontCare entry with the current metric, so for
bev/3d it uses the DontCare's 3D box; KITTI's DontCare rows carry dummy 3D boxes, so in practice they only
act in the 2d metric. Give DontCare rows NaN 3D boxes to get exactly that, or set
`dontcare_2d_all_metrics=True` to apply the 2D DontCare rule to bev/3d as well (not the devkit).

Like the devkit, AP needs many ground-truth objects: the i-th sampled threshold stands for recall i/40,
so with fewer than 41 valid objects even perfect detections score below 100 (40 objects: 97.5).
A class/difficulty without any valid ground truth gives NaN (the devkit divides by zero).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from redsup.det3d import boxes as box_ops
from redsup.det3d.kitti_types import FrameDet, FrameGT

DIFFICULTIES = ("easy", "moderate", "hard")
MIN_HEIGHT = (40.0, 25.0, 25.0)
MAX_OCCLUSION = (0, 1, 2)
MAX_TRUNCATION = (0.15, 0.30, 0.50)
N_SAMPLE_PTS = 41
NEIGHBOUR_CLASS = {"car": "van", "pedestrian": "person_sitting"}
METRICS = ("2d", "bev", "3d")


def thresholds(scores: np.ndarray, n_gt: int, n_sample_pts: int = N_SAMPLE_PTS) -> np.ndarray:
    """Devkit `getThresholds`: TP scores (descending) kept so that recall steps by 1/(n_sample_pts - 1)."""
    v = np.sort(np.asarray(scores, dtype=np.float64))[::-1]
    out = []
    current = 0.0
    for i, score in enumerate(v):
        l_recall = (i + 1) / n_gt
        r_recall = (i + 2) / n_gt if i < len(v) - 1 else l_recall
        if (r_recall - current) < (current - l_recall) and i < len(v) - 1:
            continue
        out.append(score)
        current += 1.0 / (n_sample_pts - 1.0)
    return np.asarray(out[:n_sample_pts], dtype=np.float64)


def _lower(names, n: int) -> np.ndarray:
    if names is None:
        return np.full(n, "car", dtype=object)
    return np.array([str(v).lower() for v in names], dtype=object).reshape(n)


@dataclass
class _Stacked:
    """All frames padded to G ground-truth and D detection slots (padding: NaN boxes, -inf scores)."""
    gt_boxes: np.ndarray      # (F, G, 7)
    gt_bbox: np.ndarray       # (F, G, 4)
    gt_occ: np.ndarray        # (F, G) float, padding NaN
    gt_trunc: np.ndarray      # (F, G)
    gt_cls: np.ndarray        # (F, G) lower-case names, padding ""
    det_boxes: np.ndarray     # (F, D, 7)
    det_bbox: np.ndarray      # (F, D, 4)
    det_score: np.ndarray     # (F, D)
    det_cls: np.ndarray       # (F, D)
    gt_alpha: np.ndarray      # (F, G) observation angle, NaN where not given
    det_alpha: np.ndarray     # (F, D)


def _stack(gts: list[FrameGT], dets: list[FrameDet]) -> _Stacked:
    n_f = len(gts)
    g_max = max([len(g.cls) for g in gts] + [1])
    d_max = max([len(d.score) for d in dets] + [1])
    out = _Stacked(np.full((n_f, g_max, 7), np.nan), np.full((n_f, g_max, 4), np.nan), np.full((n_f, g_max), np.nan),
                   np.full((n_f, g_max), np.nan), np.full((n_f, g_max), "", dtype=object),
                   np.full((n_f, d_max, 7), np.nan), np.full((n_f, d_max, 4), np.nan),
                   np.full((n_f, d_max), -np.inf), np.full((n_f, d_max), "", dtype=object),
                   np.full((n_f, g_max), np.nan), np.full((n_f, d_max), np.nan))
    for f, (gt, det) in enumerate(zip(gts, dets)):
        g, d = len(gt.cls), len(det.score)
        if g:
            out.gt_boxes[f, :g] = np.asarray(gt.boxes, dtype=np.float64).reshape(g, 7)
            out.gt_bbox[f, :g] = np.asarray(gt.bbox, dtype=np.float64).reshape(g, 4)
            out.gt_occ[f, :g] = np.asarray(gt.occlusion, dtype=np.float64)
            out.gt_trunc[f, :g] = np.asarray(gt.truncation, dtype=np.float64)
            out.gt_cls[f, :g] = _lower(gt.cls, g)
            if gt.alpha is not None:
                out.gt_alpha[f, :g] = np.asarray(gt.alpha, dtype=np.float64)
        if d:
            out.det_boxes[f, :d] = np.asarray(det.boxes, dtype=np.float64).reshape(d, 7)
            out.det_bbox[f, :d] = np.asarray(det.bbox, dtype=np.float64).reshape(d, 4)
            out.det_score[f, :d] = np.asarray(det.score, dtype=np.float64)
            out.det_cls[f, :d] = _lower(det.cls, d)
            if det.alpha is not None:
                out.det_alpha[f, :d] = np.asarray(det.alpha, dtype=np.float64)
    return out


def _overlaps(st: _Stacked, metric: str, gt_rows: np.ndarray | None = None, criterion: int = -1) -> np.ndarray:
    """(F, D, G) overlap of detections with ground-truth rows (only `gt_rows` (F, G) bool if given)."""
    if metric == "2d":
        gb = st.gt_bbox if gt_rows is None else np.where(gt_rows[..., None], st.gt_bbox, np.nan)
        return box_ops.image_box_overlap(st.det_bbox, gb, criterion=criterion)
    gb = st.gt_boxes if gt_rows is None else np.where(gt_rows[..., None], st.gt_boxes, np.nan)
    return box_ops.overlap_matrix_batched(st.det_boxes, gb, kind=metric, criterion=criterion)


def has_orientation(gts: list[FrameGT], dets: list[FrameDet]) -> bool:
    """Whether AOS can be computed: every frame gives `alpha` for its ground truth and its detections, and every
    detection's alpha is a number other than -10 (KITTI's "no orientation"; the devkit then skips AOS)."""
    if any(g.alpha is None for g in gts) or any(d.alpha is None for d in dets):
        return False
    alphas = np.concatenate([np.asarray(d.alpha, dtype=np.float64).ravel() for d in dets] + [np.zeros(0)])
    return bool(np.isfinite(alphas).all() and (alphas != -10).all())


def _orientation_similarity(st: _Stacked) -> np.ndarray:
    """(F, D, G) (1 + cos(alpha_gt - alpha_det)) / 2 of every detection with every ground-truth row."""
    return (1.0 + np.cos(st.gt_alpha[:, None, :] - st.det_alpha[:, :, None])) / 2.0


@dataclass
class _Prepared:
    """Ignore flags for one class and difficulty (F frames, D dets, G gts)."""
    ign_gt: np.ndarray       # (F, G) 0 valid, 1 ignored, -1 not considered / padding
    ign_det: np.ndarray      # (F, D) 0 valid, 1 ignored (too small), -1 other class / padding
    score: np.ndarray        # (F, D)
    n_gt: int


def _prepare(st: _Stacked, cls: str, difficulty: int) -> _Prepared:
    cls = cls.lower()
    neighbour = NEIGHBOUR_CLASS.get(cls, None)
    height = np.nan_to_num(st.gt_bbox[..., 3] - st.gt_bbox[..., 1], nan=0.0)
    with np.errstate(invalid="ignore"):
        ignore = ((st.gt_occ > MAX_OCCLUSION[difficulty]) | (st.gt_trunc > MAX_TRUNCATION[difficulty])
                  | (height <= MIN_HEIGHT[difficulty]))
    same = st.gt_cls == cls
    neigh = (st.gt_cls == neighbour) if neighbour else np.zeros_like(same)
    ign_gt = np.full(same.shape, -1, dtype=np.int8)
    ign_gt[neigh | (same & ignore)] = 1
    ign_gt[same & ~ignore] = 0
    d_height = np.nan_to_num(np.abs(st.det_bbox[..., 3] - st.det_bbox[..., 1]), nan=0.0)
    real = np.isfinite(st.det_score) | (st.det_cls != "")
    ign_det = np.where(d_height < MIN_HEIGHT[difficulty], 1, np.where(st.det_cls == cls, 0, -1)).astype(np.int8)
    ign_det[~real] = -1
    return _Prepared(ign_gt, ign_det, st.det_score, int((ign_gt == 0).sum()))


def _first_pass(ov: np.ndarray, prep: _Prepared, min_overlap: float) -> np.ndarray:
    """TP scores of the devkit's recall pass (compute_fp=False, threshold 0)."""
    f_idx = np.arange(ov.shape[0])
    assigned = np.zeros(prep.ign_det.shape, dtype=bool)
    usable = prep.ign_det != -1
    tp_scores = []
    for g in range(ov.shape[2]):
        active = prep.ign_gt[:, g] != -1
        cand = usable & ~assigned & (ov[:, :, g] > min_overlap) & active[:, None]
        has = cand.any(axis=1)
        j = np.argmax(np.where(cand, prep.score, -np.inf), axis=1)
        tp = has & (prep.ign_gt[:, g] == 0) & (prep.ign_det[f_idx, j] == 0)
        tp_scores.append(prep.score[f_idx[tp], j[tp]])
        assigned[f_idx[has], j[has]] = True
    return np.concatenate(tp_scores) if tp_scores else np.zeros(0)


def _second_pass(ov: np.ndarray, dc_ov: np.ndarray, prep: _Prepared, min_overlap: float,
                 thr: np.ndarray, sim: np.ndarray | None = None, chunk_elems: int = 4_000_000
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(tp, fp, fn, similarity) per threshold (T,) of the devkit's precision pass (compute_fp=True); similarity:
    the sum of ``sim`` (F, D, G) over the TP matches (the devkit's compute_aos), zeros without ``sim``."""
    n_f, n_d, n_g = ov.shape
    n_t = len(thr)
    tp = np.zeros(n_t, dtype=np.int64)
    fp = np.zeros(n_t, dtype=np.int64)
    fn = np.zeros(n_t, dtype=np.int64)
    similarity = np.zeros(n_t)
    step = max(1, chunk_elems // max(1, n_t * max(n_d, 1)))
    for s in range(0, n_f, step):
        sl = slice(s, min(n_f, s + step))
        o, ig_d, ig_g, sc = ov[sl], prep.ign_det[sl], prep.ign_gt[sl], prep.score[sl]
        avail = (sc[:, None, :] >= thr[None, :, None]) & (ig_d != -1)[:, None, :]      # (f, T, D)
        valid_det = (ig_d == 0)[:, None, :]
        ignored_det = (ig_d == 1)[:, None, :]
        assigned = np.zeros_like(avail)
        for g in range(n_g):
            active = (ig_g[:, g] != -1)[:, None, None]
            cand = avail & ~assigned & (o[:, None, :, g] > min_overlap) & active
            cand_v = cand & valid_det
            cand_i = cand & ignored_det
            has_v = cand_v.any(axis=2)
            has_i = cand_i.any(axis=2)
            jv = np.argmax(np.where(cand_v, o[:, None, :, g], -np.inf), axis=2)
            ji = np.argmax(cand_i, axis=2)
            j = np.where(has_v, jv, ji)
            has = has_v | has_i
            gt_valid = (ig_g[:, g] == 0)[:, None]
            fn += ((~has) & gt_valid).sum(axis=0)
            tp += (has_v & gt_valid).sum(axis=0)
            if sim is not None:
                matched = np.take_along_axis(sim[sl][:, :, g], jv, axis=1)               # (f, T)
                similarity += np.where(has_v & gt_valid, matched, 0.0).sum(axis=0)
            ff, tt = np.nonzero(has)
            assigned[ff, tt, j[ff, tt]] = True
        free = avail & ~assigned & valid_det
        in_dc = (dc_ov[sl] > min_overlap)[:, None, :]
        fp += (free & ~in_dc).sum(axis=(0, 2))
    return tp, fp, fn, similarity


def _sampled_mean(numerator: np.ndarray, tp: np.ndarray, fp: np.ndarray) -> tuple[float, float]:
    """R11 and R40 (percent) of numerator / (TP + FP) per threshold (0 where nothing is detected), made monotone:
    AP for numerator = TP, AOS for numerator = the TPs' orientation similarity."""
    precision = np.zeros(N_SAMPLE_PTS)
    n = min(len(tp), N_SAMPLE_PTS)
    with np.errstate(divide="ignore", invalid="ignore"):
        precision[:n] = np.where(tp[:n] + fp[:n] > 0, numerator[:n] / np.maximum(tp[:n] + fp[:n], 1), 0.0)
    precision = np.maximum.accumulate(precision[::-1])[::-1]
    r11 = precision[0::4].sum() / 11 * 100
    r40 = precision[1:].sum() / 40 * 100
    return float(r11), float(r40)


def _check(gts: list[FrameGT], dets: list[FrameDet]) -> None:
    if len(gts) != len(dets):
        raise ValueError(f"{len(gts)} ground-truth frames but {len(dets)} detection frames")
    for k, (gt, det) in enumerate(zip(gts, dets)):
        g, d = len(gt.cls), len(det.score)
        shapes = {"gt.boxes": (np.shape(gt.boxes), (g, 7)), "gt.bbox": (np.shape(gt.bbox), (g, 4)),
                  "gt.occlusion": (np.shape(gt.occlusion), (g,)), "gt.truncation": (np.shape(gt.truncation), (g,)),
                  "det.boxes": (np.shape(det.boxes), (d, 7)), "det.bbox": (np.shape(det.bbox), (d, 4))}
        for name, (got, want) in shapes.items():
            if got != want and not (got[:1] == (0,) and want[0] == 0):
                raise ValueError(f"frame {k}: {name} has shape {got}, expected {want}")


def evaluate(gts: list[FrameGT], dets: list[FrameDet], classes: tuple[str, ...] = ("Car",),
             metrics: tuple[str, ...] = ("bev", "3d"),
             iou_thresholds: dict[str, tuple[float, ...]] | None = None,
             dontcare_2d_all_metrics: bool = False) -> dict[str, float]:
    """KITTI AP for aligned per-frame ground truth and detections.

    Returns a flat dict ``{f"{cls}_{metric}_{thr:g}/{difficulty}_{R11|R40}": AP in percent}``, e.g.
    ``Car_bev_0.7/moderate_R40``. `iou_thresholds` maps class -> thresholds evaluated for every metric
    (default Car: 0.7 and 0.5; the devkit's own "0.5" table keeps 0.7 for Car 2d, pass what you report).
    With the 2d metric and orientations (`has_orientation`) also AOS in percent, as ``Car_aos_0.7/moderate_R40``
    (the 2d matches at that IoU).
    """
    _check(gts, dets)
    iou_thresholds = iou_thresholds or {"Car": (0.7, 0.5)}
    for m in metrics:
        if m not in METRICS:
            raise ValueError(f"unknown metric {m!r}; expected one of {METRICS}")
    st = _stack(gts, dets)
    dontcare = st.gt_cls == "dontcare"
    prepared = {(cls, d): _prepare(st, cls, d) for cls in classes for d in range(len(DIFFICULTIES))}
    orientation = has_orientation(gts, dets)
    results: dict[str, float] = {}
    for metric in metrics:
        ov = _overlaps(st, metric)
        sim = _orientation_similarity(st) if metric == "2d" and orientation else None
        dc_ov = np.zeros(st.det_score.shape)
        if dontcare.any():
            dc_metric = "2d" if dontcare_2d_all_metrics else metric
            dc_ov = _overlaps(st, dc_metric, gt_rows=dontcare, criterion=0).max(axis=2)
        for cls in classes:
            for difficulty, name in enumerate(DIFFICULTIES):
                prep = prepared[(cls, difficulty)]
                for thr in iou_thresholds.get(cls, ()):
                    key = f"{cls}_{metric}_{thr:g}/{name}"
                    aos_key = f"{cls}_aos_{thr:g}/{name}"
                    if prep.n_gt == 0:
                        results[f"{key}_R11"] = results[f"{key}_R40"] = float("nan")
                        if sim is not None:
                            results[f"{aos_key}_R11"] = results[f"{aos_key}_R40"] = float("nan")
                        continue
                    t = thresholds(_first_pass(ov, prep, thr), prep.n_gt)
                    tp, fp, _, similarity = _second_pass(ov, dc_ov, prep, thr, t, sim)
                    results[f"{key}_R11"], results[f"{key}_R40"] = _sampled_mean(tp, tp, fp)
                    if sim is not None:
                        results[f"{aos_key}_R11"], results[f"{aos_key}_R40"] = _sampled_mean(similarity, tp, fp)
    return results


def resampled_ap(gts: list[FrameGT], dets: list[FrameDet], index_sets, metric: str = "bev",
                 iou: float = 0.7, cls: str = "Car", difficulties: tuple[str, ...] = DIFFICULTIES
                 ) -> dict[str, np.ndarray]:
    """AP (percent) of ``cls`` at ``iou`` on each resample of the frames: ``index_sets`` (B of them) are indices into
    ``gts`` / ``dets`` (a frame drawn twice counts twice), e.g. a bootstrap's. Returns ``evaluate``'s keys for
    each of ``difficulties``, R11 and R40, each a (B,) array; the identity resample gives ``evaluate``'s numbers. The
    overlaps are computed once and every resample selects its frames' rows, so a replicate costs only the two
    matching passes."""
    _check(gts, dets)
    if metric not in METRICS:
        raise ValueError(f"unknown metric {metric!r}; expected one of {METRICS}")
    st = _stack(gts, dets)
    ov = _overlaps(st, metric)
    dontcare = st.gt_cls == "dontcare"
    dc_ov = _overlaps(st, metric, gt_rows=dontcare, criterion=0).max(axis=2) if dontcare.any() \
        else np.zeros(st.det_score.shape)
    out: dict[str, np.ndarray] = {}
    unknown = set(difficulties) - set(DIFFICULTIES)
    if unknown:
        raise ValueError(f"unknown difficulties {sorted(unknown)}; expected some of {DIFFICULTIES}")
    for difficulty, name in enumerate(DIFFICULTIES):
        if name not in difficulties:
            continue
        prep = _prepare(st, cls, difficulty)
        r11, r40 = [], []
        for idx in (np.asarray(i, dtype=np.int64) for i in index_sets):
            sub = _Prepared(prep.ign_gt[idx], prep.ign_det[idx], prep.score[idx], int((prep.ign_gt[idx] == 0).sum()))
            if sub.n_gt == 0:
                a11 = a40 = float("nan")
            else:
                t = thresholds(_first_pass(ov[idx], sub, iou), sub.n_gt)
                tp, fp, _, _ = _second_pass(ov[idx], dc_ov[idx], sub, iou, t)
                a11, a40 = _sampled_mean(tp, tp, fp)
            r11.append(a11)
            r40.append(a40)
        key = f"{cls}_{metric}_{iou:g}/{name}"
        out[f"{key}_R11"], out[f"{key}_R40"] = np.asarray(r11), np.asarray(r40)
    return out


def bootstrap_ap(gts: list[FrameGT], dets: list[FrameDet], unit_ids: list[str],
                 specs: tuple[tuple[str, float], ...], n: int, difficulties: tuple[str, ...] = DIFFICULTIES) -> dict:
    """The test-sampling noise of a split's AP: ``resampled_ap`` on ``n`` cluster-bootstrap resamples of its frames
    (``unit_ids``, one per frame, ``"<scene>/<frame>"``: a resample draws scenes and takes their frames; the draw is
    ``redsup.stats.resample_sets``', a function of the ids only, so every run on the same frames draws the same
    ones and rows pair up) for each (metric, IoU) of ``specs`` and each of ``difficulties`` (a resample costs two
    matching passes for each). Returns {"units": digest, "n_units": F, "n_clusters": scenes, "values": {key: [n
    floats]}}."""
    from redsup.stats import n_clusters, resample_sets, units_digest

    if len(unit_ids) != len(gts) or len(set(unit_ids)) != len(unit_ids):
        raise ValueError(f"bootstrap_ap: {len(unit_ids)} unit ids for {len(gts)} frames (one distinct id a frame)")
    sets, sorted_ids = resample_sets(unit_ids, n)
    position = {u: k for k, u in enumerate(str(x) for x in unit_ids)}
    to_frame = np.array([position[u] for u in sorted_ids])
    frames = [to_frame[s] for s in sets]
    values: dict[str, list[float]] = {}
    for metric, iou in specs:
        values |= {k: [float(x) for x in v]
                   for k, v in resampled_ap(gts, dets, frames, metric, iou, difficulties=difficulties).items()}
    return {"units": units_digest(unit_ids), "n_units": len(unit_ids), "n_clusters": n_clusters(unit_ids),
            "values": values}


# ------------------------------------------------------------------------------------------------ command
CLI_THRESHOLDS = {"Car": 0.7, "Van": 0.7, "Pedestrian": 0.5, "Cyclist": 0.5, "Person_sitting": 0.5}
CLI_HELP = """KITTI object AP of a detection folder against a ground-truth folder, printed as one JSON object.

Both folders hold KITTI label_2 files, one <frame>.txt per frame, one object per line:
  type truncated occluded alpha x1 y1 x2 y2 h w l x y z rotation_y [score]
(2D box in pixels; dimensions in metres; location = bottom centre in the rectified camera 0 frame).
Ground truth has 15 fields; detections 16, the 16th the score. Frames are the ground-truth files; a
frame without a detection file has no detections.

Output keys: {class}_{2d|bev|3d}_{iou}/{easy|moderate|hard}_{R11|R40}, AP in percent, for every class of
Car, Van, Pedestrian, Cyclist, Person_sitting present in the ground truth, at its standard IoU (Car and
Van 0.7, the others 0.5) and at 0.5; and {class}_aos_{iou}/..., the average orientation similarity
(AOS, percent) of the 2d matches, from the alpha field (4th) of both folders: each true positive counts
(1 + cos(alpha_gt - alpha_det)) / 2 instead of 1, so AOS <= 2d AP. A detection with alpha -10 (no
orientation) turns AOS off, as in the devkit. Same rules as the devkit (`evaluate_object.cpp`) and its
python port: difficulty cuts, Van / Person_sitting ignored for Car / Pedestrian, DontCare regions (2D),
41 recall points (R11: every 4th, R40: points 1..40). 3D / BEV boxes are upright in the rectified camera
frame, as the devkit; --calib moves every box through the workflow's vehicle frame and back (the
workflow's own path; the numbers stay the devkit's). NaN: no valid ground truth for that cell.
"""


def main(argv: list[str] | None = None) -> int:
    import argparse
    import json
    import sys

    from redsup.det3d.kitti_files import KittiFileError, read_folders

    ap = argparse.ArgumentParser(prog="python -m redsup.det3d.kitti_eval", description=CLI_HELP,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--gt", required=True, help="ground-truth label folder (15 fields per line)")
    ap.add_argument("--det", required=True, help="detection folder (16 fields per line, score last)")
    ap.add_argument("--calib", default=None, help="optional object-benchmark calib folder (<frame>.txt)")
    args = ap.parse_args(argv)
    try:
        _, gts, dets = read_folders(args.gt, args.det, args.calib)
    except (KittiFileError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    names = {str(c) for g in gts for c in g.cls}
    classes = tuple(c for c in CLI_THRESHOLDS if c in names)
    thr = {c: tuple(sorted({CLI_THRESHOLDS[c], 0.5}, reverse=True)) for c in classes}
    result = evaluate(gts, dets, classes=classes, metrics=METRICS, iou_thresholds=thr)
    print(json.dumps(result, indent=1, sort_keys=True))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
