"""The ch. 7 detector stage in the tiny build: cached splits, one trained configuration per row, the three
tables with the thesis' values beside ours, and the run records."""
import json
import math
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest
import yaml

from redsup.config import resolve

TABLES = ("mccraith_ch7_table1", "mccraith_ch7_table2", "mccraith_ch7_table3")


@pytest.fixture(scope="module")
def cfg():
    raw = yaml.safe_load((Path(__file__).resolve().parents[1] / "config.yaml").read_text())
    raw["profile"] = "tiny"
    return resolve(raw)["lidar_detector"]


def test_splits_are_cached_with_counts(built):
    from redsup.lidar_detector.data import load_split

    for split in ("train", "test"):
        data = load_split(built / f"results/lidar_detector/data/{split}.npz")
        assert data.n_frames > 0 and len(data.arrays["points"]) > 0
        assert data.counts["masks_used"] > 0
        assert np.isfinite(data.arrays["points"]).all() and np.isfinite(data.arrays["obj_points"]).all()
        log = (built / f"results/logs/lidar_detector/data/{split}.log").read_text()
        assert "skipped with no LiDAR point" in log


def test_every_configuration_trained_once_per_seed_with_curves(built, cfg):
    from redsup import checkpoint

    assert cfg["seeds"] == [0]                                      # tiny: one seed per configuration
    for name in cfg["runs"]:
        for k in cfg["seeds"]:
            metrics = json.loads((built / f"results/lidar_detector/metrics/{name}/seed{k}.json").read_text())
            assert metrics["train_steps"] == cfg["train"]["steps"] and metrics["train_steps_nonfinite"] == 0
            for d in ("easy", "moderate", "hard"):
                v = metrics[f"Car_bev_0.7/{d}_R40"]
                assert 0.0 <= v <= 100.0 or math.isnan(v)
            assert metrics["frames"] > 0 and metrics["infer_fps"] > 0
            # the AP's bootstrap over the test frames (the cells' test-sampling noise), one id a frame
            boot = metrics["bootstrap"]
            assert boot["n_units"] == metrics["frames"] and sorted(boot["values"]) == sorted(
                f"Car_bev_0.7/{d}_{r}" for d in ("easy", "moderate", "hard") for r in ("R11", "R40"))
            assert all(len(v) == cfg["eval"]["bootstrap"] for v in boot["values"].values())
            ckpt = checkpoint.load(built / f"results/lidar_detector/models/{name}/seed{k}.pt", "lidar_detector")
            assert ckpt["config"]["profile"] == "tiny" and ckpt["meta"]["configuration"] == name
            record = json.loads((built / f"results/runs/lidar_detector/metrics/{name}/seed{k}.json").read_text())
            assert record["status"] == "FINISHED" and record["parent"] in TABLES
            curves = {m[0] for m in record["metrics"] if m[2] > 0}
            assert {"train/loss", "train/heatmap", "train/yaw"} <= curves
            bev = [a[0] for a in record["artifacts"] if a[0].endswith("bev_test_frame.png")]
            assert len(bev) == 1 and cv2.imread(str(built / bev[0])).shape[2] == 3   # drawn with OpenCV, BGR on disk


def test_tables_have_paper_values_and_scores(built, cfg):
    for table_id in TABLES:
        md = (built / f"results/tables/{table_id}.md").read_text()
        assert "(paper)" in md and "(ours)" in md and "Scorecard" in md
        csv = pd.read_csv(built / f"results/tables/{table_id}.csv", dtype=str)
        rows = set(csv.iloc[:, 0])
        assert {r["label"] for r in cfg["tables"][table_id]["rows"]} <= rows
        score = json.loads((built / f"results/tables/{table_id}.score.json").read_text())
        assert score["rows_both"] >= len(cfg["tables"][table_id]["rows"]) and score["claims_total"] >= 2
        assert (built / f"results/tables/{table_id}.tex").exists()
    t1 = pd.read_csv(built / "results/tables/mccraith_ch7_table1.csv").set_index("row")
    assert t1.loc["McCraith et al. [2022] †", "status"] == "ours + paper"      # the ch. 6 stage's numbers
    # ... read through lifting.full_method: the mean over the lifting seeds of that configuration
    root = Path(__file__).resolve().parents[1]
    raw = yaml.safe_load((root / "config.yaml").read_text())
    raw["profile"] = "tiny"
    lift = resolve(raw)["lifting"]
    per_seed = [json.loads((built / f"results/lifting/metrics/{lift['full_method']}/seed{k}.json").read_text())
                ["Car_bev_0.7/moderate_R40"] for k in lift["seeds"]]
    assert len(per_seed) == 1 and cfg["tables"]["mccraith_ch7_table1"]["lifting_row"] == "McCraith et al. [2022] †"
    assert t1.loc["McCraith et al. [2022] †", "AP_BEV Moderate (ours)"] == pytest.approx(per_seed[0], abs=1e-6)
    assert "AP_BEV Moderate (ours) std" not in t1.columns                     # one seed: no spread column
    scorecard = (built / "results/tables/scorecard.md").read_text()
    assert all(t in scorecard for t in TABLES)
