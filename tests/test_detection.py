"""Simulated 2D instance segmenter, noisy road segmenter and LiDAR point sets (redsup.prep) on a
hand-made scene in the canonical format (README, "The canonical raw-scene format")."""
from __future__ import annotations

import copy
import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from scipy.stats import spearmanr

from redsup import sceneio
from redsup.prep import masks_io
from redsup.prep.detections import detect_scene, write_detections
from redsup.prep.detector import (KIND_FALSE_POSITIVE, KIND_MERGED, miss_probability, perturb_boundary,
                                  simulate_frame)
from redsup.prep.road import segment_road, write_road

ROOT = Path(__file__).resolve().parents[1]
W, H = 64, 48
FX = FY = 40.0
CX, CY = 32.0, 24.0
CAM_HEIGHT = 1.5

PERFECT = {"miss_base": 0.0, "miss_small_px": 0, "miss_occluded_fraction": 0.0, "boundary_mean_px": 0.0,
           "boundary_std_px": 0.0, "edge_flip": 0.0, "merge_prob": 0.0, "merge_gap_px": 1, "fp_per_frame": 0.0,
           "fp_labels": [11, 17, 21], "fp_height_px": [4, 10], "score_bias": float(np.log(9.0)),
           "score_size_px": 100, "score_size_gain": 0.0, "score_visibility_gain": 0.0, "score_latent_gain": 0.0,
           "score_noise": 0.0, "mask_quality_coupling": 0.0, "fp_score_offset": float(np.log(0.2 / 0.8) - np.log(9.0))}
CLEAN_ROAD = {"boundary_offset_std_px": 0.0, "boundary_noise_px": 0.0, "noise_cell_px": 20.0,
              "fp_blobs_per_frame": 0.0, "fn_blobs_per_frame": 0.0, "fp_labels": [8, 21], "blob_height_px": [4, 10]}


def detection_cfg(**level) -> dict:
    return {"camera": "cam_front", "classes": ["car"], "reference_height": H, "score_threshold": 0.0,
            "match_iou": 0.5, "levels": {"test": {**PERFECT, **level}}, "road": CLEAN_ROAD,
            "points": {"min_depth": 0.1, "gt_box_margin": 0.2},
            "tracking": {"min_score": 0.0, "min_points": 1, "max_distance": 2.0, "max_count_ratio": 2.0}}


def lidar_point(u: float, v: float, depth: float, reflectance: float = 0.5) -> list[float]:
    """LiDAR-frame point (LiDAR at the camera centre, x forward) seen at pixel (u, v) at that depth."""
    return [depth, -(u - CX) * depth / FX, -(v - CY) * depth / FY, reflectance]


# car 1: full rectangle rows 20-29, cols 10-21; car 2: rows 20-29, cols 30-45 minus a notch rows 20-23, cols 30-35
CAR1 = (slice(20, 30), slice(10, 22))
CAR2 = (slice(20, 30), slice(30, 46))
NOTCH = (slice(20, 24), slice(30, 36))
POINTS = {  # name: (u, v, depth)
    "car1_a": (15, 25, 11.0), "car1_b": (18, 22, 12.0), "car1_glass": (12, 21, 25.0),
    "car2_a": (40, 27, 11.0), "car2_b": (43, 25, 11.5), "notch": (32, 21, 30.0),
    "building": (5, 5, 20.0), "between": (25, 25, 15.0), "road": (30, 40, 6.0),
}
EXTRA = [[-5.0, 0.0, 0.0, 0.1], lidar_point(100, 25, 10.0)]  # behind the camera; outside the image


def gt_box(cols: tuple[int, int], rows: tuple[int, int], near: float, length: float) -> list[float]:
    """Vehicle-frame box whose near face projects onto pixel columns/rows (outer edges)."""
    y_left, y_right = -(cols[0] - 0.5 - CX) * near / FX, -(cols[1] + 0.5 - CX) * near / FX
    z_top, z_bottom = CAM_HEIGHT - (rows[0] - 0.5 - CY) * near / FY, CAM_HEIGHT - (rows[1] + 0.5 - CY) * near / FY
    return [near + length / 2, (y_left + y_right) / 2, (z_top + z_bottom) / 2, length, y_left - y_right,
            z_top - z_bottom, 0.0]


