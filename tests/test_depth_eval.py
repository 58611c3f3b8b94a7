"""KITTI Eigen evaluation protocol on hand-made cases."""
import math

import numpy as np
import pytest

from redsup.depth import evaluation


def test_garg_crop_hand_case():
    mask = evaluation.garg_crop_mask(100, 200)
    # rows int(40.81)=40 .. int(99.19)=99, cols int(7.19)=7 .. int(192.81)=192 (end-exclusive, Monodepth2)
    rows, cols = np.nonzero(mask)
    assert (rows.min(), rows.max(), cols.min(), cols.max()) == (40, 98, 7, 191)
    assert mask.sum() == 59 * 185


def test_metrics_hand_pair():
    gt = np.array([2.0, 4.0, 8.0, 10.0])
    m = evaluation.compute_depth_metrics(gt, 2 * gt)
    assert m["abs_rel"] == pytest.approx(1.0)
    assert m["sq_rel"] == pytest.approx(gt.mean())
    assert m["rmse"] == pytest.approx(math.sqrt(np.mean(gt ** 2)))
    assert m["rmse_log"] == pytest.approx(math.log(2))
    assert (m["a1"], m["a2"], m["a3"]) == (0.0, 0.0, 0.0)  # ratio 2 > 1.25^3 = 1.953
    m = evaluation.compute_depth_metrics(gt, 1.2 * gt)
    assert (m["a1"], m["a2"], m["a3"]) == (1.0, 1.0, 1.0)


def _frame(h=20, w=40, seed=0):
    rng = np.random.default_rng(seed)
    gt = rng.uniform(2.0, 30.0, size=(h, w))
    gt[rng.random((h, w)) < 0.5] = 0.0  # sparse LiDAR
    return gt


def test_median_scaling_and_fixed_scale():
    gt = _frame()
    pred = 2 * np.where(gt > 0, gt, 5.0)
    raw, reason = evaluation.evaluate_frame(gt, pred, median_scaling=False)
    assert reason is None and raw["abs_rel"] == pytest.approx(1.0) and raw["scale"] == 1.0
    scaled, _ = evaluation.evaluate_frame(gt, pred)
    assert scaled["abs_rel"] == pytest.approx(0.0, abs=1e-12) and scaled["a1"] == 1.0
    assert scaled["median_ratio"] == pytest.approx(0.5) and scaled["scale"] == pytest.approx(0.5)
    assert scaled["n_valid"] == int(((gt > 1e-3) & evaluation.garg_crop_mask(*gt.shape)).sum())
    stereo, _ = evaluation.evaluate_frame(gt, pred / 5.4 * 2, median_scaling=False, fixed_scale=5.4 / 4)
    assert stereo["abs_rel"] == pytest.approx(0.0, abs=1e-12)


def test_median_scaling_hand_values_and_clamp():
    gt = np.zeros((10, 10))
    gt[6:9, 3:6] = [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 100.0]]  # 100 m is beyond max_depth
    pred = np.ones_like(gt)
    pred[6:9, 3:6] = [[2.0, 4.0, 6.0], [8.0, 10.0, 12.0], [14.0, 16.0, 1.0]]
    m, _ = evaluation.evaluate_frame(gt, pred)
    # valid gt: 1..8 (median 4.5); pred on those pixels: 2..16 (median 9) -> ratio 0.5, exact
    assert m["n_valid"] == 8 and m["median_ratio"] == pytest.approx(0.5) and m["abs_rel"] == pytest.approx(0.0)
    far, _ = evaluation.evaluate_frame(gt, 1000 * pred, median_scaling=False)
    # every prediction clamped to 80 m
    assert far["abs_rel"] == pytest.approx(np.mean(np.abs(np.arange(1, 9) - 80.0) / np.arange(1, 9)))


def test_garg_crop_excludes_pixels():
    gt = np.zeros((100, 200))
    gt[10, 100] = 5.0  # above the crop
    assert evaluation.evaluate_frame(gt, np.ones_like(gt)).metrics is None
    m, _ = evaluation.evaluate_frame(gt, np.ones_like(gt), crop=None)
    assert m["n_valid"] == 1


def test_frame_without_valid_gt_is_skipped_with_reason():
    gt = np.zeros((20, 40))
    result = evaluation.evaluate_frame(gt, np.ones_like(gt))
    assert result.metrics is None and "no valid ground-truth pixel" in result.reason
    bad_pred = np.full((20, 40), np.nan)
    assert "non-finite" in evaluation.evaluate_frame(_frame(), bad_pred).reason
    good = evaluation.evaluate_frame(_frame(), 3 * _frame() + 1)
    agg = evaluation.aggregate([good, result, None, good.metrics])
    assert agg["n_frames"] == 2 and agg["n_skipped"] == 2
    assert all(np.isfinite(agg[k]) for k in evaluation.METRICS)
    assert agg["abs_rel"] == pytest.approx(good.metrics["abs_rel"])
    assert evaluation.aggregate([result]) == {"n_frames": 0, "n_skipped": 1}


def test_shape_mismatch_is_an_error():
    with pytest.raises(ValueError, match="resize"):
        evaluation.evaluate_frame(np.ones((4, 4)), np.ones((2, 2)))
