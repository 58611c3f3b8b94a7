"""KITTI-convention IoU and AP (redsup.det3d.boxes / kitti_eval) against hand-computed cases and a
loop-for-loop transliteration of the devkit's computeStatistics / eval_class."""
import math

import numpy as np
import pytest

from redsup.det3d import boxes as B
from redsup.det3d import kitti_eval as K


# ----------------------------------------------------------------------------------------------- IoU
@pytest.mark.parametrize("yaw", [0.3, math.pi / 4])
def test_rotated_square_shifted_along_its_axis(yaw):
    # side 2, shifted 0.5 along its own heading: intersection 1.5 x 2 = 3, union 8 - 3 = 5
    a = np.array([[1.0, -2.0, 0.0, 2.0, 2.0, 1.0, yaw]])
    b = a.copy()
    b[0, 0] += 0.5 * math.cos(yaw)
    b[0, 1] += 0.5 * math.sin(yaw)
    assert B.bev_iou(a, b)[0, 0] == pytest.approx(0.6, abs=1e-12)
    assert B.bev_iou(a, b, method="shapely")[0, 0] == pytest.approx(0.6, abs=1e-12)
    assert B.iou_3d(a, b)[0, 0] == pytest.approx(0.6, abs=1e-12)


def test_diamond_shifted_along_x():
    # a 2 x 2 square at 45 deg shifted by d along x moves by d/sqrt2 along both of its axes:
    # intersection (2 - d/sqrt2)^2 = 1.5^2 for d = sqrt2 / 2, IoU = 2.25 / (8 - 2.25) = 9/23
    a = np.array([[0.0, 0.0, 0.0, 2.0, 2.0, 1.0, math.pi / 4]])
    b = a.copy()
    b[0, 0] += math.sqrt(2) / 2
    assert B.bev_iou(a, b)[0, 0] == pytest.approx(9 / 23, abs=1e-12)


def test_3d_iou_half_vertical_overlap():
    a = np.array([[5.0, 1.0, 0.75, 3.9, 1.6, 1.5, 0.4]])
    b = a.copy()
    b[0, 2] += 0.75
    assert B.bev_iou(a, b)[0, 0] == pytest.approx(1.0)
    assert B.iou_3d(a, b)[0, 0] == pytest.approx(1 / 3, abs=1e-12)   # A h/2 / (2 A h - A h / 2)


def test_pairwise_matrix_matches_shapely_and_handles_nan():
    rng = np.random.default_rng(0)
    a = np.c_[rng.uniform(-3, 3, (30, 2)), rng.uniform(-1, 1, 30), rng.uniform(1, 5, (30, 1)),
              rng.uniform(0.5, 2, (30, 1)), rng.uniform(1, 2, 30), rng.uniform(-4, 4, 30)]
    b = a[::-1].copy() + rng.normal(0, 0.3, a.shape)
    b[3] = np.nan
    m = B.iou_3d(a, b)
    assert m.shape == (30, 30) and np.isfinite(m).all() and (m[:, 3] == 0).all()
    assert np.allclose(m, B.iou_3d(a, b, method="shapely"), atol=1e-9)
    assert np.allclose(np.diag(B.bev_iou(a, a)), 1.0)


def test_image_box_overlap_criteria():
    a = np.array([[0.0, 0.0, 30.0, 60.0]])
    b = np.array([[10.0, 0.0, 40.0, 60.0], [100.0, 0, 110, 10]])
    assert np.allclose(B.image_box_overlap(a, b), [[0.5, 0.0]])
    assert np.allclose(B.image_box_overlap(a, b, criterion=0), [[2 / 3, 0.0]])


def test_boxes_to_image_bbox_projects_corners():
    Kmat = np.array([[100.0, 0, 50], [0, 100.0, 40], [0, 0, 1]])
    T_cam_veh = np.array([[0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0], [0, 0, 0, 1]], dtype=float)
    box = np.array([[10.0, 0.0, 0.0, 2.0, 2.0, 2.0, 0.0], [-10.0, 0, 0, 2, 2, 2, 0]])
    bb = B.boxes_to_image_bbox(box, T_cam_veh, Kmat, (100, 80))
    # nearest face at depth 9 spans +-1 m: u = 50 +- 100/9, v = 40 +- 100/9
    assert np.allclose(bb[0], [50 - 100 / 9, 40 - 100 / 9, 50 + 100 / 9, 40 + 100 / 9])
    assert np.isnan(bb[1]).all()