def write_scene(root: Path, n_frames: int = 3, points: dict | None = None, extra_points=None) -> Path:
    """A tiny scene: two cars in cam_front, hand-placed LiDAR points, identity ego poses."""
    scene = root / "scene_000"
    for sub in ("cam_front", "lidar_top", "gt/instance/cam_front", "gt/semantic/cam_front"):
        (scene / sub).mkdir(parents=True, exist_ok=True)
    (scene / "scene.json").write_text(json.dumps({
        "scene": "scene_000", "dataset": "test", "domain": "test", "split": "train", "fps": 10.0,
        "n_frames": n_frames, "cameras": ["cam_front"], "lidars": ["lidar_top"], "seed": 0}))
    K = np.array([[FX, 0, CX], [0, FY, CY], [0, 0, 1]])
    sceneio.write_intrinsics(scene / "cam_front.txt", K, (W, H))
    T_vc = np.eye(4)
    T_vc[:3, :3] = np.array([[0, 0, 1], [-1, 0, 0], [0, -1, 0]])  # camera x right, y down, z forward
    T_vc[2, 3] = CAM_HEIGHT
    T_vl = np.eye(4)
    T_vl[2, 3] = CAM_HEIGHT
    (scene / "extrinsics.json").write_text(json.dumps({"cam_front": T_vc.tolist(), "lidar_top": T_vl.tolist()}))
    np.savetxt(scene / "ego_poses.txt", np.tile(np.eye(4)[:3].ravel(), (n_frames, 1)))
    instance = np.zeros((H, W), np.uint16)
    instance[CAR1] = 1
    instance[CAR2] = 2
    instance[NOTCH] = 0
    semantic = np.full((H, W), 21, np.uint8)
    semantic[:15] = 11
    semantic[30:] = 7
    semantic[instance > 0] = 26
    rows = []
    for f in range(n_frames):
        cv2.imwrite(str(scene / "gt/instance/cam_front" / sceneio.frame_name(f, "png")), instance)
        cv2.imwrite(str(scene / "gt/semantic/cam_front" / sceneio.frame_name(f, "png")), semantic)
        image = np.random.default_rng(f).integers(0, 255, (H, W, 3), dtype=np.uint8)
        cv2.imwrite(str(scene / "cam_front" / sceneio.frame_name(f, "png")), image)
        sweep = [lidar_point(*p) for p in (points if points is not None else POINTS).values()]
        sweep += EXTRA if extra_points is None else extra_points
        np.asarray(sweep, dtype="<f4").reshape(-1, 4).tofile(scene / "lidar_top" / sceneio.frame_name(f, "bin"))
        for track, box, px in ((1, gt_box((10, 21), (20, 29), 10.5, 4.0), 120),
                               (2, gt_box((30, 45), (20, 29), 10.5, 4.0), 136)):
            rows.append([f, track, "car", *box, 0, 0, 0, 0, 0.0, 0, 0, 0, 0, px, 3])
    header = ",".join(sceneio.BOX_COLUMNS)
    lines = [header] + [",".join(str(v) for v in r) for r in rows]
    (scene / "gt").joinpath("boxes.csv").write_text("\n".join(lines) + "\n")
    return scene


def as_set(points: np.ndarray) -> set:
    return {tuple(np.round(p, 4)) for p in points}


def expected(*names) -> set:
    return as_set(np.array([lidar_point(*POINTS[n]) for n in names], dtype=np.float32))


# ----------------------------------------------------------------------------- packing


