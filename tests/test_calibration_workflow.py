"""The ch. 5 calibration stage in the session's tiny build (conftest.built): tables, Fig. 1, per-method results,
run records, the same frames for every row, and a frame without road pixels on the real prepared files."""
import json
import math

import numpy as np
import pandas as pd
import pytest

from redsup import config as redsup_config
from redsup.calib import inputs, methods, plan

from conftest import ROOT

pytestmark = pytest.mark.workflow

TABLES = ("mccraith_ch5_fig1", "mccraith_ch5_table1", "mccraith_ch5_table2", "mccraith_ch5_table3",
          "mccraith_ch5_table4")
METRICS = ("Abs Rel", "Sq Rel", "RMSE", "RMSE log", "δ < 1.25", "δ < 1.25^2", "δ < 1.25^3")


@pytest.fixture(scope="module")
def cfg():
    return redsup_config.load(ROOT / "config.yaml", {"profile": "tiny"})


def _methods(cfg):
    return sorted({m for rows in plan.table_methods(cfg["calibration"]).values() for _, m in rows})


def _camera_height(built, cfg):
    c = cfg["calibration"]
    return inputs.camera_geometry(built / "results" / "raw" / c["dataset"] / "test_000",
                                  cfg["detection"]["camera"])["camera_height"]


def _n_test_frames(cfg):
    c = cfg["calibration"]
    return cfg["datasets"][c["dataset"]]["scenes"]["test"] * cfg["world"]["frames"]["test"]


def test_tables_figure_and_scorecard_exist(built):
    tables = built / "results" / "tables"
    for table in TABLES:
        for ext in ("md", "csv", "tex", "score.json"):
            assert (tables / f"{table}.{ext}").stat().st_size > 0, (table, ext)
    assert (built / "results" / "figures" / "mccraith_ch5_fig1.png").stat().st_size > 10_000
    scorecard = (tables / "scorecard.md").read_text()
    assert all(t in scorecard for t in TABLES)


def test_every_configuration_is_a_finished_child_run_with_nan_free_results(built, cfg):
    c = cfg["calibration"]
    n_test = _n_test_frames(cfg)
    units = set()
    assert set(methods.BASELINES) <= set(_methods(cfg))
    for name in _methods(cfg):
        path = built / "results" / "calibration" / c["dataset"] / c["mode"] / f"{name}.json"
        text = path.read_text()
        assert "NaN" not in text and "Infinity" not in text, name
        result = json.loads(text)
        s = result["summary"]
        assert s["n_frames"] + s["n_not_evaluable"] == n_test, name
        assert s["n_fit"] + s["n_fallback"] == s["n_frames"] and 0 <= s["coverage"] <= 1
        assert len(result["failed"]) == s["n_fallback"]
        assert all(" frame " in m for m in result["failed"])
        units.add(tuple(sorted(methods.per_frame(result, "abs_rel"))))
        if s["n_frames"]:
            assert 0 <= s["abs_rel"] < 10 and 0 <= s["a1"] <= 1
        if name not in ("gt_median", "single_train", "single_test"):  # camera height from the extrinsics
            assert result["camera_height"] == {"test_000": pytest.approx(_camera_height(built, cfg))}
        record = json.loads((built / "results" / "runs" / "calibration" / c["dataset"] / c["mode"]
                             / f"{name}.json").read_text())
        assert record["status"] == "FINISHED" and record["run_name"] == name
        assert record["parent"] in TABLES and record["parent"] != "mccraith_ch5_fig1"  # a table's whole id
    assert len(units) == 1  # every method on the same frames
    single = built / "results" / "calibration" / c["dataset"] / c["mode"] / "single_train.json"
    assert json.loads(single.read_text())["single_scale"] > 0


def test_table1_rows_beside_the_paper(built, cfg):
    df = pd.read_csv(built / "results" / "tables" / "mccraith_ch5_table1.csv").set_index("Method")
    n_test = _n_test_frames(cfg)
    for row in ("(a) GT Single Scaling (training set)", "(b) GT Single Scaling (testing set)", "(c) Fixed road plane",
                "(d) Ours"):
        assert df.at[row, "status"] == "ours + paper"
        assert 0 < int(df.at[row, "frames (ours)"]) <= n_test
        assert 0 <= float(df.at[row, "coverage (ours)"]) <= 1
        assert all(math.isfinite(float(df.at[row, f"{m} (ours)"])) for m in METRICS)
    assert df["frames (ours)"].nunique() == 1  # every row averages the same frames
    assert float(df.at["(d) Ours", "Abs Rel (paper)"]) == 0.113
    ref = "GT Scaling (per-frame median, reference)"
    assert df.at[ref, "status"] == "ours only" and float(df.at[ref, "scale err (ours)"]) == 0
    assert float(df.at[ref, "coverage (ours)"]) == 1.0
    score = json.loads((built / "results" / "tables" / "mccraith_ch5_table1.score.json").read_text())
    assert score["rows_both"] == 4 and score["claims_total"] >= 2
    assert "paired bootstrap" in (built / "results" / "tables" / "mccraith_ch5_table1.md").read_text()