# ------------------------------------------------------------------------------------ AP fixtures
def _car(x, y=0.0, l=3.9, w=1.6, yaw=0.0):
    return [x, y, 0.75, l, w, 1.5, yaw]


def _scene(objects, alpha=False):
    """objects: list of frames; each frame a (gts, dets) pair of lists of dicts. ``alpha``: give every frame
    its objects' "alpha" (default -10, KITTI's "no orientation")."""
    gts, dets = [], []
    for frame_gt, frame_det in objects:
        gts.append(K.FrameGT(
            boxes=np.array([o.get("box", [np.nan] * 7) for o in frame_gt], dtype=float).reshape(-1, 7),
            bbox=np.array([o.get("bbox", [100, 100, 150, 160]) for o in frame_gt], dtype=float).reshape(-1, 4),
            occlusion=np.array([o.get("occ", 0) for o in frame_gt], dtype=int),
            truncation=np.array([o.get("trunc", 0.0) for o in frame_gt], dtype=float),
            cls=np.array([o.get("cls", "Car") for o in frame_gt], dtype=object),
            alpha=np.array([o.get("alpha", -10.0) for o in frame_gt], dtype=float) if alpha else None))
        dets.append(K.FrameDet(
            boxes=np.array([o["box"] for o in frame_det], dtype=float).reshape(-1, 7),
            bbox=np.array([o.get("bbox", [100, 100, 150, 160]) for o in frame_det], dtype=float).reshape(-1, 4),
            score=np.array([o["score"] for o in frame_det], dtype=float),
            cls=np.array([o.get("cls", "Car") for o in frame_det], dtype=object),
            alpha=np.array([o.get("alpha", -10.0) for o in frame_det], dtype=float) if alpha else None))
    return gts, dets


def _perfect(n, start_score=0.9):
    """n frames with one easy car each (60 px tall) detected exactly, decreasing scores."""
    return [([{"box": _car(10.0 + i % 7)}], [{"box": _car(10.0 + i % 7), "score": start_score - 0.001 * i}])
            for i in range(n)]


def _ap(gts, dets, **kw):
    return K.evaluate(gts, dets, metrics=("2d", "bev", "3d"), **kw)


# ------------------------------------------------------------------------------------ AP hand cases
def test_perfect_detections_score_100_everywhere():
    frames = _perfect(41)
    # moderate-only objects (30 px tall, occluded)
    frames += [([{"box": _car(20), "occ": 1, "bbox": [0, 0, 50, 30]}],
                [{"box": _car(20), "score": 0.5, "bbox": [0, 0, 50, 30]}]) for _ in range(5)]
    frames += [([{"box": _car(30), "occ": 2, "trunc": 0.4}], [{"box": _car(30), "score": 0.4}])
               for _ in range(5)]                       # hard-only objects
    res = _ap(*_scene(frames))
    assert len(res) == 3 * 2 * 3 * 2
    assert all(v == pytest.approx(100.0) for v in res.values()), res


def test_needs_41_objects_like_the_devkit():
    # 40 valid objects give 40 sampled thresholds: precision[40] stays 0, R40 = 39/40
    res = _ap(*_scene(_perfect(40)))
    assert res["Car_bev_0.7/easy_R40"] == pytest.approx(97.5)
    assert res["Car_bev_0.7/easy_R11"] == pytest.approx(1000 / 11)


def test_false_positive_lowest_score_is_harmless():
    frames = _perfect(41) + [([], [{"box": _car(15), "score": 0.01}])]
    res = _ap(*_scene(frames))
    assert all(v == pytest.approx(100.0) for v in res.values())


def test_false_positive_highest_score():
    # thresholds = the 41 TP scores; at the k-th: TP k, FP 1 -> precision k/(k+1), monotone max = 41/42
    frames = _perfect(41) + [([], [{"box": _car(15), "score": 0.99}])]
    res = _ap(*_scene(frames))
    for key in ("Car_bev_0.7/easy_R40", "Car_3d_0.5/hard_R40", "Car_bev_0.5/moderate_R11", "Car_2d_0.7/easy_R40"):
        assert res[key] == pytest.approx(4100 / 42)