def test_packing_round_trips_odd_sizes(tmp_path):
    rng = np.random.default_rng(0)
    size = (13, 7)  # 91 pixels: not a multiple of 8
    masks = rng.random((5, 7, 13)) < 0.4
    packed = masks_io.pack_masks(masks, size)
    assert packed.shape == (5, 12) and packed.dtype == np.uint8
    for m, row in zip(masks, packed):
        assert np.array_equal(masks_io.unpack_mask(row, size), m)
    np.savez(tmp_path / "d.npz", mask=packed, image_size=np.array(size))
    d = masks_io.load_detections(tmp_path / "d.npz")
    assert np.array_equal(masks_io.mask_of(d, 3), masks[3])
    with pytest.raises(ValueError, match="expected"):
        masks_io.pack_masks([np.zeros((13, 7), bool)], size)


# ----------------------------------------------------------------------------- whole scene


def test_perfect_detector_reproduces_gt_masks_and_point_sets(tmp_path):
    scene = write_scene(tmp_path)
    out = tmp_path / "detections_test.npz"
    summary = write_detections(scene, out, detection_cfg(), "test", seed=1)
    d = masks_io.load_detections(out)
    instance = sceneio.read_label_png(scene / "gt/instance/cam_front/000000.png")
    assert summary["n_detections"] == 6 and summary["recall"] == 1.0 and summary["precision"] == 1.0
    assert tuple(d["image_size"]) == (W, H)
    assert d["mask"].shape == (6, (W * H + 7) // 8)
    assert d["point_offsets"].shape == (7,) and d["point_offsets"].dtype == np.int64
    for i in range(6):
        track = d["matched_track"][i]
        assert np.array_equal(masks_io.mask_of(d, i), instance == track)
        assert d["score"][i] == pytest.approx(0.9)
    i1, i2 = [int(np.flatnonzero((d["frame"] == 0) & (d["matched_track"] == t))[0]) for t in (1, 2)]
    np.testing.assert_array_equal(d["box"][i1], [9.5, 19.5, 21.5, 29.5])
    np.testing.assert_array_equal(d["box"][i2], [29.5, 19.5, 45.5, 29.5])
    assert as_set(masks_io.points_of(d, i1)) == expected("car1_a", "car1_b", "car1_glass")
    assert as_set(masks_io.points_of(d, i2)) == expected("car2_a", "car2_b")
    assert as_set(masks_io.box_points_of(d, i2)) == expected("car2_a", "car2_b", "notch")
    # the point seen through the glass lies in the mask but not in the ground-truth box
    flags = dict(zip(map(tuple, np.round(masks_io.points_of(d, i1), 4)), masks_io.inliers_of(d, i1)))
    assert flags == {next(iter(expected(n))): n != "car1_glass" for n in ("car1_a", "car1_b", "car1_glass")}
    assert summary["inlier_fraction_mask"] == pytest.approx(4 / 5)
    assert summary["inlier_fraction_box"] == pytest.approx(4 / 6)


def test_detections_deterministic_given_seed(tmp_path):
    scene = write_scene(tmp_path)
    noisy = detection_cfg(boundary_std_px=2.0, edge_flip=0.3, fp_per_frame=2.0, score_noise=0.1)
    a, _ = detect_scene(scene, noisy, "test", seed=7)
    b, _ = detect_scene(scene, noisy, "test", seed=7)
    c, _ = detect_scene(scene, noisy, "test", seed=8)
    for key in a:
        assert np.array_equal(a[key], b[key]), key
    assert not (len(a["score"]) == len(c["score"]) and np.array_equal(a["mask"], c["mask"]))


def test_mask_without_points_nan_and_truncated_lidar(tmp_path):
    only_car1 = {k: v for k, v in POINTS.items() if not k.startswith("car2")}
    nan_row = [[np.nan, 1.0, 2.0, 0.5]]
    scene = write_scene(tmp_path, points=only_car1, extra_points=EXTRA + nan_row)
    summary = write_detections(scene, tmp_path / "d.npz", detection_cfg(), "test", seed=0)
    d = masks_io.load_detections(tmp_path / "d.npz")
    assert summary["n_detections_without_points"] == 3  # car 2 in each of the 3 frames
    assert summary["lidar_nonfinite_records"] == 3 and d["lidar_nonfinite"].tolist() == [1, 1, 1]
    assert np.isfinite(d["points"]).all() and all(np.isfinite(v) for v in summary.values())
    sweep = scene / "lidar_top" / "000001.bin"
    sweep.write_bytes(sweep.read_bytes() + b"\x00" * 5)
    with pytest.raises(sceneio.SceneError, match="000001.bin"):
        write_detections(scene, tmp_path / "d2.npz", detection_cfg(), "test", seed=0)
    assert not (tmp_path / "d2.npz").exists()


# ----------------------------------------------------------------------------- fault rates


def two_cars() -> tuple[np.ndarray, np.ndarray, list[dict]]:
    instance = np.zeros((H, W), np.uint16)
    instance[CAR1] = 1
    instance[20:30, 22:34] = 2  # touches car 1
    semantic = np.full((H, W), 21, np.uint8)
    semantic[instance > 0] = 26
    return instance, semantic, [{"track": 1, "visible_fraction": 1.0}, {"track": 2, "visible_fraction": 1.0}]


def run_many(level: dict, n: int = 300) -> list[tuple[list, dict]]:
    instance, semantic, objects = two_cars()
    rng = np.random.default_rng(0)
    return [simulate_frame(instance, semantic, objects, level, rng, 1.0) for _ in range(n)]


def test_fault_rates_match_config():
    runs = run_many({**PERFECT, "miss_base": 0.3})
    assert sum(c["missed"] for _, c in runs) / 600 == pytest.approx(0.3, abs=0.05)
    runs = run_many({**PERFECT, "merge_prob": 0.4})
    merged = [any(d["kind"] == KIND_MERGED for d in dets) for dets, _ in runs]
    assert np.mean(merged) == pytest.approx(0.4, abs=0.07)
    assert all(len(dets) == (1 if m else 2) for (dets, _), m in zip(runs, merged))
    runs = run_many({**PERFECT, "fp_per_frame": 1.5}, n=200)
    fps = [[d for d in dets if d["kind"] == KIND_FALSE_POSITIVE] for dets, _ in runs]
    assert np.mean([len(f) for f in fps]) == pytest.approx(1.5, abs=0.2)
    instance, semantic, _ = two_cars()
    for f in fps:
        for d in f:
            assert not (d["mask"] & (instance > 0)).any() and (semantic[d["mask"]] == 21).all()
            assert d["score"] == pytest.approx(0.2) and d["members"] == []  # sigmoid(bias + fp offset)


def test_boundary_dilation_erosion_and_score_quality():
    instance, _, _ = two_cars()
    gt = instance == 1
    rng = np.random.default_rng(0)
    grown, shrunk = perturb_boundary(gt, 2, 0.0, rng), perturb_boundary(gt, -2, 0.0, rng)
    assert (grown >= gt).all() and grown.sum() > gt.sum() and grown[19:31, 9:23].all()
    assert (shrunk <= gt).all() and shrunk.sum() == 8 * 6
    # the score does not read the mask's IoU: without the latent coupling it carries no information about it,
    # with it the two correlate without being equal (tests/test_detection_score.py measures it on the world)
    noisy = {**PERFECT, "boundary_std_px": 2.0, "edge_flip": 0.2, "score_latent_gain": 1.0, "score_noise": 0.3}
    for coupling, lo, hi in ((0.0, -0.15, 0.15), (0.8, 0.3, 0.9)):
        ious, scores = [], []
        for dets, _ in run_many({**noisy, "mask_quality_coupling": coupling}):
            for d in dets:
                m = instance == d["members"][0]
                ious.append((d["mask"] & m).sum() / (d["mask"] | m).sum())
                scores.append(d["score"])
        rho = spearmanr(ious, scores)[0]
        assert np.std(ious) > 0.05 and lo < rho < hi, (coupling, rho)


def test_miss_probability_rises_as_visibility_falls():
    level = {**PERFECT, "miss_base": 0.01, "miss_small_px": 100, "miss_occluded_fraction": 0.2}
    by_size = [miss_probability(px, 1.0, level) for px in (10, 50, 100, 400, 4000)]
    by_frac = [miss_probability(10000, f, level) for f in (0.02, 0.1, 0.2, 0.5, 1.0)]
    assert by_size == sorted(by_size, reverse=True) and by_size[2] == pytest.approx(0.5, abs=0.02)
    assert by_frac == sorted(by_frac, reverse=True) and by_frac[2] == pytest.approx(0.5, abs=0.02)
    assert miss_probability(100, 0.2, {**level, "miss_small_px": 400}, scale=0.5) == pytest.approx(
        miss_probability(100, 0.2, level))
    assert miss_probability(3, 0.01, PERFECT) == 0.0


def test_coco_level_is_worse_than_cityscapes():
    cfg = yaml.safe_load((ROOT / "config.yaml").read_text())["detection"]["levels"]
    instance = np.zeros((200, 300), np.uint16)
    instance[60:120, 40:120] = 1
    instance[70:130, 120:200] = 2  # touches car 1
    semantic = np.where(instance > 0, 26, 21).astype(np.uint8)
    objects = [{"track": 1, "visible_fraction": 1.0}, {"track": 2, "visible_fraction": 0.3}]
    stats = {}
    for name in ("coco", "cityscapes"):
        rng = np.random.default_rng(1)
        runs = [simulate_frame(instance, semantic, objects, cfg[name], rng, 1.0) for _ in range(300)]
        real = [d for dets, _ in runs for d in dets if d["kind"] != KIND_FALSE_POSITIVE]
        stats[name] = {"missed": sum(c["missed"] for _, c in runs), "score": np.mean([d["score"] for d in real]),
                       "merged": sum(d["kind"] == KIND_MERGED for d in real),
                       "fp": sum(c["false_positive"] for _, c in runs)}
    coco, city = stats["coco"], stats["cityscapes"]
    assert coco["missed"] > city["missed"] and coco["score"] < city["score"]
    assert coco["merged"] > city["merged"] and coco["fp"] > city["fp"]


# ----------------------------------------------------------------------------- road


def test_road_segmenter_clean_noisy_and_file(tmp_path):
    semantic = np.full((H, W), 11, np.uint8)
    semantic[28:] = 7
    semantic[28:, :8] = 8
    rng = np.random.default_rng(0)
    assert np.array_equal(segment_road(semantic, CLEAN_ROAD, rng), semantic == 7)
    noisy = {**CLEAN_ROAD, "boundary_offset_std_px": 1.0, "boundary_noise_px": 2.0, "fp_blobs_per_frame": 1.0,
             "fn_blobs_per_frame": 1.0}
    pred = segment_road(semantic, noisy, np.random.default_rng(0))
    iou = (pred & (semantic == 7)).sum() / (pred | (semantic == 7)).sum()
    assert 0.5 < iou < 1.0
    scene = write_scene(tmp_path)
    cfg = detection_cfg()
    summary = write_road(scene, tmp_path / "road.npz", cfg, seed=3)
    r = masks_io.load_road(tmp_path / "road.npz")
    gt_road = sceneio.read_label_png(scene / "gt/semantic/cam_front/000002.png") == 7
    assert np.array_equal(masks_io.road_of(r, 2), gt_road) and summary["road_iou_mean"] == 1.0
    cfg["road"] = noisy
    write_road(scene, tmp_path / "a.npz", cfg, seed=3)
    write_road(scene, tmp_path / "b.npz", copy.deepcopy(cfg), seed=3)
    a, b = masks_io.load_road(tmp_path / "a.npz"), masks_io.load_road(tmp_path / "b.npz")
    assert np.array_equal(a["road"], b["road"]) and (a["iou"] < 1).all() and r["road"].shape == (3, W * H // 8)
