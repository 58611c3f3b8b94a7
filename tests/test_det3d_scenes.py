"""Object views of a scene: ground-truth frames and per-detection point sets in the vehicle frame."""
import json

import numpy as np
import pandas as pd

from redsup.det3d import scenes
from redsup.prep.masks_io import offsets_from_counts, pack_masks
from redsup.sceneio import BOX_COLUMNS


def _scene(tmp_path):
    scene = tmp_path / "s"
    (scene / "gt").mkdir(parents=True)
    (scene / "scene.json").write_text(json.dumps({"scene": "s", "n_frames": 2, "fps": 10, "cameras": ["cam_front"],
                                                  "lidars": ["lidar_top"]}))
    T_lidar = np.eye(4)
    T_lidar[:3, 3] = [1.0, 0.0, 1.7]
    (scene / "extrinsics.json").write_text(json.dumps({"lidar_top": T_lidar.tolist(), "cam_front": np.eye(4).tolist()}))
    rows = [[0, 1, "car", 10, 2, 0.75, 3.9, 1.6, 1.5, 0.1, 0, 0, 0, 0, 0.0, 100, 50, 140, 80, 900, 50],
            [0, 2, "car", 30, -3, 0.75, 3.9, 1.6, 1.5, 0.0, 0, 0, 0, 3, 1.0, np.nan, np.nan, np.nan, np.nan, 0, 0],
            [1, 1, "car", 9, 2, 0.75, 3.9, 1.6, 1.5, 0.1, 0, 0, 0, 1, 0.2, 102, 50, 142, 80, 800, 40]]
    pd.DataFrame(rows, columns=BOX_COLUMNS).to_csv(scene / "gt" / "boxes.csv", index=False)
    return scene, T_lidar


def test_gt_frames_group_by_frame_and_ignore_invisible(tmp_path):
    scene, _ = _scene(tmp_path)
    frames = scenes.gt_frames(scene)
    assert [len(f.cls) for f in frames] == [2, 1]
    assert list(frames[0].cls) == ["Car", "Car"]
    assert np.allclose(frames[0].boxes[0], [10, 2, 0.75, 3.9, 1.6, 1.5, 0.1])
    assert np.array_equal(frames[0].bbox[1], [0, 0, 0, 0])  # invisible: zero height, ignored
    assert frames[1].occlusion.tolist() == [1]


def test_object_set_moves_points_to_vehicle_frame(tmp_path):
    scene, T_lidar = _scene(tmp_path)
    pts = np.array([[5.0, 0.0, 0.0, 0.3], [6.0, 1.0, -1.0, 0.5], [7.0, 0.0, 0.0, 0.1]], dtype=np.float32)
    masks = pack_masks([np.ones((4, 4), bool), np.zeros((4, 4), bool)], (4, 4))
    np.savez(tmp_path / "det.npz", frame=np.array([0, 1], np.int32), score=np.array([0.9, 0.4], np.float32),
             box=np.zeros((2, 4), np.float32), mask=masks, image_size=np.array([4, 4]),
             matched_track=np.array([1, -1], np.int32), points=pts, point_offsets=offsets_from_counts([2, 1]),
             box_points=pts[:1], box_point_offsets=offsets_from_counts([1, 0]),
             point_inlier_gt=np.array([True, False, True]))
    objs = scenes.object_set(scene, tmp_path / "det.npz")
    assert len(objs) == 2
    assert np.allclose(objs.points_of(0)[:, :3], [[6.0, 0.0, 1.7], [7.0, 1.0, 0.7]])
    assert np.allclose(objs.points_of(0)[:, 3], [0.3, 0.5])
    assert objs.points_of(1).shape == (1, 4) and objs.inlier_gt.tolist() == [True, False, True]
    box = scenes.object_set(scene, tmp_path / "det.npz", source="box")
    assert len(box.points_of(0)) == 1 and len(box.points_of(1)) == 0
