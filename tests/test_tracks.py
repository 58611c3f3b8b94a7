"""3D tracks by pseudo-centres (McCraith ch. 6) and MedianFlow box tracks of velocity clips (ch. 3)."""
from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest

from redsup.prep import masks_io
from redsup.prep.medianflow import _new_tracker, track_backward, tracker_settings, upscale, write_medianflow
from redsup.prep.tracks3d import COLUMNS, link_frames, write_tracks3d
from redsup.sceneio import SceneError

LIDAR_HEIGHT = 1.5
TRACKING = {"min_score": 0.5, "min_points": 3, "max_distance": 2.0, "max_count_ratio": 2.0}


def cluster(centre_vehicle, n: int, seed: int = 0) -> np.ndarray:
    """n LiDAR-frame points scattered +-0.3 m around a vehicle-frame centre (LiDAR 1.5 m above it)."""
    rng = np.random.default_rng(seed)
    pts = np.asarray(centre_vehicle, float) + rng.uniform(-0.3, 0.3, (n, 3))
    pts[:, 2] -= LIDAR_HEIGHT
    return np.hstack([pts, np.full((n, 1), 0.4)]).astype(np.float32)


def write_case(root: Path, detections: list[tuple[int, np.ndarray, int]], ego_x: list[float],
               score: float = 0.9) -> tuple[Path, Path]:
    """A scene folder (ego poses translating along x, extrinsics) and a detections npz from
    (frame, points, matched_track) triples."""
    scene = root / "scene"
    scene.mkdir(parents=True, exist_ok=True)
    poses = np.tile(np.eye(4)[:3], (len(ego_x), 1, 1))
    poses[:, 0, 3] = ego_x
    np.savetxt(scene / "ego_poses.txt", poses.reshape(len(ego_x), 12))
    T_vl = np.eye(4)
    T_vl[2, 3] = LIDAR_HEIGHT
    (scene / "extrinsics.json").write_text(json.dumps({"lidar_top": T_vl.tolist(), "cam_front": np.eye(4).tolist()}))
    pts = [p for _, p, _ in detections]
    path = root / "detections_test.npz"
    np.savez(path, frame=np.array([f for f, _, _ in detections], np.int32),
             score=np.full(len(detections), score, np.float32),
             matched_track=np.array([t for _, _, t in detections], np.int32),
             points=np.concatenate(pts) if pts else np.zeros((0, 4), np.float32),
             point_offsets=masks_io.offsets_from_counts([len(p) for p in pts]))
    return scene, path


def run_tracks(tmp_path, detections, ego_x, cfg=TRACKING, score=0.9) -> tuple[pd.DataFrame, dict]:
    scene, path = write_case(tmp_path, detections, ego_x, score)
    summary = write_tracks3d(scene, path, tmp_path / "tracks3d_test.csv", cfg)
    table = pd.read_csv(tmp_path / "tracks3d_test.csv")
    assert list(table.columns) == COLUMNS
    return table, summary


def test_links_one_metre_move_under_ego_motion(tmp_path):
    # ego drives 5 m forward per frame, the car 1 m: in the vehicle frame it appears 4 m closer each frame
    dets = [(0, cluster((10, 2, 0.8), 60, 0), 7), (1, cluster((6, 2, 0.8), 55, 1), 7),
            (2, cluster((2, 2, 0.8), 50, 2), 7)]
    table, summary = run_tracks(tmp_path, dets, ego_x=[0, 5, 10])
    assert table["track"].nunique() == 1 and summary["n_links"] == 2
    assert summary["link_gt_consistent"] == 1.0 and summary["mean_track_length"] == 3.0
    row = table.iloc[1]
    assert row["cx"] == pytest.approx(6, abs=0.15) and row["cz"] == pytest.approx(0.8, abs=0.15)
    assert row["n_points"] == 55 and row["detection"] == 1 and row["frame"] == 1