def test_ground_truth_outside_difficulty_is_ignored_not_missed():
    frames = _perfect(41) + [([{"box": _car(12), "occ": 2}], [])]     # an undetected, occlusion-2 car
    res = _ap(*_scene(frames))
    assert res["Car_bev_0.7/easy_R40"] == pytest.approx(100.0)
    assert res["Car_bev_0.7/moderate_R40"] == pytest.approx(100.0)
    # hard: 42 valid, 41 found -> getThresholds keeps 40 of the 41 scores (skips i = 31): 39/40
    assert res["Car_bev_0.7/hard_R40"] == pytest.approx(97.5)


def test_small_detection_is_ignored_at_its_difficulty():
    frames = _perfect(41) + [([], [{"box": _car(15), "score": 0.99, "bbox": [0, 0, 50, 30]}])]
    res = _ap(*_scene(frames))
    assert res["Car_bev_0.7/easy_R40"] == pytest.approx(100.0)          # 30 px < 40: ignored
    assert res["Car_bev_0.7/moderate_R40"] == pytest.approx(4100 / 42)   # 30 px >= 25: a false positive


@pytest.mark.parametrize("shift,expected", [(1.0, 97.5), (0.99, 100.0)])
def test_strictly_greater_than_threshold(shift, expected):
    # l = 3, w = 2 boxes shifted by 1 along x: IoU = 2/4 = 0.5 exactly, not a match at 0.5
    frames = _perfect(40)
    gt_box, det_box = _car(10, l=3.0, w=2.0), _car(10 + shift, l=3.0, w=2.0)
    frames.append(([{"box": gt_box}], [{"box": det_box, "score": 0.001}]))
    if shift == 1.0:
        assert B.bev_iou([gt_box], [det_box])[0, 0] == 0.5
    res = K.evaluate(*_scene(frames), metrics=("bev",), iou_thresholds={"Car": (0.5,)})
    assert res["Car_bev_0.5/easy_R40"] == pytest.approx(expected)


def test_dontcare_regions():
    fp = {"box": _car(25, y=5), "score": 0.99, "bbox": [300, 100, 350, 160]}
    dc_2d = {"cls": "DontCare", "bbox": [290, 90, 360, 170]}             # no 3D box (NaN), like KITTI
    frames = _perfect(41) + [([dc_2d], [fp])]
    res = _ap(*_scene(frames))
    assert res["Car_2d_0.7/easy_R40"] == pytest.approx(100.0)            # inside the DontCare box
    assert res["Car_bev_0.7/easy_R40"] == pytest.approx(4100 / 42)       # devkit: bev uses the 3D box
    res2 = _ap(*_scene(frames), dontcare_2d_all_metrics=True)
    assert res2["Car_bev_0.7/easy_R40"] == pytest.approx(100.0)
    dc_3d = dict(dc_2d, box=[25, 5, 0.75, 6.0, 4.0, 3.0, 0.0])            # a DontCare volume around it
    res3 = _ap(*_scene(_perfect(41) + [([dc_3d], [fp])]))
    assert res3["Car_3d_0.7/easy_R40"] == pytest.approx(100.0)
    frames_off = _perfect(41) + [([dict(dc_2d, bbox=[0, 0, 20, 20])], [fp])]
    assert _ap(*_scene(frames_off))["Car_2d_0.7/easy_R40"] == pytest.approx(4100 / 42)


def test_van_is_a_neighbour_class_not_a_false_positive():
    frames = _perfect(41) + [([{"box": _car(15), "cls": "Van"}], [{"box": _car(15), "score": 0.99}])]
    res = _ap(*_scene(frames))
    assert res["Car_3d_0.7/easy_R40"] == pytest.approx(100.0)


def test_no_ground_truth_gives_nan():
    res = K.evaluate(*_scene([([], [{"box": _car(15), "score": 0.5}])]))
    assert all(math.isnan(v) for v in res.values())


