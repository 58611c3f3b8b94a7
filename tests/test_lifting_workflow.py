"""The lifting stage (McCraith ch. 6) in the session's tiny build: tables, per-configuration metrics, the
full-method metrics chapter 7 reads, the auto-labels, run records and the bad-input messages."""
import json

import numpy as np
import pytest
import yaml

from conftest import ROOT

pytestmark = pytest.mark.workflow

TABLES = ("mccraith_ch6_table1", "mccraith_ch6_table2", "mccraith_ch6_table3", "mccraith_ch6_table4")


def _lifting_cfg():
    from redsup.config import resolve

    raw = yaml.safe_load((ROOT / "config.yaml").read_text())
    raw["profile"] = "tiny"
    return resolve(raw)["lifting"]


def test_tables_written_with_paper_values_and_scorecard(built):
    for table in TABLES:
        md = (built / "results" / "tables" / f"{table}.md").read_text()
        assert "(paper)" in md and "Scorecard" in md, table
        for ext in ("csv", "tex", "score.json"):
            assert (built / "results" / "tables" / f"{table}.{ext}").stat().st_size > 0
        score = json.loads((built / "results" / "tables" / f"{table}.score.json").read_text())
        assert score["rows_both"] == len(_lifting_cfg()["tables"][table]["rows"])   # every row named as the paper's
        assert "training seeds" in md
    scorecard = (built / "results" / "tables" / "scorecard.md").read_text()
    assert all(t in scorecard for t in TABLES)
    t2 = (built / "results" / "tables" / "mccraith_ch6_table2.md").read_text()
    assert "Goel et al. [8]" in t2 and "(g) Ours, 128 bins" in t2
    t3 = (built / "results" / "tables" / "mccraith_ch6_table3.md").read_text()
    assert "paper only: literature, not reproduced" in t3      # VS3D / Zakharov rows


def test_every_configuration_has_metrics_and_a_model_per_seed(built):
    from redsup import checkpoint

    cfg = _lifting_cfg()
    assert cfg["seeds"] == [0]                                      # tiny: one seed per configuration
    for run in cfg["runs"]:
        for k in cfg["seeds"]:
            metrics = json.loads((built / "results" / "lifting" / "metrics" / run / f"seed{k}.json").read_text())
            assert "Car_bev_0.5/moderate_R40" in metrics and "Car_3d_0.5/hard_R11" in metrics
            # the moderate AP_BEV's bootstrap over the test frames, at every evaluated IoU
            boot = metrics["bootstrap"]
            assert sorted(boot["values"]) == [f"Car_bev_{iou:g}/moderate_{r}" for iou in (0.5, 0.7) for r in ("R11", "R40")]
            assert all(len(v) == cfg["eval"]["bootstrap"] for v in boot["values"].values())
            ckpt = checkpoint.load(built / "results" / "lifting" / "models" / run / f"seed{k}.pt", "lifting")
            assert ckpt["config"]["profile"] == "tiny" and ckpt["meta"]["configuration"] == run
            record = json.loads((built / "results/runs/lifting/metrics" / run / f"seed{k}.json").read_text())
            assert record["status"] == "FINISHED" and record["parent"] in TABLES  # a whole id
            steps = [m for m in record["metrics"] if m[0] == "train/total"]
            assert steps and all(np.isfinite(m[1]) for m in steps)            # a training curve, never NaN
    # a run that feeds several tables is listed by all of them
    record = json.loads((built / "results/runs/lifting/metrics/full_coco/seed0.json").read_text())
    assert set(json.loads(record["params"]["tables"]) if isinstance(record["params"]["tables"], str)
               else record["params"]["tables"]) >= {"mccraith_ch6_table1", "mccraith_ch6_table2", "mccraith_ch6_table3"}


def test_full_method_metrics_for_chapter_7(built):
    path = built / "results" / "lifting" / "metrics" / _lifting_cfg()["full_method"] / "seed0.json"
    assert path.parent.name == "full_cityscapes"
    metrics = json.loads(path.read_text())
    for key in ("Car_bev_0.7/moderate_R40", "Car_bev_0.7/easy_R11", "Car_bev_0.5/hard_R40", "Car_3d_0.7/moderate_R40"):
        assert key in metrics
    assert {"n_gt/easy", "n_gt/moderate", "n_gt/hard"} <= set(metrics)


def test_auto_labels_and_bad_input_messages(built):
    cfg = _lifting_cfg()
    source = cfg["runs"]["labels_cityscapes"]["labels_from"]
    with np.load(built / "results" / "lifting" / "labels" / source / "seed0.npz") as z:
        assert z["box"].shape[1] == 7 and len(z["box"]) == len(z["detection"]) > 0
        assert np.isfinite(z["box"]).all() and np.allclose(z["box"][:, 3:6], [3.9, 1.6, 1.5])
    log = (built / "results" / "logs" / "lifting" / "metrics" / "full_coco" / "seed0.log").read_text()
    assert "objects kept of" in log and "fewer than 3 finite LiDAR points" in log