def test_refuses_three_metre_jump_and_fivefold_point_change(tmp_path):
    jump = [(0, cluster((10, 2, 0.8), 60), 1), (1, cluster((8, 2, 0.8), 60), 1)]  # world: 10 -> 13 m
    table, summary = run_tracks(tmp_path / "a", jump, ego_x=[0, 5])
    assert table["track"].nunique() == 2 and summary["n_links"] == 0
    count = [(0, cluster((10, 2, 0.8), 40), 1), (1, cluster((10, 2, 0.8), 200), 1)]
    table, summary = run_tracks(tmp_path / "b", count, ego_x=[0, 0])
    assert table["track"].nunique() == 2 and summary["n_links"] == 0
    fine = [(0, cluster((10, 2, 0.8), 40), 1), (1, cluster((10, 2, 0.8), 60), 1)]
    table, _ = run_tracks(tmp_path / "c", fine, ego_x=[0, 0])
    assert table["track"].nunique() == 1


def test_greedy_one_to_one_and_gaps(tmp_path):
    dets = [(0, cluster((10, 0, 0.8), 50), 1),
            (1, cluster((10.5, 0, 0.8), 50), 2), (1, cluster((10.2, 0.3, 0.8), 50), 1),  # two candidates
            (3, cluster((10.2, 0.3, 0.8), 50), 1)]  # frame 2 has no detection: the track breaks
    table, summary = run_tracks(tmp_path, dets, ego_x=[0, 0, 0, 0])
    tracks = table.set_index("detection")["track"]
    assert tracks[0] == tracks[2] and tracks[1] != tracks[0] and tracks[3] not in (tracks[0], tracks[1])
    assert summary["n_links"] == 1 and summary["n_tracks"] == 3 and summary["n_tracks_multi_frame"] == 1
    c = np.array([[0.0, 0, 0], [5.0, 0, 0]])
    assert link_frames(c, np.array([10, 10]), c[::-1] + 0.5, np.array([10, 10]), 2.0, 2.0) == [(0, 1), (1, 0)]
    assert link_frames(c, np.array([10, 10]), np.zeros((0, 3)), np.zeros(0), 2.0, 2.0) == []


def test_empty_and_single_point_masks_are_skipped_not_nan(tmp_path):
    dets = [(0, cluster((10, 0, 0.8), 30), 1), (0, np.zeros((0, 4), np.float32), -1),
            (1, cluster((20, 5, 0.8), 1), 2), (1, cluster((10, 0, 0.8), 30), 1)]
    table, summary = run_tracks(tmp_path / "a", dets, ego_x=[0, 0])
    assert sorted(table["detection"]) == [0, 3] and summary["n_skipped_few_points"] == 2
    assert np.isfinite(table[["cx", "cy", "cz"]].to_numpy()).all()
    assert all(np.isfinite(v) for v in summary.values()) and summary["n_links"] == 1
    table, summary = run_tracks(tmp_path / "b", dets, ego_x=[0, 0], cfg={**TRACKING, "min_points": 1})
    single = table[table["detection"] == 2].iloc[0]
    assert single["n_points"] == 1 and summary["n_skipped_few_points"] == 1
    low, summary = run_tracks(tmp_path / "c", dets, ego_x=[0, 0], score=0.2)
    assert len(low) == 0 and summary["n_skipped_low_score"] == 4 and summary["mean_track_length"] == 0.0


def test_gt_consistency_counts_wrong_links(tmp_path):
    dets = [(0, cluster((10, 0, 0.8), 30), 1), (1, cluster((10, 0, 0.8), 30), 2),
            (2, cluster((10, 0, 0.8), 30), 2)]
    _, summary = run_tracks(tmp_path, dets, ego_x=[0, 0, 0])
    assert summary["n_links"] == 2 and summary["link_gt_consistent"] == pytest.approx(0.5)


# ----------------------------------------------------------------------------- MedianFlow

H, W = 120, 200


