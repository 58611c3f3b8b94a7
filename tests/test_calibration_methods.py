"""McCraith ch. 5 scaling methods on synthetic scenes: known per-frame scales, failed fits and their fallback,
the same frames for every method, tables with paired bootstrap records."""
import math

import numpy as np
import pytest

from redsup.calib import inputs, methods
from redsup.calib import tables as calib_tables
from redsup.depth import calibration
from redsup.prep import masks_io
from redsup.tables import align, paper_table

H_CAM = 1.65
K = np.array([[100.0, 0.0, 63.5], [0.0, 100.0, 31.5], [0.0, 0.0, 1.0]])
SIZE = (64, 128)  # prediction (H, W); the ground truth is twice as large
SCALES = (20.0, 35.0, 27.0)  # metres per network unit, per frame


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def _metric_depth(K_, size, normal, car=True):
    """Camera-z depth of a road plane n.X + 1.65 = 0 below the horizon, a slanted facade 20-40 m away
    elsewhere, and a car (a slanted face 8-12 m away) on the road."""
    h, w = size
    v, u = np.mgrid[0:h, 0:w].astype(float)
    rays = np.stack([u, v, np.ones_like(u)], -1) @ np.linalg.inv(K_).T
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -H_CAM / (rays @ normal)
    facade = 20.0 + 20.0 * u / w
    road = (t > 0) & (t < facade)
    depth = np.where(road, t, facade)
    if car:
        r = h / 64
        rows, cols = slice(int(36 * r), int(44 * r)), slice(int(20 * r), int(44 * r))
        depth[rows, cols] = np.minimum(depth[rows, cols], 8.0 + 4.0 * (u[rows, cols] - 20 * r) / (24 * r))
    return depth, road


def _scene(normal=(0.0, -1.0, -0.035), empty_road_frame=None, seed=0):
    rng = np.random.default_rng(seed)
    normal = _unit(normal)  # about 2 degrees of pitch
    K2 = K.copy()
    K2[:2] *= 2
    K2[:2, 2] += 0.5  # pixel-centre convention of a 2x resize
    metric, road = _metric_depth(K, SIZE, normal)
    gt_full, road_full = _metric_depth(K2, (2 * SIZE[0], 2 * SIZE[1]), normal)
    sparse = np.zeros(gt_full.shape, bool)
    sparse[::3, ::2] = True
    preds, gts, roads = [], [], []
    for i, s in enumerate(SCALES):
        noise = 1.0 + 0.01 * rng.standard_normal(SIZE)
        preds.append(metric / s * noise)
        gts.append(np.where(sparse, gt_full, 0.0))
        mask = road.copy()  # the segmenter also marks the car as road (outliers for the fit)
        mask[36:44, 20:44] = True
        if i == empty_road_frame:
            mask[:] = False
        roads.append(mask)
    return inputs.SceneInputs("test_000", np.stack(preds).astype(np.float32), K, np.stack(gts).astype(np.float32),
                              np.stack(roads), K2, np.stack([road_full] * len(SCALES)))


def test_road_plane_recovers_the_per_frame_scale():
    scene = _scene()
    scales = methods.road_scales(scene, camera_height=H_CAM, length=30.0, width=3.0, min_points=20, n_iter=300,
                                 max_tilt_deg=None, seed=0)
    for (s, reason), truth in zip(scales, SCALES):
        assert reason is None
        assert s == pytest.approx(truth, rel=0.01)
    # the per-frame GT ratio recovers it too (on the resized prediction, at the GT resolution), also on the
    # road-box pixels only
    for (s, reason), truth in zip(methods.gt_scales(scene), SCALES):
        assert reason is None and s == pytest.approx(truth, rel=0.01)
    for (s, reason), truth in zip(methods.road_gt_scales(scene, camera_height=H_CAM, length=30.0, width=3.0), SCALES):
        assert reason is None and s == pytest.approx(truth, rel=0.02)  # ratio of medians over a car edge