# ------------------------------------------------------------------------------------ AOS hand cases
def test_aos_of_three_cars_and_a_false_positive():
    """Three frames, one car each (alpha_gt 0, 1, -0.5), detected with orientation errors 0, pi/2, pi, plus a
    false positive that outscores them all:
    similarity of each true positive (1 + cos(error)) / 2 = 1, 0.5, 0.
    3 valid cars, TP scores 0.9, 0.8, 0.7: getThresholds keeps all three (recall 1/3 .. 1 is past every 1/40 step).
      threshold 0.9: TP 1, FP 1 -> precision 1/2, aos 1/2;   0.8: TP 2, FP 1 -> 2/3, (1 + 0.5)/3 = 1/2;
      0.7: TP 3, FP 1 -> 3/4, 1.5/4 = 3/8;                   points 3..40: 0.
    Monotone (max over the points after): precision 3/4, 3/4, 3/4; aos 1/2, 1/2, 3/8.
    AP  R11 = point 0 / 11 = 75/11;   R40 = points 1, 2 / 40 = 1.5/40 = 3.75 %.
    AOS R11 = 50/11;                  R40 = (0.5 + 0.375)/40 = 2.1875 %."""
    fp_bbox = [300, 100, 350, 160]
    frames = [([{"box": _car(10), "alpha": 0.0}], [{"box": _car(10), "score": 0.9, "alpha": 0.0}]),
              ([{"box": _car(12), "alpha": 1.0}], [{"box": _car(12), "score": 0.8, "alpha": 1.0 + math.pi / 2}]),
              ([{"box": _car(14), "alpha": -0.5}], [{"box": _car(14), "score": 0.7, "alpha": -0.5 + math.pi},
                                                    {"box": _car(30), "score": 0.95, "alpha": 0.3, "bbox": fp_bbox}])]
    res = K.evaluate(*_scene(frames, alpha=True), metrics=("2d",), iou_thresholds={"Car": (0.7,)})
    assert res["Car_2d_0.7/easy_R11"] == pytest.approx(75 / 11) and res["Car_2d_0.7/easy_R40"] == pytest.approx(3.75)
    assert res["Car_aos_0.7/easy_R11"] == pytest.approx(50 / 11)
    assert res["Car_aos_0.7/easy_R40"] == pytest.approx(2.1875)
    assert res["Car_aos_0.7/hard_R40"] == pytest.approx(2.1875)        # all three are easy, so also moderate, hard


def test_aos_is_ap_times_the_similarity_of_a_constant_error():
    """41 exact detections, each 60 degrees off in alpha: every true positive counts (1 + cos 60)/2 = 3/4, so at
    every threshold aos = 3/4 precision = 3/4: AOS 75 where AP is 100 (an error of 2 pi counts as none)."""
    frames = [([{"box": _car(10.0 + i % 7), "alpha": 0.2}],
               [{"box": _car(10.0 + i % 7), "score": 0.9 - 0.001 * i, "alpha": 0.2 + math.pi / 3 + 2 * math.pi * i}])
              for i in range(41)]
    res = K.evaluate(*_scene(frames, alpha=True), metrics=("2d", "bev"))
    aos = {k: v for k, v in res.items() if "_aos_" in k}
    assert len(aos) == 2 * 3 * 2                              # the 2d metric's IoU 0.7 and 0.5, 3 difficulties
    assert all(v == pytest.approx(75.0) for v in aos.values()), aos
    assert res["Car_2d_0.7/moderate_R40"] == pytest.approx(100.0)


def test_no_aos_without_orientations_or_2d():
    frames = [([{"box": _car(10.0), "alpha": 0.0}], [{"box": _car(10.0), "score": 0.9, "alpha": 0.1}])]
    has_aos = lambda res: any("_aos_" in k for k in res)                       # noqa: E731
    assert has_aos(K.evaluate(*_scene(frames, alpha=True), metrics=("2d",)))
    assert not has_aos(K.evaluate(*_scene(frames, alpha=True), metrics=("bev", "3d")))
    assert not has_aos(K.evaluate(*_scene(frames), metrics=("2d",)))            # no alpha given
    no_orientation = frames + [([], [{"box": _car(20.0), "score": 0.5}])]      # one detection with alpha -10
    assert not has_aos(K.evaluate(*_scene(no_orientation, alpha=True), metrics=("2d",)))
    gts, dets = _scene(frames, alpha=True)
    assert not K.has_orientation(gts, [K.FrameDet(dets[0].boxes, dets[0].bbox, dets[0].score, alpha=[np.nan])])


