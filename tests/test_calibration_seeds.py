"""McCraith ch. 5 over the depth model's training seeds: one run per seed, rows = the mean over the seeds, the
noise = the seed spread with the paired bootstrap of the seed mean (hand-computed cases)."""
import copy

import numpy as np
import pytest

from redsup.calib import plan as calib_plan
from redsup.calib.tables import COLUMNS, method_frame
from redsup.depth.evaluation import METRICS
from redsup.tables import noise as noise_lib


def _result(method, per_unit):
    """A calibration_eval result whose frames all evaluate, every metric = the frame's value (scale err 0.1)."""
    frames = [{"unit": u, "evaluated": True, **{k: v for k in METRICS}} for u, v in per_unit.items()]
    mean = float(np.mean(list(per_unit.values())))
    return {"method": method, "summary": {**{k: mean for k in METRICS}, "n_frames": len(per_unit),
                                          "scale_rel_err": 0.1, "coverage": 1.0},
            "frames": frames, "failed": [], "not_evaluable": []}


UNITS = [f"test_{s:03d}/{f:04d}" for s in range(6) for f in (4, 14)]


def test_one_seed_keeps_the_bootstrap_record():
    a = _result("ours", {u: 0.1 + 0.01 * i for i, u in enumerate(UNITS)})
    ours, noise, info = method_frame([("Ours", a)])
    assert info["seeds"] == 1 and info["frames"] == len(UNITS)
    assert ours.loc["Ours", "Abs Rel"] == pytest.approx(0.1 + 0.01 * 5.5)
    assert noise["Ours"]["Abs Rel"]["kind"] == "bootstrap"
    assert noise["Ours"]["Abs Rel"]["n_clusters"] == 6


def test_seeds_average_and_carry_their_spread_and_the_frames():
    seeds = [_result("ours", {u: 0.10 + 0.001 * i + 0.02 * k for i, u in enumerate(UNITS)}) for k in range(3)]
    gt = [_result("gt_median", {u: 0.12 + 0.001 * i + 0.01 * k for i, u in enumerate(UNITS)}) for k in range(3)]
    rows = [("Ours", r) for r in seeds] + [("GT", r) for r in gt]
    ours, noise, info = method_frame(rows, pair="world_kitti/M")
    assert info["seeds"] == 3
    # seed k's mean over the 12 frames: 0.10 + 0.0055 + 0.02 k; the row: their mean (k = 0, 1, 2 -> + 0.02)
    assert ours.loc["Ours", "Abs Rel"] == pytest.approx(0.1055 + 0.02)
    assert ours.loc["GT", "Abs Rel"] == pytest.approx(0.1255 + 0.01)
    assert ours.loc["Ours", "frames"] == len(UNITS)
    rec = noise["Ours"]["Abs Rel"]
    assert rec["kind"] == "seeds" and rec["pair"] == "world_kitti/M"
    assert rec["values"] == pytest.approx([0.1055, 0.1255, 0.1455])
    assert noise_lib.spread(rec) == pytest.approx(0.02)
    # the seed mean's sampling noise: replicate r = the mean of the seeds' r-th bootstrap replicates
    boots = [noise_lib.bootstrap({f["unit"]: f["abs_rel"] for f in r["frames"]}) for r in seeds]
    assert rec["boot"] == pytest.approx(np.mean([b["values"] for b in boots], axis=0))
    assert rec["n_clusters"] == 6
    # rows from the same models pair seed by seed: GT - ours differs by 0.02 - 0.01 k, exactly per seed
    lo, hi, _ = noise_lib.difference_interval(ours.loc["GT", "Abs Rel"], ours.loc["Ours", "Abs Rel"],
                                              noise["GT"]["Abs Rel"], rec)
    assert lo < 0.01 < hi


def test_rows_differing_in_frames_are_refused():
    a = _result("ours", {u: 0.1 for u in UNITS})
    b = _result("ours", {u: 0.1 for u in UNITS[:-1]})
    with pytest.raises(ValueError, match="same frames"):
        method_frame([("Ours", a), ("Ours", b)])


def _config(n_seeds):
    cal = {"dataset": "world_kitti", "model_dataset": None, "mode": "M", "length": 30.0, "width": 3.0,
           "tables": {"t1": {"rows": [{"label": "(d) Ours", "run": "ours"}, {"label": "GT", "run": "gt_median"}]},
                      "t3": {"rows": [{"label": "{length}", "run": "ours", "sweep": {"length": [10, 30]}}]}, "f1": {"series": "long"}}}
    return {"calibration": cal, "detection": {"camera": "cam_front"},
            "depth": {"models": [{"dataset": "world_kitti", "mode": "M", "seeds": n_seeds}]}}


def _scenes(_dataset):
    return ["train_000", "test_000", "test_001", "long_000"]


def test_a_method_row_reads_one_run_per_training_seed():
    rows = calib_plan.rows(_config(3), _scenes)
    assert rows["t1"] == [("(d) Ours", "world_kitti/M/road_L30_W3", None),
                          ("(d) Ours", "world_kitti/M/seed1/road_L30_W3", None),
                          ("(d) Ours", "world_kitti/M/seed2/road_L30_W3", None),
                          ("GT", "world_kitti/M/gt_median", None),
                          ("GT", "world_kitti/M/seed1/gt_median", None),
                          ("GT", "world_kitti/M/seed2/gt_median", None)]
    assert [r[1] for r in rows["t3"]][:3] == ["world_kitti/M/road_L10_W3", "world_kitti/M/seed1/road_L10_W3",
                                              "world_kitti/M/seed2/road_L10_W3"]
    assert rows["f1"][0][1] == "world_kitti/M/series_long"  # Fig. 1: the first seed's model
    assert calib_plan.split_run("world_kitti/M/seed2/road_L30_W3") == ("world_kitti", "M/seed2", "road_L30_W3")
    assert calib_plan.split_run("world_kitti/M/gt_median") == ("world_kitti", "M", "gt_median")
    # a seed's run reads that seed's predictions
    files = calib_plan.eval_inputs(_config(3), _scenes(None), "world_kitti", "M/seed1", "single_train")
    assert files["pred"] == ["results/depth/predictions/world_kitti/M/seed1/test_000.npz",
                             "results/depth/predictions/world_kitti/M/seed1/test_001.npz"]
    assert files["train_pred"] == ["results/depth/predictions/world_kitti/M/seed1/train_000.npz"]


def test_one_trained_seed_keeps_the_run_names():
    cfg = _config(1)
    assert [r[1] for r in calib_plan.rows(cfg, _scenes)["t1"]] == ["world_kitti/M/road_L30_W3",
                                                                    "world_kitti/M/gt_median"]
    cfg2 = copy.deepcopy(cfg)
    cfg2["calibration"]["model_dataset"] = "world_other"
    cfg2["depth"]["models"].append({"dataset": "world_other", "mode": "M", "seeds": 2})
    assert calib_plan.model_seeds(cfg2) == ["M", "M/seed1"]  # the seeds of the model that predicts
    assert COLUMNS["abs_rel"] == "Abs Rel"