def test_evaluation_of_the_methods():
    scene = _scene()
    results = {}
    single = methods.single_scale([scene])
    assert single["scale"] == pytest.approx(np.median(SCALES), rel=0.01) and single["n_frames"] == 3
    for name in ("gt_median", "single_test", "fixed_plane", "road_L30_W3"):
        scales = {scene.name: methods.method_scales(scene, name, camera_height=H_CAM, single=single["scale"])}
        if name == "gt_median":
            assert scales[scene.name] is None
            scales = None
        results[name] = methods.evaluate_scenes([scene], name, scales)
    summary = {k: r["summary"] for k, r in results.items()}
    assert summary["road_L30_W3"]["abs_rel"] < 0.03
    assert summary["road_L30_W3"]["scale_rel_err"] < 0.01
    assert summary["gt_median"]["abs_rel"] < 0.03
    # one scale for frames whose true scales differ by 1.75x is far worse
    assert summary["single_test"]["abs_rel"] > 0.1
    # a fixed horizontal plane misreads the pitched road
    assert summary["fixed_plane"]["scale_rel_err"] > 0.05 > summary["road_L30_W3"]["scale_rel_err"]
    for s in summary.values():
        assert s["n_frames"] == 3 and s["n_not_evaluable"] == 0
        assert s["coverage"] == 1.0 and s["n_fallback"] == 0


def test_fill_failed_by_hand():
    ok = [(None, "a"), (2.0, None), (None, "b"), (None, "c"), (5.0, None), (None, "d")]
    assert methods.fill_failed(ok) == [(2.0, "next"), (2.0, "fit"), (2.0, "previous"), (2.0, "previous"),
                                       (5.0, "fit"), (5.0, "previous")]
    assert methods.fill_failed(ok, "raw") == [(1.0, "raw"), (2.0, "fit"), (1.0, "raw"), (1.0, "raw"),
                                              (5.0, "fit"), (1.0, "raw")]
    assert methods.fill_failed([(None, "x")] * 2) == [(1.0, "raw")] * 2  # no frame of the scene succeeded
    with pytest.raises(ValueError, match="unknown fallback"):
        methods.fill_failed(ok, "median")


def test_failed_fit_gets_the_fallback_and_every_method_keeps_the_same_frames():
    scene = _scene(empty_road_frame=1)
    good = methods.evaluate_scenes([_scene()], "road_L30_W3",
                                   {"test_000": methods.method_scales(_scene(), "road_L30_W3", camera_height=H_CAM)})
    for name in ("road_L30_W3", "fixed_plane"):
        scales = {scene.name: methods.method_scales(scene, name, camera_height=H_CAM)}
        assert scales[scene.name][1][0] is None
        result = methods.evaluate_scenes([scene], name, scales)
        s = result["summary"]
        assert (s["n_frames"], s["n_fit"], s["n_fallback"], s["n_not_evaluable"]) == (3, 2, 1, 0)
        assert s["coverage"] == pytest.approx(2 / 3)
        f0, f1 = result["frames"][:2]
        assert (f1["fit"], f1["source"], f1["evaluated"]) == (False, "previous", True) and f1["reason"]
        assert f1["scale"] == pytest.approx(f0["scale"])  # frame 0's scale held
        assert len(result["failed"]) == 1 and result["failed"][0].startswith("test_000 frame 1: ")
        assert "previous scale" in result["failed"][0]
        assert sorted(methods.per_frame(result, "abs_rel")) == ["test_000/000000", "test_000/000001",
                                                                "test_000/000002"]
    # frame 1's true scale is 35, frame 0's 20: the held scale costs |20/35 - 1| = 0.43 on that frame
    held = methods.evaluate_scenes([scene], "road_L30_W3",
                                   {scene.name: methods.method_scales(scene, "road_L30_W3", camera_height=H_CAM)})
    assert held["frames"][1]["abs_rel"] == pytest.approx(1 - 20 / 35, abs=0.02)
    assert held["summary"]["abs_rel"] > good["summary"]["abs_rel"] + 0.1
    # a failure on the first frame takes the next successful frame's scale
    first = _scene(empty_road_frame=0)
    r = methods.evaluate_scenes([first], "road_L30_W3",
                                {first.name: methods.method_scales(first, "road_L30_W3", camera_height=H_CAM)})
    assert r["frames"][0]["source"] == "next" and r["frames"][0]["scale"] == pytest.approx(r["frames"][1]["scale"])
    # a scene where every frame fails: the raw output (scale 1) on every frame, counted, coverage 0
    empty = _scene()
    empty.road[:] = False
    result = methods.evaluate_scenes([empty], "road_L30_W3",
                                     {empty.name: methods.method_scales(empty, "road_L30_W3", camera_height=H_CAM)})
    s = result["summary"]
    assert (s["n_frames"], s["n_fit"], s["coverage"]) == (3, 0, 0.0)
    assert [f["scale"] for f in result["frames"]] == [1.0] * 3 and s["abs_rel"] > 0.9
    row = calib_tables.metrics_row(result)
    assert row["frames"] == 3 and row["coverage"] == 0.0