def test_table2_marks_the_literature_as_not_reproduced(built):
    df = pd.read_csv(built / "results" / "tables" / "mccraith_ch5_table2.csv").set_index("Method")
    assert df.at["Ours", "status"] == "ours + paper" and df.at["Godard et al. [2019]", "status"] == "ours + paper"
    assert df.at["Fu et al. [2018]", "status"] == "paper only: literature, not reproduced"
    assert "per-frame GT median scaling" in (built / "results" / "tables" / "mccraith_ch5_table2.md").read_text()


def test_ablation_rows_follow_the_config_lists(built, cfg):
    c = cfg["calibration"]
    for table, key in (("mccraith_ch5_table3", "Length (m)"), ("mccraith_ch5_table4", "Width (m)")):
        values = c["tables"][table]["values"]
        df = pd.read_csv(built / "results" / "tables" / f"{table}.csv")
        ours = df[df["status"].str.startswith("ours")]
        assert sorted(float(v) for v in ours[key]) == sorted(float(v) for v in values)


def test_fig1_summary(built):
    df = pd.read_csv(built / "results" / "tables" / "mccraith_ch5_fig1.csv").set_index("series")
    gt = df.loc["per-frame GT scaling factor"]
    assert 0 < float(gt["min (ours)"]) <= float(gt["median (ours)"]) <= float(gt["max (ours)"])
    assert float(gt["max/min (ours)"]) >= 1
    assert float(df.at["GT Single Scaling (training set)", "scaling factor (ours)"]) > 0


def test_frame_without_road_pixels_on_the_prepared_files(built, cfg):
    """A test frame whose road mask is empty fails the fit with its reason and gets the fallback scale; it
    stays in the mean, NaN-free."""
    c = cfg["calibration"]
    spec = cfg["datasets"][c["dataset"]]
    camera_height = _camera_height(built, cfg)
    prepared = built / "results" / "prepared" / c["dataset"] / "test_000"
    scene = inputs.load_scene(built / "results" / "depth" / "predictions" / c["dataset"] / c["mode"] / "test_000.npz",
                              prepared / f"{cfg['detection']['camera']}_depth.npz", prepared / "road.npz",
                              crop=spec["crop"], name="test_000")
    scene.road[0] = False
    name = methods.road_method(c["length"], c["width"])
    scales = {scene.name: methods.method_scales(scene, name, camera_height=camera_height)}
    result = methods.evaluate_scenes([scene], name, scales, **c["eval"])
    assert result["failed"][0].startswith("test_000 frame 0: 0 road points")
    s = result["summary"]
    assert s["n_fallback"] >= 1 and s["n_frames"] + s["n_not_evaluable"] == scene.n_frames
    assert result["frames"][0]["source"] in ("next", "raw") and result["frames"][0]["evaluated"]
    assert all(np.isfinite(v) for k, v in s.items() if isinstance(v, float))


def test_road_plane_recovers_a_known_scale_of_the_lidar_depth(built, cfg):
    """The geometry on the world itself: with the LiDAR depth / 30 as the 'network output' (camera and road
    masks as prepared), the road-plane scale is 30 within 5 % on every test frame."""
    from redsup.depth import calibration

    c = cfg["calibration"]
    spec = cfg["datasets"][c["dataset"]]
    camera_height = _camera_height(built, cfg)
    prepared = built / "results" / "prepared" / c["dataset"] / "test_000"
    scene = inputs.load_scene(built / "results" / "depth" / "predictions" / c["dataset"] / c["mode"] / "test_000.npz",
                              prepared / f"{cfg['detection']['camera']}_depth.npz", prepared / "road.npz",
                              crop=spec["crop"], name="test_000")
    for i in range(scene.n_frames):
        scale, reason = calibration.calibrate_frame(scene.gt[i] / 30.0, scene.road_gt[i], scene.gt_K, camera_height,
                                                    max_length=c["length"], max_width=c["width"])
        assert reason is None and scale == pytest.approx(30.0, rel=0.05), i
