"""In-box / in-mask LiDAR outlier fraction by distance (issue 11 §4, redsup.prep.outliers): by hand on the
hand-made scene of test_detection, on the genuine KITTI object sample (skipped without ../shared/realdata) and
on a tiny rendered world."""
import copy
import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from redsup import config, sceneio
from redsup.prep.outliers import by_distance, pixel_rect, scene_records
from redsup.world.generate import write_scene as render_scene
from test_detection import write_scene as hand_scene

ROOT = Path(__file__).resolve().parents[1]
REAL = Path(os.environ.get("REDSUP_REALDATA", ROOT.parent / "shared" / "realdata"))


def test_pixel_rect_of_outer_edges():
    assert pixel_rect({"x1": 9.5, "y1": 19.5, "x2": 21.5, "y2": 29.5}) == (10, 20, 21, 29)
    assert pixel_rect({"x1": 9.2, "y1": 19.9, "x2": 22.0, "y2": 29.4}) == (10, 20, 22, 29)  # centres inside
    assert pixel_rect({"x1": np.nan, "y1": 0, "x2": 1, "y2": 1}) is None
    assert pixel_rect({"x1": 3, "y1": 0, "x2": 3, "y2": 1}) is None


def test_outliers_by_hand(tmp_path):
    """Car 1: three points in its box and mask, one of them seen through the glass 25 m away (outside the
    3D box); car 2: its two points plus one through the notch of its mask (in the box, not the mask)."""
    scene = hand_scene(tmp_path, n_frames=1)
    boxes = sceneio.read_boxes(scene / "gt" / "boxes.csv")
    boxes[["x1", "y1", "x2", "y2"]] = [[9.5, 19.5, 21.5, 29.5], [29.5, 19.5, 45.5, 29.5]]
    boxes.to_csv(scene / "gt" / "boxes.csv", index=False)
    recs = {r["track"]: r for r in scene_records(scene, "cam_front", margin=0.2)}
    assert (recs[1]["n_box"], recs[1]["out_box"], recs[1]["n_mask"], recs[1]["out_mask"]) == (3, 1, 3, 1)
    assert (recs[2]["n_box"], recs[2]["out_box"], recs[2]["n_mask"], recs[2]["out_mask"]) == (3, 1, 2, 0)
    # upper 45 % of rows 20-29 (rows < 24.05): car 1's glass point (row 21) and car 1's b (row 22); the notch (21)
    assert (recs[1]["n_top"], recs[1]["out_top"], recs[2]["n_top"], recs[2]["out_top"]) == (2, 1, 1, 1)
    assert recs[1]["distance"] == pytest.approx(np.hypot(12.5, boxes.loc[0, "y"]))
    near, far = by_distance(list(recs.values()), edges=(0.0, 20.0, 80.0))
    assert near["box_cars"] == 2 and near["box_points"] == 6 and near["box_fraction"] == pytest.approx(2 / 6)
    assert near["mask_points"] == 5 and near["mask_fraction"] == pytest.approx(1 / 5)
    assert near["mask_median"] == pytest.approx(1 / 6)  # median of 1/3 and 0
    assert far["box_cars"] == 0 and far["box_fraction"] is None
    # masks painted from label boxes are no masks: not measured
    assert scene_records(scene, "cam_front", use_masks=False)[0]["n_mask"] is None


@pytest.mark.skipif(not REAL.is_dir(), reason=f"real data samples not found at {REAL}")
def test_outliers_on_the_real_kitti_object_sample(tmp_path):
    """The three labelled cars of frames 000000-000003 (14, 36, 62 m, unoccluded): 28 %, 38 %, 25 % of the
    points in their 2D label box lie outside their 3D box (+ 0.2 m); no masks (instances from label boxes)."""
    from redsup.adapters import adapt_scene, scene_ids

    spec = {"kind": "kitti_object", "path": str(REAL / "kitti_object"),
            "crop": {"top": 0, "bottom": 0, "left": 0, "right": 0}, "resize": {"width": 320, "height": 96},
            "instances": {"source": "label_boxes"}}
    recs = []
    for scene in scene_ids("kitti_object", spec):
        adapt_scene("kitti_object", spec, scene, tmp_path / scene)
        found = scene_records(tmp_path / scene, "cam_front")
        boxes = sceneio.read_boxes(tmp_path / scene / "gt" / "boxes.csv")
        for r in found:
            n_lidar = int(boxes.loc[boxes["track_id"] == r["track"], "n_lidar"].iloc[0])
            assert r["n_box"] - r["out_box"] >= 0.9 * n_lidar  # the box's own points (margin 0) are inliers
        recs += found
    assert len(recs) == 3 and all(r["n_mask"] is None for r in recs)
    rows = pd.DataFrame(by_distance(recs))
    assert rows["box_cars"].tolist() == [1, 1, 1]
    assert rows["box_points"].tolist() == [1019, 111, 12]
    np.testing.assert_allclose(rows["box_fraction"], [281 / 1019, 42 / 111, 3 / 12])
    # most of them in the upper 45 % of the box (glass, background above the bonnet and boot)
    pooled = by_distance(recs, edges=(0.0, 80.0))[0]
    assert pooled["box_top_fraction"] == pytest.approx((2 + 32 + 237) / (2 + 54 + 524))
    assert pooled["box_bottom_fraction"] == pytest.approx((1 + 10 + 44) / (10 + 57 + 495))


def test_outliers_on_a_tiny_rendered_world(tmp_path):
    """Rendered cars: the mask removes most of the box's outliers (background and ground), the box keeps a
    near-range fraction like the real sample's, mostly in its upper part; glass and edges keep a few in the
    mask. (6 train scenes x 4 frames, benchmarks/bench_inmask_outliers.py: see the README's world section.)"""
    cfg = config.load(ROOT / "config.yaml", {"profile": "tiny"})
    world = copy.deepcopy(cfg["world"])
    world["frames"] = {"train": 2, "test": 2, "long": 2}
    recs = []
    for i in range(2):
        render_scene(world, "world_kitti", "kitti_like", "train", i, 5, tmp_path / f"train_{i:03d}")
        recs += scene_records(tmp_path / f"train_{i:03d}", "cam_front")
    near = by_distance(recs, edges=(0.0, 20.0))[0]
    assert near["box_cars"] >= 5 and near["mask_cars"] >= 5
    assert 0.1 < near["box_fraction"] < 0.5
    assert 0.0 < near["mask_fraction"] < 0.5 * near["box_fraction"]
    assert near["box_top_fraction"] > 2 * near["box_bottom_fraction"]