def render_clip(velocity_px=(1.5, 0.5), start=(40.0, 30.0), size=(40, 30), seed=0, n=40):
    """Frames of a textured rectangle sliding at a constant sub-pixel image speed over a textured
    background (alpha-composited, so edges stay consistent); returns frames and true x, y, w, h."""
    rng = np.random.default_rng(seed)
    bg = cv2.GaussianBlur(rng.integers(0, 255, (H, W, 3)).astype(np.uint8), (0, 0), 2).astype(np.float32)
    tex = cv2.GaussianBlur(rng.integers(0, 255, (size[1], size[0], 3)).astype(np.uint8), (0, 0), 1.5)
    frames, truth = [], []
    for t in range(n):
        x, y = start[0] + velocity_px[0] * t, start[1] + velocity_px[1] * t
        M = np.float32([[1, 0, x], [0, 1, y]])
        fg = cv2.warpAffine(tex.astype(np.float32), M, (W, H), flags=cv2.INTER_LINEAR)
        alpha = cv2.warpAffine(np.ones(tex.shape[:2], np.float32), M, (W, H), flags=cv2.INTER_LINEAR)[..., None]
        frames.append((bg * (1 - alpha) + fg).clip(0, 255).astype(np.uint8))
        truth.append((x, y, size[0], size[1]))
    return frames, np.array(truth)


def test_medianflow_recovers_known_image_motion():
    frames, truth = render_clip()
    boxes, failed, gated = track_backward(frames, truth[-1], max_scale_step=0.1)
    assert boxes.shape == (40, 4) and not failed.any() and not gated.any()   # a smooth track: the gate is silent
    assert np.abs(boxes[:, :2] - truth[:, :2]).max() < 1.0
    assert np.abs(np.diff(boxes[:, :2], axis=0) - [1.5, 0.5]).max() < 1.0
    assert np.abs(boxes[:, 2:] - truth[:, 2:]).max() < 1.5


def test_medianflow_on_upscaled_frames_returns_boxes_at_the_clip_scale():
    """Frames upscaled x2 (bilinear): the box goes in and comes out at the clip's scale (pixel centres map as
    (x + 0.5) s - 0.5, sizes x s), so the track still follows the known motion of a small box."""
    frames, truth = render_clip(size=(12, 9))
    scaled = upscale(frames, 2.0)
    assert scaled[0].shape == (2 * H, 2 * W, 3) and upscale(frames, 1.0) is frames and upscale([None], 2.0) == [None]
    boxes, failed, _ = track_backward(scaled, truth[-1], scale=2.0)
    assert not failed.any()
    assert np.abs(boxes[:, :2] - truth[:, :2]).max() < 1.0
    assert np.abs(boxes[:, 2:] - truth[:, 2:]).max() < 1.5    # as at scale 1 (the drift of 40 updates)
    # a box that never moves: the round trip of the coordinate map is exact
    still, _, _ = track_backward(upscale([frames[0]] * 3, 4.0), (10.0, 20.0, 12.0, 9.0), scale=4.0)
    assert still == pytest.approx(np.tile([10.0, 20.0, 12.0, 9.0], (3, 1)), abs=1e-3)


class ScriptedTracker:
    """Stands in for cv2.legacy's MedianFlow: ``update`` returns the next scripted box; records every init."""

    def __init__(self, script: list, inits: list):
        self.script, self.inits = script, inits

    def init(self, frame, box):
        self.inits.append((int(frame[0, 0, 0]), tuple(box)))
        return True

    def update(self, frame):
        return True, self.script.pop(0)


def test_scale_gate_rejects_an_impossible_size_jump_and_restarts_the_tracker(monkeypatch):
    """Backward from frame 5 (index 4): the tracker doubles the box at index 2 (|log scale step| = log 2 = 0.69),
    then keeps that size. With the gate at 0.1 the jump is rejected: index 2 keeps index 3's box, the tracker
    restarts from it on frame 2, and that frame is flagged gated, not failed. A 5 % step passes (0.05 < 0.1)."""
    frames = [np.full((8, 8, 3), k, np.uint8) for k in range(5)]   # pixel value = frame index (seen by init)
    last = (10.0, 10.0, 20.0, 10.0)
    step5 = (10.0, 10.0, 21.0, 10.0)                                # sqrt(w h) x 1.0247: |log| 0.024
    jump = (5.0, 5.0, 40.0, 20.0)                                   # sqrt(w h) x 2 from step5
    inits: list = []
    scripts = [[step5, jump, (5.0, 5.0, 40.0, 20.0)], [(11.0, 10.0, 21.0, 10.0), (12.0, 10.0, 21.0, 10.0)]]
    monkeypatch.setattr(cv2.legacy, "TrackerMedianFlow_create", lambda: ScriptedTracker(scripts.pop(0), inits))
    boxes, failed, gated = track_backward(frames, last, max_scale_step=0.1)
    assert inits == [(4, last), (2, step5)]                         # first on the last frame, then the restart
    assert gated.tolist() == [False, False, True, False, False] and not failed.any()
    np.testing.assert_allclose(boxes, [(12, 10, 21, 10), (11, 10, 21, 10), step5, step5, last])
    # without the gate the jump is taken and nothing restarts
    inits.clear()
    scripts = [[step5, jump, (5.0, 5.0, 40.0, 20.0), (5.0, 5.0, 40.0, 20.0)]]
    boxes, failed, gated = track_backward(frames, last)
    assert len(inits) == 1 and not gated.any() and not failed.any()
    np.testing.assert_allclose(boxes[1:4], [jump, jump, step5])