# ------------------------------------------------------------- loop transliteration of the devkit
def _frame_overlaps(gt, det, metric, criterion=-1):
    if metric == "2d":
        return B.image_box_overlap(det.bbox, gt.bbox, criterion=criterion)
    return B.overlap_matrix(det.boxes, gt.boxes, kind=metric, criterion=criterion)


def _devkit_ap(gts, dets, cls, difficulty, metric, min_overlap):
    """computeStatistics / eval_class of evaluate_object.cpp, one loop per loop, frame by frame: AP (R11, R40) and
    AOS (R11, R40; the frames carry alpha)."""
    NO_DET = -1e7
    prepared, n_gt = [], 0
    for gt, det in zip(gts, dets):
        ign_gt, ign_det = [], []
        for i in range(len(gt.cls)):
            name = gt.cls[i].lower()
            height = gt.bbox[i, 3] - gt.bbox[i, 1]
            valid = 1 if name == cls.lower() else (0 if (cls.lower(), name) == ("car", "van") else -1)
            ignore = (gt.occlusion[i] > K.MAX_OCCLUSION[difficulty] or gt.truncation[i] > K.MAX_TRUNCATION[difficulty]
                      or height <= K.MIN_HEIGHT[difficulty])
            if valid == 1 and not ignore:
                ign_gt.append(0)
                n_gt += 1
            elif valid == 0 or (ignore and valid == 1):
                ign_gt.append(1)
            else:
                ign_gt.append(-1)
        for j in range(len(det.score)):
            height = abs(det.bbox[j, 3] - det.bbox[j, 1])
            ign_det.append(1 if height < K.MIN_HEIGHT[difficulty] else (0 if det.cls[j].lower() == cls.lower() else -1))
        ov = np.zeros((len(det.score), len(gt.cls)))
        if len(gt.cls) and len(det.score):
            ov = _frame_overlaps(gt, det, metric)
        dc = [i for i in range(len(gt.cls)) if gt.cls[i].lower() == "dontcare"]
        dc_ov = np.zeros((len(det.score), len(dc)))
        if dc and len(det.score):
            sub = K.FrameGT(gt.boxes[dc], gt.bbox[dc], gt.occlusion[dc], gt.truncation[dc], gt.cls[dc])
            dc_ov = _frame_overlaps(sub, det, metric, criterion=0)
        prepared.append((ign_gt, ign_det, ov, dc_ov, det.score, gt.alpha, det.alpha))

    def stats(ign_gt, ign_det, ov, dc_ov, score, gt_alpha, det_alpha, compute_fp, thresh):
        assigned = [False] * len(score)
        below = [compute_fp and s < thresh for s in score]
        tp = fp = fn = 0
        v, delta = [], []
        for i in range(len(ign_gt)):
            if ign_gt[i] == -1:
                continue
            det_idx, valid_det, max_ov, assigned_ign = -1, NO_DET, 0.0, False
            for j in range(len(score)):
                if ign_det[j] == -1 or assigned[j] or below[j]:
                    continue
                o = ov[j, i]
                if not compute_fp and o > min_overlap and score[j] > valid_det:
                    det_idx, valid_det = j, score[j]
                elif compute_fp and o > min_overlap and (o > max_ov or assigned_ign) and ign_det[j] == 0:
                    max_ov, det_idx, valid_det, assigned_ign = o, j, 1, False
                elif compute_fp and o > min_overlap and valid_det == NO_DET and ign_det[j] == 1:
                    det_idx, valid_det, assigned_ign = j, 1, True
            if valid_det == NO_DET and ign_gt[i] == 0:
                fn += 1
            elif valid_det != NO_DET and (ign_gt[i] == 1 or ign_det[det_idx] == 1):
                assigned[det_idx] = True
            elif valid_det != NO_DET:
                tp += 1
                v.append(score[det_idx])
                delta.append(gt_alpha[i] - det_alpha[det_idx])
                assigned[det_idx] = True
        if compute_fp:
            fp = sum(1 for j in range(len(score)) if not (assigned[j] or ign_det[j] != 0 or below[j]))
            for i in range(dc_ov.shape[1]):
                for j in range(len(score)):
                    if assigned[j] or ign_det[j] != 0 or below[j]:
                        continue
                    if dc_ov[j, i] > min_overlap:
                        assigned[j] = True
                        fp -= 1
        # compute_aos: FP count 0, each TP (1 + cos(delta)) / 2; a frame with neither adds nothing (-1)
        similarity = sum((1.0 + math.cos(d)) / 2.0 for d in delta) if tp > 0 or fp > 0 else -1
        return tp, fp, fn, v, similarity

    v = []
    for p in prepared:
        v += stats(*p, compute_fp=False, thresh=0.0)[3]
    thr = K.thresholds(np.array(v), n_gt)
    precision, aos = np.zeros(41), np.zeros(41)
    for t, th in enumerate(thr):
        tp = fp = similarity = 0
        for p in prepared:
            a, b, _, _, sim = stats(*p, compute_fp=True, thresh=th)
            tp, fp = tp + a, fp + b
            similarity += sim if sim != -1 else 0
        precision[t] = tp / (tp + fp)
        aos[t] = similarity / (tp + fp)
    for t in range(len(thr)):
        precision[t] = precision[t:].max()
        aos[t] = aos[t:].max()
    return (precision[0::4].sum() / 11 * 100, precision[1:].sum() / 40 * 100,
            aos[0::4].sum() / 11 * 100, aos[1:].sum() / 40 * 100)


