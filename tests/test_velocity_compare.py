"""The paired, bin-stratified ratio bootstrap of two velocity methods (redsup.velocity.compare)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from redsup.velocity.compare import in_clips, per_vehicle_errors, ratio_bootstrap


def test_ratio_is_the_ratio_of_the_bin_means_by_hand():
    # near: a 1, 3 (mean 2), b 2, 2 (mean 2); far: a 2, b 8. E_v a = (2 + 2) / 2 = 2, b = (2 + 8) / 2 = 5
    r = ratio_bootstrap([1.0, 3.0, 2.0], [2.0, 2.0, 8.0], [0, 0, 2], n=500)
    assert r["ev_a"] == pytest.approx(2.0) and r["ev_b"] == pytest.approx(5.0)
    assert r["ratio"] == pytest.approx(0.4) and r["diff"] == pytest.approx(3.0)
    # the far bin has one vehicle: every replicate draws it (stratified), so b's far mean is always 8 and the
    # ratio only moves with the near draw: a's near mean is 1, 2 or 3 -> ratio (m + 2) / 2 / 5 in [0.3, 0.5]
    assert 0.3 - 1e-12 <= r["ratio_lo"] <= r["ratio"] <= r["ratio_hi"] <= 0.5 + 1e-12
    assert r["ratio_lo"] < r["ratio_hi"]


def test_a_constant_factor_has_no_spread():
    rng = np.random.default_rng(3)
    b = rng.uniform(0.5, 4.0, 90)
    r = ratio_bootstrap(0.5 * b, b, rng.integers(0, 3, 90), n=300)
    assert r["ratio"] == pytest.approx(0.5)
    assert r["ratio_lo"] == pytest.approx(0.5) and r["ratio_hi"] == pytest.approx(0.5)
    assert r["diff_lo"] > 0


def test_noise_around_equal_methods_gives_an_interval_around_one():
    rng = np.random.default_rng(0)
    b = rng.exponential(4.0, 400)
    a = rng.permutation(b)  # the same distribution, paired with other vehicles
    r = ratio_bootstrap(a, b, rng.integers(0, 3, 400), n=1000)
    assert r["ratio_lo"] < 1.0 < r["ratio_hi"]
    assert r["diff_lo"] < 0.0 < r["diff_hi"]


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="2 / 3 errors for 3 vehicles"):
        ratio_bootstrap([1.0, 2.0], [1.0, 2.0, 3.0], [0, 1, 2])
    with pytest.raises(ValueError, match="not finite"):
        ratio_bootstrap([1.0, np.nan], [1.0, 2.0], [0, 1])


def test_per_vehicle_errors_average_a_configuration_over_its_seeds(tmp_path):
    def write(run, name, sq):
        (tmp_path / run).mkdir()
        rec = {"name": name, "per_track": {"test": {"id": ["0/1", "3/2"], "bin": [0, 2], "sq_err": sq}}}
        (tmp_path / run / "metrics.json").write_text(json.dumps(rec))

    write("mlp_tracker", "mlp_tracker", [1.0, 5.0])
    write("mlp_tracker_seed1", "mlp_tracker", [3.0, 7.0])
    write("constant", "constant", [4.0, 4.0])
    errs = per_vehicle_errors(tmp_path, "mlp_tracker", "test")
    assert errs == {"0/1": (0, 2.0), "3/2": (2, 6.0)}
    assert per_vehicle_errors(tmp_path, "constant", "test") == {"0/1": (0, 4.0), "3/2": (2, 4.0)}
    with pytest.raises(FileNotFoundError, match="'mlp_tracker' and split 'val'"):
        per_vehicle_errors(tmp_path, "mlp_tracker", "val")


def test_in_clips_keeps_the_vehicles_of_a_clip_range():
    errs = {"0/1": (0, 1.0), "39/2": (1, 2.0), "40/1": (2, 3.0), "159/4": (0, 4.0), "160/1": (1, 5.0)}
    assert in_clips(errs, 40, 160) == {"40/1": (2, 3.0), "159/4": (0, 4.0)}
    assert in_clips(errs, 0, 40) == {"0/1": (0, 1.0), "39/2": (1, 2.0)}
    with pytest.raises(ValueError, match="'car7' is not"):
        in_clips({"car7": (0, 1.0)}, 0, 10)