def opencv_params(tracker) -> dict:
    fs = cv2.FileStorage("params.yaml", cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
    tracker.write(fs)
    reader = cv2.FileStorage(fs.releaseAndGetString(), cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    nodes = {k: reader.getNode(k) for k in ("pointsInGrid", "winSize", "maxLevel", "winSizeNCC")}
    return {k: [n.at(i).real() for i in range(n.size())] if n.isSeq() else n.real() for k, n in nodes.items()}


def test_tracker_settings_reach_opencv_and_unset_keys_keep_its_defaults():
    frame = np.random.default_rng(0).integers(0, 255, (60, 80, 3)).astype(np.uint8)
    defaults = {"pointsInGrid": 10, "winSize": [3, 3], "maxLevel": 5, "winSizeNCC": [30, 30]}
    assert tracker_settings(None) is None and tracker_settings({}) is None
    assert opencv_params(_new_tracker(frame, (20, 20, 12, 9))[0]) == defaults
    tracker, ok = _new_tracker(frame, (20, 20, 12, 9), tracker_settings({"win_size_ncc": 7, "max_level": 2}))
    assert ok and opencv_params(tracker) == {**defaults, "winSizeNCC": [7, 7], "maxLevel": 2}
    with pytest.raises(ValueError, match="winsize"):
        tracker_settings({"winsize": 5})


def test_track_split_passes_the_configured_tracker_settings(tmp_path, monkeypatch):
    seen = []
    real = _new_tracker

    def spy(frame, box, settings=None):
        seen.append(settings)
        return real(frame, box, settings)

    monkeypatch.setattr("redsup.prep.medianflow._new_tracker", spy)
    frames, truth = render_clip(n=5)
    write_clip(tmp_path / "val", 1, frames, [vehicle(truth[-1], 30.0, 0)])
    cfg = {"n_frames": 5, "near": 20.0, "far": 45.0, "tracker": {"win_size_ncc": 7}}
    write_medianflow(tmp_path / "val", tmp_path / "mf.npz", cfg)
    assert seen == [tracker_settings({"win_size_ncc": 7})]
    assert "winSizeNCC: [ 7, 7 ]" in seen[0]


def write_clip(split: Path, n: int, frames, vehicles: list[dict]) -> None:
    imgs = split / "clips" / str(n) / "imgs"
    imgs.mkdir(parents=True)
    for k, frame in enumerate(frames, start=1):
        cv2.imwrite(str(imgs / f"{k:03d}.png"), frame)
    (imgs.parent / "annotation.json").write_text(json.dumps(vehicles))


def vehicle(box, z, track_id):
    x, y, w, h = (float(v) for v in box)
    return {"bbox": {"top": y, "left": x, "bottom": y + h, "right": x + w}, "velocity": [0.5, -1.0],
            "position": [z, 1.0], "track_id": track_id}  # TuSimple order: [forward, lateral]


def test_medianflow_split_file_failures_and_bins(tmp_path):
    split = tmp_path / "test"
    frames, truth = render_clip()
    write_clip(split, 2, frames, [vehicle(truth[-1], 12.0, 5), vehicle((150, 80, 30, 20), 50.0, 6)])
    gone = [np.full_like(f, 90) if t < 20 else f for t, f in enumerate(render_clip((1.0, 0.0), seed=1)[0])]
    write_clip(split, 10, gone, [vehicle(render_clip((1.0, 0.0), seed=1)[1][-1], 30.0, 1)])
    (split / "calibration.txt").write_text("100 100 100 60\n1.5\n")
    summary = write_medianflow(split, tmp_path / "medianflow.npz", {"n_frames": 40, "near": 20.0, "far": 45.0})
    with np.load(tmp_path / "medianflow.npz") as d:
        assert d["boxes"].shape == (3, 40, 4) and d["boxes"].dtype == np.float32 and d["failed"].shape == (3, 40)
        assert d["gated"].shape == (3, 40) and not d["gated"].any()       # the gate is off unless configured
        assert d["clip"].tolist() == [2, 2, 10] and d["track_id"].tolist() == [5, 6, 1]
        assert d["bin"].tolist() == ["near", "far", "medium"] and d["bin_index"].tolist() == [0, 2, 1]
        np.testing.assert_allclose(d["velocity"][0], [0.5, -1.0])
        np.testing.assert_allclose(d["position"][2], [30.0, 1.0])
        np.testing.assert_allclose(d["boxes"][0, -1], truth[-1], atol=1e-4)
        assert np.isfinite(d["boxes"]).all() and not d["failed"][0].any()
        failed = d["failed"][2]
        assert failed[:19].all() and not failed[20:].any()
        assert (d["boxes"][2, :19] == d["boxes"][2, 19]).all()  # a failed update keeps the last box
    assert summary["vehicles_with_failure"] >= 1 and summary["n_near"] == summary["n_far"] == summary["n_medium"] == 1


def test_medianflow_bad_clips_are_counted_per_clip_and_name_the_file(tmp_path):
    cfg = {"n_frames": 40, "near": 20.0, "far": 45.0}
    frames, truth = render_clip(n=40)
    split = tmp_path / "s"
    write_clip(split, 1, frames, [vehicle(truth[-1], 12.0, 1)])                     # clean
    write_clip(split, 2, frames, [vehicle(truth[-1], 12.0, 2)])
    (split / "clips" / "2" / "imgs" / "010.png").unlink()                           # one frame missing
    write_clip(split, 3, frames[:39], [vehicle(truth[-1], 12.0, 3)])                # the last frame missing
    write_clip(split, 4, frames, [vehicle(truth[-1], 12.0, 4)])
    (split / "clips" / "4" / "annotation.json").write_text("[{")                    # malformed annotation
    summary = write_medianflow(split, tmp_path / "m.npz", cfg)
    assert summary["n_clips_skipped"] == 1 and summary["n_clips_missing_frames"] == 2
    assert summary["n_vehicles"] == 3 and summary["n_clips"] == 3
    text = "\n".join(summary["problems"])
    assert "clips/4/annotation.json" in text and "010.png missing" in text and "040.png missing" in text
    with np.load(tmp_path / "m.npz") as d:
        assert d["clip"].tolist() == [1, 2, 3]
        assert not d["failed"][0].any()
        assert d["failed"][1, 9] and d["failed"][1].sum() == 1                      # only the missing frame
        np.testing.assert_allclose(d["boxes"][1, :9], d["boxes"][0, :9], atol=1.0)  # tracking went on before it
        assert d["failed"][2].all()                                                 # cannot initialise
    only_bad = tmp_path / "bad"
    write_clip(only_bad, 1, frames, [vehicle(truth[-1], 12.0, 1)])
    (only_bad / "clips" / "1" / "annotation.json").write_text("{}")
    with pytest.raises(SceneError, match="annotation.json"):
        write_medianflow(only_bad, tmp_path / "b.npz", cfg)


def test_medianflow_on_real_tusimple_clip(tmp_path, realdata):
    summary = write_medianflow(realdata / "tusimple_velocity" / "train", tmp_path / "m.npz",
                               {"n_frames": 40, "near": 20.0, "far": 45.0})
    with np.load(tmp_path / "m.npz") as d:
        steps = np.abs(np.diff(d["boxes"][0, :, :2], axis=0))
    assert summary["n_vehicles"] == 1 and steps.max() < 10