def _random_scene(rng, n_frames):
    frames = []
    for _ in range(n_frames):
        g = []
        for _ in range(rng.integers(0, 6)):
            top = rng.uniform(0, 100)
            g.append({"box": _car(rng.uniform(5, 40), rng.uniform(-8, 8), yaw=rng.uniform(-3, 3)),
                      "bbox": [10, top, 60, top + rng.choice([20, 25, 30, 40, 41, 80])],
                      "occ": int(rng.choice([0, 0, 1, 2, 3])), "trunc": float(rng.choice([0.0, 0.0, 0.15, 0.3, 0.6])),
                      "cls": str(rng.choice(["Car"] * 6 + ["Van", "Pedestrian", "DontCare"]))})
        d = []
        for o in g:
            o["alpha"] = rng.uniform(-math.pi, math.pi)
            if rng.random() < 0.8:
                box = np.array(o["box"]) + np.r_[rng.normal(0, 0.2, 3), rng.normal(0, 0.1, 3), rng.normal(0, 0.1)]
                bb = np.array(o["bbox"]) + rng.normal(0, 2, 4)
                d.append({"box": box.tolist(), "bbox": bb.tolist(), "score": float(rng.random()),
                          "cls": str(rng.choice(["Car"] * 5 + ["Pedestrian"])),
                          "alpha": o["alpha"] + rng.choice([0.0, 1.0]) * rng.normal(0, 1.5)})
        for _ in range(rng.integers(0, 3)):
            top = rng.uniform(0, 100)
            d.append({"box": _car(rng.uniform(5, 40), rng.uniform(-8, 8)), "score": float(rng.random()),
                      "bbox": [200, top, 260, top + rng.choice([20, 30, 50])], "alpha": rng.uniform(-3, 3)})
        frames.append((g, d))
    return frames


@pytest.mark.parametrize("seed", [0, 1])
def test_vectorised_matches_loop_transliteration(seed):
    rng = np.random.default_rng(seed)
    gts, dets = _scene(_random_scene(rng, 80), alpha=True)
    res = K.evaluate(gts, dets, metrics=("2d", "bev", "3d"), iou_thresholds={"Car": (0.7, 0.5)})
    checked = aos_below_ap = 0
    for metric in ("2d", "bev", "3d"):
        for d, name in enumerate(K.DIFFICULTIES):
            for thr in (0.7, 0.5):
                r11, r40, aos11, aos40 = _devkit_ap(gts, dets, "Car", d, metric, thr)
                key = f"Car_{metric}_{thr:g}/{name}"
                assert res[f"{key}_R11"] == pytest.approx(r11, abs=1e-9), key
                assert res[f"{key}_R40"] == pytest.approx(r40, abs=1e-9), key
                checked += r40 > 0
                if metric == "2d":
                    aos_key = f"Car_aos_{thr:g}/{name}"
                    assert res[f"{aos_key}_R11"] == pytest.approx(aos11, abs=1e-9), aos_key
                    assert res[f"{aos_key}_R40"] == pytest.approx(aos40, abs=1e-9), aos_key
                    aos_below_ap += 0 < aos40 < r40 - 1
    assert checked >= 12        # the random scene is not degenerate
    assert aos_below_ap >= 4    # nor are its orientations