def test_frame_without_ground_truth_is_left_out_for_every_method():
    scene = _scene()
    scene.gt[2] = 0.0  # no LiDAR return in frame 2
    units = set()
    for name in ("gt_median", "single_test", "road_L30_W3"):
        scales = methods.method_scales(scene, name, camera_height=H_CAM, single=27.0)
        r = methods.evaluate_scenes([scene], name, None if scales is None else {scene.name: scales})
        assert (r["summary"]["n_frames"], r["summary"]["n_not_evaluable"]) == (2, 1)
        assert r["not_evaluable"][0].startswith("test_000 frame 2: no valid ground-truth pixel")
        units.add(tuple(sorted(methods.per_frame(r, "abs_rel"))))
    assert units == {("test_000/000000", "test_000/000001")}


def test_method_names():
    assert methods.road_method(30.0, 3.0) == "road_L30_W3"
    assert methods.road_method(30, 0.5) == "road_L30_W0.5"
    assert methods.parse_method("road_L30_W0.5") == {"kind": "road", "length": 30.0, "width": 0.5}
    assert methods.parse_method("single_train") == {"kind": "single", "split": "train"}
    with pytest.raises(ValueError, match="unknown calibration method"):
        methods.parse_method("road_L30")
    with pytest.raises(ValueError, match="single scale"):
        methods.method_scales(_scene(), "single_train", camera_height=H_CAM)


def test_crop_resize_nearest_by_hand():
    mask = np.arange(24).reshape(4, 6)
    crop = {"top": 1, "bottom": 1, "left": 0, "right": 2}  # keeps rows 1-2, columns 0-3
    # 4 x 2 -> 2 x 1: output pixel centres fall in input row 1 of the cut, columns 1 and 3
    assert inputs.crop_resize_nearest(mask, crop, (2, 1)).tolist() == [[13, 15]]
    # identity size: just the crop
    assert inputs.crop_resize_nearest(mask, crop, (4, 2)).tolist() == [[6, 7, 8, 9], [12, 13, 14, 15]]
    # upsampling repeats pixels; a stack of masks is resized frame by frame
    up = inputs.crop_resize_nearest(np.stack([mask, mask + 100]), crop, (8, 4))
    assert up.shape == (2, 4, 8) and up[1, 3, 7] == 115 and up[0, 0, 0] == 6
    with pytest.raises(ValueError, match="leaves nothing"):
        inputs.crop_resize_nearest(mask, {"top": 2, "bottom": 2, "left": 0, "right": 0}, (2, 2))


def test_resize_depth_interpolates_disparity():
    pred = np.array([[1.0, 2.0]], dtype=np.float32)
    up = inputs.resize_depth(pred, (1, 4))
    # bilinear in disparity with pixel centres: disparities 1, 0.875, 0.625, 0.5
    assert up[0] == pytest.approx(1.0 / np.array([1.0, 0.875, 0.625, 0.5]))
    assert inputs.resize_depth(pred, (1, 2)) == pytest.approx(pred)
    bad = inputs.resize_depth(np.array([[1.0, 2.0, 0.0]], dtype=np.float32), (1, 6))
    assert np.isfinite(bad[0, 0]) and not np.isfinite(bad[0, 5])  # an invalid depth is not interpolated


