"""Named depth evaluation protocols (redsup.depth.evaluation.PROTOCOLS) against hand-computed values.

A 20 x 30 frame (Garg crop: rows 8..18, cols 1..27), gt 0 except: (10,5)=10, (10,6)=20, (10,7)=90,
(10,8)=0.05 inside the crop and (0,0)=40 outside; prediction 10 everywhere, no scaling.
  eigen           : 10, 20, 0.05          abs_rel = (0 + 0.5 + 199) / 3
  eigen_benchmark : 10, 20, 90, 0.05, 40  abs_rel = (0 + 0.5 + 80/90 + 199 + 0.75) / 5
  ddad / lyft     : 10, 20, 40            abs_rel = (0 + 0.5 + 0.75) / 3
"""
import numpy as np
import pytest

from redsup.depth.evaluation import PROTOCOLS, evaluate_frame, valid_mask


def frame():
    gt = np.zeros((20, 30))
    gt[10, 5], gt[10, 6], gt[10, 7], gt[10, 8], gt[0, 0] = 10, 20, 90, 0.05, 40
    return gt, np.full(gt.shape, 10.0)


@pytest.mark.parametrize("name, n, abs_rel", [
    ("eigen", 3, (0 + 0.5 + 199) / 3),
    ("eigen_benchmark", 5, (0 + 0.5 + 80 / 90 + 199 + 0.75) / 5),
    ("ddad", 3, 1.25 / 3),
    ("lyft", 3, 1.25 / 3),
])
def test_protocol_against_hand_computed_values(name, n, abs_rel):
    gt, pred = frame()
    m = evaluate_frame(gt, pred, median_scaling=False, protocol_name=name).metrics
    assert m["n_valid"] == n
    assert m["abs_rel"] == pytest.approx(abs_rel, rel=1e-12)


def test_protocol_overrides_explicit_keys_and_default_is_unchanged():
    gt, pred = frame()
    assert valid_mask(gt, crop=None, protocol_name="eigen").sum() == 3
    assert valid_mask(gt, crop=None).sum() == 4             # no protocol: explicit 1e-3..80, no crop
    assert set(PROTOCOLS) == {"eigen", "eigen_benchmark", "ddad", "lyft"}
    with pytest.raises(ValueError, match="unknown depth evaluation protocol"):
        valid_mask(gt, protocol_name="kitti")


def test_eigen_benchmark_still_clamps_the_prediction():
    gt, pred = frame()
    pred[10, 7] = 200.0                                      # clamped to 80: |90 - 80| / 90
    m = evaluate_frame(gt, pred, median_scaling=False, protocol_name="eigen_benchmark").metrics
    assert m["abs_rel"] == pytest.approx((0 + 0.5 + 10 / 90 + 199 + 0.75) / 5)