# ------------------------------------------------------------------------------------ resampled AP (bootstrap)
def test_resampled_ap_is_evaluate_on_the_resampled_frames():
    """Every resample's AP equals `evaluate` on the explicitly repeated frame list (overlaps computed once); the
    41 exactly detected frames alone score 100, the 41 frames whose car is missed alone 0."""
    frames = _perfect(41) + [([{"box": _car(15.0)}], [{"box": _car(40.0), "score": 0.3}]) for _ in range(41)]
    frames += [([{"box": _car(12.0)}, {"cls": "DontCare", "bbox": [0, 0, 60, 60]}],
                [{"box": _car(12.2), "score": 0.6}, {"box": _car(30.0), "score": 0.7, "bbox": [0, 0, 50, 50]}])]
    gts, dets = _scene(frames)
    rng = np.random.default_rng(0)
    index_sets = [np.arange(41), np.arange(41, 82), *rng.integers(0, len(gts), (3, len(gts)))]
    for metric, iou in (("bev", 0.7), ("3d", 0.5)):
        got = K.resampled_ap(gts, dets, index_sets, metric, iou)
        assert got[f"Car_{metric}_{iou:g}/easy_R40"][0] == 100.0 and got[f"Car_{metric}_{iou:g}/easy_R40"][1] == 0.0
        for b, idx in enumerate(index_sets):
            ref = K.evaluate([gts[i] for i in idx], [dets[i] for i in idx], metrics=(metric,),
                             iou_thresholds={"Car": (iou,)})
            for key, values in got.items():
                assert values[b] == pytest.approx(ref[key], abs=1e-9), (b, key)
    moderate = K.resampled_ap(gts, dets, index_sets, "bev", 0.7, difficulties=("moderate",))
    assert sorted(moderate) == ["Car_bev_0.7/moderate_R11", "Car_bev_0.7/moderate_R40"]
    assert moderate["Car_bev_0.7/moderate_R40"] == pytest.approx(K.resampled_ap(gts, dets, index_sets, "bev", 0.7)
                                                                 ["Car_bev_0.7/moderate_R40"])
    with pytest.raises(ValueError, match="unknown difficulties"):
        K.resampled_ap(gts, dets, index_sets, "bev", 0.7, difficulties=("medium",))


def test_bootstrap_ap_resamples_by_frame_ids():
    """The resamples are a function of the frame ids only: two detectors on the same frames draw the same
    resamples (their replicates pair), and listing the frames in another order changes nothing."""
    frames = _perfect(30) + [([{"box": _car(15.0)}], []) for _ in range(20)]
    gts, dets = _scene(frames)
    worse = [K.FrameDet(d.boxes[:0], d.bbox[:0], d.score[:0]) if i % 3 == 0 else d for i, d in enumerate(dets)]
    ids = [f"s/{i}" for i in range(len(gts))]
    a = K.bootstrap_ap(gts, dets, ids, (("bev", 0.7),), 20)
    b = K.bootstrap_ap(gts, worse, ids, (("bev", 0.7),), 20)
    key = "Car_bev_0.7/moderate_R40"
    assert a["units"] == b["units"] and a["n_units"] == 50 and len(a["values"][key]) == 20
    assert all(x >= y for x, y in zip(a["values"][key], b["values"][key]))   # fewer detections, same resample
    order = np.random.default_rng(1).permutation(len(gts))
    c = K.bootstrap_ap([gts[i] for i in order], [dets[i] for i in order], [ids[i] for i in order],
                       (("bev", 0.7),), 20)
    assert c["values"][key] == pytest.approx(a["values"][key]) and c["units"] == a["units"]
    with pytest.raises(ValueError, match="one distinct id a frame"):
        K.bootstrap_ap(gts, dets, ids[:-1] + ids[:1], (("bev", 0.7),), 5)