def test_load_scene_brings_road_masks_to_the_prediction(tmp_path):
    crop = {"top": 2, "bottom": 2, "left": 0, "right": 0}
    raw = np.zeros((2, 8, 8), bool)  # raw masks 8 x 8 -> cut 8 x 4 -> prediction 4 x 2
    raw[:, 4:6, :4] = True
    np.savez(tmp_path / "pred.npz", depth=np.ones((2, 2, 4), np.float32), K=np.eye(3))
    np.savez(tmp_path / "gt.npz", depth=np.ones((2, 4, 8), np.float32))
    np.savez(tmp_path / "road.npz", road=masks_io.pack_masks(list(raw), (8, 8)), image_size=np.array([8, 8]))
    scene = inputs.load_scene(tmp_path / "pred.npz", tmp_path / "gt.npz", tmp_path / "road.npz", crop=crop)
    assert scene.name == "pred" and scene.n_frames == 2
    assert scene.road.shape == (2, 2, 4)
    assert scene.road[0].tolist() == [[False] * 4, [True, True, False, False]]
    np.savez(tmp_path / "gt3.npz", depth=np.ones((3, 4, 8), np.float32))
    with pytest.raises(ValueError, match="3 ground-truth frames"):
        inputs.load_scene(tmp_path / "pred.npz", tmp_path / "gt3.npz")
    np.savez(tmp_path / "gt_big.npz", depth=np.ones((2, 6, 8), np.float32))
    with pytest.raises(ValueError, match="cropped by"):
        inputs.load_scene(tmp_path / "pred.npz", tmp_path / "gt_big.npz", tmp_path / "road.npz", crop=crop)


def _fake_result(method, abs_rel, units=("test_000/000000", "test_000/000001", "test_000/000002"), failed=0):
    """A method result on ``units`` with per-frame Abs Rel ``abs_rel`` (a list, one per unit)."""
    frames = []
    for i, (u, v) in enumerate(zip(units, abs_rel)):
        f = {"unit": u, "evaluated": True, "fit": i >= failed, "abs_rel": v, "sq_rel": v, "rmse": v,
             "rmse_log": v, "a1": 0.9, "a2": 0.95, "a3": 0.99}
        frames.append(f)
    summary = {k: float(np.mean([f[k] for f in frames])) for k in ("abs_rel", "sq_rel", "rmse", "rmse_log", "a1",
                                                                  "a2", "a3")}
    summary.update(n_frames=len(frames), n_fit=len(frames) - failed, coverage=1 - failed / len(frames),
                   n_not_evaluable=0, scale_rel_err=0.05)
    return {"method": method, "summary": summary, "frames": frames,
            "failed": [f"test_000 frame {i}: why -> previous scale 20" for i in range(failed)], "not_evaluable": []}


CAL = {"dataset": "world_x", "mode": "M", "length": 30.0, "width": 3.0, "fallback": "hold",
       "tables": {"mccraith_ch5_table1": {"rows": [
                      {"label": "(a) GT Single Scaling (training set)", "run": "single_train"},
                      {"label": "(b) GT Single Scaling (testing set)", "run": "single_test"},
                      {"label": "(c) Fixed road plane", "run": "fixed_plane"},
                      {"label": "(d) Ours", "run": "ours"},
                      {"label": "GT Scaling (per-frame median, reference)", "run": "gt_median"}],
                      "note": "box {width:g} x {length:g}"},
                  "mccraith_ch5_table2": {"rows": [{"label": "Godard et al. [2019]", "run": "gt_median"},
                                                   {"label": "Ours", "run": "ours"}]},
                  "mccraith_ch5_table3": {"rows": [{"label": "{length}", "run": "ours", "sweep": {"length": [6, 10, 30]}}]},
                  "mccraith_ch5_table4": {"rows": [{"label": "{width}", "run": "ours", "sweep": {"width": "$values"}}],
                                          "values": [0.5, 3]},
                  "mccraith_ch5_fig1": {"series": "long"}}}


def _scenes_of(dataset):
    return ["train_000", "train_001", "test_000", "long_000"]


