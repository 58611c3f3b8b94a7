"""The ch. 3 velocity stage in the session's tiny build (conftest.built): tables, figures, run records."""
import json

import numpy as np
import pandas as pd
import pytest

pytestmark = pytest.mark.workflow

TABLES = ("mccraith_ch3_table2", "mccraith_ch3_synthetic_ablation", "mccraith_ch3_fig3", "mccraith_ch3_fig6")
CONFIGS = ("geometric", "mlp_tracker", "mlp_synthetic", "mlp_synthetic_more", "mlp_synthetic_abnormal")


def test_tables_figures_and_scorecard_exist(built):
    tables = built / "results" / "tables"
    for table in TABLES:
        for ext in ("md", "csv", "tex", "score.json"):
            assert (tables / f"{table}.{ext}").stat().st_size > 0, (table, ext)
    for figure in ("mccraith_ch3_fig3", "mccraith_ch3_fig6"):
        assert (built / "results" / "figures" / f"{figure}.png").stat().st_size > 10_000
    scorecard = (tables / "scorecard.md").read_text()
    assert all(t in scorecard for t in TABLES)


def test_table2_has_our_rows_beside_the_paper(built):
    df = pd.read_csv(built / "results" / "tables" / "mccraith_ch3_table2.csv").set_index("method")
    for row in ("geometric reprojection", "Ours (MLP-tracker)", "Ours (MLP-synthetic)"):
        assert np.isfinite(float(df.at[row, "E_v (ours)"])) and float(df.at[row, "E_v (ours)"]) >= 0
        assert float(df.at[row, "runtime (ms) (ours)"]) > 0
        assert df.at[row, "status"] == "ours + paper"
    assert float(df.at["Ours (MLP-synthetic)", "E_v (paper)"]) == 1.28
    assert df.at["Wrona (2nd)", "status"].startswith("paper only")
    # MLP rows: the seed mean with its spread; the geometric row: a bootstrap over the test vehicles
    assert np.isfinite(float(df.at["Ours (MLP-tracker)", "E_v (ours) std"]))
    assert np.isfinite(float(df.at["geometric reprojection", "E_v (ours) std"]))
    score = json.loads((built / "results" / "tables" / "mccraith_ch3_table2.score.json").read_text())
    assert score["n_rows"] == 3 and score["claims_total"] >= 6
    md = (built / "results" / "tables" / "mccraith_ch3_table2.md").read_text()
    assert "Scorecard" in md and "geometric velocity = the last-frame derivative" in md


def test_configuration_outputs_and_bad_input_report(built):
    for name in CONFIGS:
        record = json.loads((built / "results" / "velocity" / name / "metrics.json").read_text())
        m = record["metrics"]
        assert record["name"] == name and {"val", "test", "abnormal"} <= set(record["bad_input"])
        for split in ("test", "abnormal"):
            assert m[f"{split}_n"] == m[f"{split}_n_near"] + m[f"{split}_n_medium"] + m[f"{split}_n_far"]
            assert m[f"{split}_n_tracker_failed"] >= 0 and m[f"{split}_n_degenerate"] >= 0
        with np.load(built / "results" / "velocity" / name / "predictions.npz") as p:
            assert p["test_velocity_pred"].shape == p["test_velocity_true"].shape == (m["test_n"], 2)
            assert np.isfinite(p["test_velocity_pred"]).all()
    stats = json.loads((built / "results" / "velocity" / "generator_statistics.json").read_text())
    assert stats["n_start_points"] >= 1 and len(stats["velocity_cov"]) == 2


def test_child_runs_have_training_curves_and_parents(built):
    runs = built / "results" / "runs"
    for name in CONFIGS[1:]:
        record = json.loads((runs / "velocity" / name / "metrics.json").read_text())
        assert record["status"] == "FINISHED"
        steps = [s for k, _, s, _ in record["metrics"] if k == "train_loss"]
        assert steps == list(range(len(steps))) and len(steps) >= 1
        # the training curve monitors the val split, never the test split
        keys = {k for k, *_ in record["metrics"]}
        assert "val_loss" in keys and "test_loss" not in keys
    parents = {json.loads((runs / "velocity" / n / "metrics.json").read_text())["parent"] for n in CONFIGS}
    assert parents == {"mccraith_ch3_table2", "mccraith_ch3_synthetic_ablation"}
    for figure in ("mccraith_ch3_fig3", "mccraith_ch3_fig6"):
        record = json.loads((runs / "figures" / f"{figure}.json").read_text())  # the PNG rule
        assert record["parent"] == figure
        assert any(path.endswith(f"{figure}.png") for path, _ in record["artifacts"])
        assert any(path.endswith(f"{figure}.png") for path, _ in record["parent_artifacts"])


def test_ablation_shows_the_table2_rows_with_their_noise(built):
    df = pd.read_csv(built / "results" / "tables" / "mccraith_ch3_synthetic_ablation.csv").set_index("configuration")
    for row in ("Ours (MLP-tracker)", "Ours (MLP-synthetic)", "MLP-synthetic, abnormal velocities (x3)",
                "geometric reprojection"):
        assert df.at[row, "status"].startswith("ours"), row
        assert np.isfinite(float(df.at[row, "E_v (abnormal) (ours)"]))
        assert np.isfinite(float(df.at[row, "E_v (abnormal) (ours) std"]))


def test_figure_numbers_feed_the_table_and_the_png(built):
    """The figure rule writes only its PNG; its numbers (table rows + plotted data) are a result of their own."""
    for figure in ("mccraith_ch3_fig3", "mccraith_ch3_fig6"):
        numbers = json.loads((built / "results" / "velocity" / "figures" / f"{figure}.json").read_text())
        assert numbers["rows"] and numbers["plot"]["figure"] in ("vehicle_statistics", "sequences")
        record = json.loads((built / "results" / "runs" / "velocity" / "figures" / f"{figure}.json").read_text())
        assert record["status"] == "FINISHED" and record["parent"] == figure