def test_tables_use_the_paper_row_and_column_names_and_carry_paired_bootstrap_records():
    from redsup.calib import plan
    from redsup.tables.noise import difference_interval

    config = {"calibration": CAL, "profile": "tiny"}
    rows = plan.rows(config, _scenes_of)
    results = {run: _fake_result(run, [0.1 + 0.01 * i, 0.12 + 0.01 * i, 0.11 + 0.01 * i], failed=int(i == 2))
               for i, (_, run, _) in enumerate(rows["mccraith_ch5_table1"])}
    frame = plan.table_frame("mccraith_ch5_table1", config, rows["mccraith_ch5_table1"], results)
    t1 = frame.ours
    aligned = align(t1, paper_table("mccraith_ch5_table1"))
    assert set(paper_table("mccraith_ch5_table1").index) <= set(aligned.index)
    assert set(paper_table("mccraith_ch5_table1").columns) <= set(aligned.columns)
    assert t1.loc["(d) Ours", "Abs Rel"] == pytest.approx(0.14)  # mean of 0.13, 0.15, 0.14
    assert t1.loc["(c) Fixed road plane", "coverage"] == pytest.approx(2 / 3)
    assert list(t1["frames"]) == [3] * 5
    # every metric cell has a bootstrap record over the same 3 frames: the rows are paired
    a, b = frame.noise["(d) Ours"]["Abs Rel"], frame.noise["(a) GT Single Scaling (training set)"]["Abs Rel"]
    assert a["kind"] == b["kind"] == "bootstrap" and a["units"] == b["units"] and len(a["values"]) == 200
    lo, hi, how = difference_interval(0.14, 0.11, a, b)
    # the 3 frames come from one test scene: their test-sampling noise cannot be measured, no verdict
    assert math.isnan(lo) and how == "test units in 1 clusters (fewer than 5)"
    # over 5 scenes a per-frame difference of exactly 0.03 gives a paired interval without width
    spread = tuple(f"test_{g:03d}/000000" for g in range(5))
    five = {r: _fake_result(r, [0.1, 0.12, 0.11, 0.1, 0.12], units=spread) for _, r, _ in rows["mccraith_ch5_table1"]}
    five[rows["mccraith_ch5_table1"][0][1]] = _fake_result("x", [0.13, 0.15, 0.14, 0.13, 0.15], units=spread)
    noise5 = plan.table_frame("mccraith_ch5_table1", config, rows["mccraith_ch5_table1"], five).noise
    first, other = (frame.ours.index[0], frame.ours.index[1])
    lo, hi, how = difference_interval(0.14, 0.11, noise5[first]["Abs Rel"], noise5[other]["Abs Rel"])
    assert how == "paired cluster bootstrap, 5 clusters" and lo == pytest.approx(0.03) and hi == pytest.approx(0.03)
    assert "box 3 x 30" in frame.note and "same 3 test frames" in frame.note
    assert "(c) Fixed road plane: 1 failed fit(s)" in frame.note
    # rows over different frames are refused
    results[rows["mccraith_ch5_table1"][0][1]] = _fake_result("x", [0.1, 0.1], units=("a/000000", "a/000001"))
    with pytest.raises(ValueError, match="same frames"):
        plan.table_frame("mccraith_ch5_table1", config, rows["mccraith_ch5_table1"], results)
    # a sweep: row labels are the values, the index says which side varies
    sweep = {run: _fake_result(run, [0.2, 0.2, 0.2]) for _, run, _ in rows["mccraith_ch5_table3"]}
    t3 = plan.table_frame("mccraith_ch5_table3", config, rows["mccraith_ch5_table3"], sweep).ours
    assert list(t3.index) == ["6", "10", "30"] and t3.index.name == "Length (m)"
    assert set(align(t3, paper_table("mccraith_ch5_table3")).index) >= {"6", "10", "30"}
    # Fig. 1's series table: its note follows the generated caption
    series = {"frames": [{"scene": "long_000", "gt": g, "ours": o, "road_gt": g} for g, o in ((20.0, 21.0), (40.0, 38.0))],
              "single_scale": 30.0}
    cfg_note = {"calibration": {**CAL, "tables": {**CAL["tables"], "mccraith_ch5_fig1": {
        "series": "long", "note": "why it spans 2x (box {length:g} m)."}}}, "profile": "tiny"}
    fig1 = plan.table_frame("mccraith_ch5_fig1", cfg_note, rows["mccraith_ch5_fig1"],
                            {r[1]: series for r in rows["mccraith_ch5_fig1"]})
    assert fig1.note.endswith("No frame skipped. why it spans 2x (box 30 m)")
    assert fig1.ours.loc[calib_tables.FIG1_GT_ROW, "max/min"] == pytest.approx(2.0)
    fig = calib_tables.fig1_table([20.0, 40.0, None], [21.0, 38.0, 30.0], 30.0, road_gt=[20.0, 38.0, 33.0])
    assert fig.loc[calib_tables.FIG1_GT_ROW, "max/min"] == pytest.approx(2.0)
    assert fig.loc[calib_tables.FIG1_OURS_ROW, "median |x / GT - 1|"] == pytest.approx(0.05)
    assert fig.loc[calib_tables.FIG1_SINGLE_ROW, "median |x / GT - 1|"] == pytest.approx(0.375)
    assert fig.loc[calib_tables.FIG1_OURS_ROW, "median |ours / road GT - 1|"] == pytest.approx(0.05)


def test_plan_lists_the_jobs_as_data():
    from redsup.calib import plan

    config = {"calibration": CAL, "detection": {"camera": "cam_front"}}
    rows = plan.rows(config, _scenes_of)
    assert [r[1] for r in rows["mccraith_ch5_table1"]] == [
        "world_x/M/single_train", "world_x/M/single_test", "world_x/M/fixed_plane", "world_x/M/road_L30_W3",
        "world_x/M/gt_median"]
    assert rows["mccraith_ch5_table3"] == [("6", "world_x/M/road_L6_W3", None), ("10", "world_x/M/road_L10_W3", None),
                                           ("30", "world_x/M/road_L30_W3", None)]
    assert [r[:2] for r in rows["mccraith_ch5_table4"]] == [("0.5", "world_x/M/road_L30_W0.5"),
                                                            ("3", "world_x/M/road_L30_W3")]
    assert {r[1] for r in rows["mccraith_ch5_fig1"]} == {"world_x/M/series_long"}
    assert plan.result_path("world_x/M/gt_median") == "results/calibration/world_x/M/gt_median.json"
    runs = plan.runs(config, _scenes_of)
    assert len(runs) == 5 + 2 + 1 + 1  # 5 methods, road_L6/L10, road_L30_W0.5, the series
    assert runs["world_x/M/road_L30_W3"]["tables"] == ["mccraith_ch5_table1", "mccraith_ch5_table2",
                                                      "mccraith_ch5_table3", "mccraith_ch5_table4"]
    assert plan.parent_of(config, _scenes_of, "world_x", "M", "road_L6_W3") == "mccraith_ch5_table3"
    assert plan.figure_series(config) == {"mccraith_ch5_fig1": "world_x/M/series_long"}
    assert plan.rows(config, lambda d: ["train_000"]) == {}  # no test scene: no table rows
    scenes = _scenes_of("world_x")
    files = plan.eval_inputs(config, scenes, "world_x", "M", "single_train")
    assert files["pred"] == ["results/depth/predictions/world_x/M/test_000.npz"]
    assert files["gt"] == ["results/prepared/world_x/test_000/cam_front_depth.npz"]
    assert files["road"] == ["results/prepared/world_x/test_000/road.npz"]
    assert files["raw"] == ["results/raw/world_x/test_000"]
    assert files["train_pred"] == [f"results/depth/predictions/world_x/M/train_00{i}.npz" for i in (0, 1)]
    assert "train_pred" not in plan.eval_inputs(config, scenes, "world_x", "M", "road_L6_W3")
    series = plan.series_inputs(config, scenes, "world_x", "M", "long")
    assert series["raw"] == ["results/raw/world_x/long_000"]
    assert series["single"] == "results/calibration/world_x/M/single_train.json"
    import re

    for name in ("gt_median", "single_train", "road_L30_W0.5"):
        assert re.fullmatch(plan.METHOD_PATTERN, name) and methods.parse_method(name)


def test_camera_height_comes_from_the_scene_extrinsics(tmp_path):
    import json

    scene = tmp_path / "test_000"
    scene.mkdir()
    T = np.eye(4)
    T[:3, 3] = (1.2, 0.0, 1.73)  # camera 1.73 m above the vehicle origin on the road
    (scene / "extrinsics.json").write_text(json.dumps({"cam_front": T.tolist(), "lidar_top": np.eye(4).tolist()}))
    (scene / "scene.json").write_text(json.dumps({"scene": "test_000", "dataset": "x", "domain": "real",
                                                  "split": "test", "fps": 10.0, "n_frames": 3,
                                                  "cameras": ["cam_front"], "lidars": ["lidar_top"], "seed": 0}))
    assert inputs.camera_geometry(scene, "cam_front") == {"camera_height": pytest.approx(1.73), "fps": 10.0}
    with pytest.raises(ValueError, match="extrinsics.json.*cam_back"):
        inputs.camera_geometry(scene, "cam_back")
    T[2, 3] = -0.1
    (scene / "extrinsics.json").write_text(json.dumps({"cam_front": T.tolist()}))
    with pytest.raises(ValueError, match="must be > 0"):
        inputs.camera_geometry(scene, "cam_front")
