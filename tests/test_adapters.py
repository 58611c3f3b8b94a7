"""Dataset adapters on tiny fixtures written here in the datasets' exact on-disk formats (hand-computed cases)."""
import json
import math

import cv2
import numpy as np
import pytest


from pathlib import Path

from redsup import config, sceneio
from redsup.adapters import AdapterError, adapt_scene, cameras, rle, scene_ids
from redsup.adapters.scene_folder import focal_from_lens
from redsup.adapters.tusimple import adapt_clips, read_calibration
from redsup.prep import masks_io
from redsup.prep.depthmap import lidar_depth_maps
from redsup.prep.detections import detect_scene
from redsup.prep.detector import KIND_FALSE_POSITIVE, KIND_SINGLE
from redsup.prep.outliers import scene_records

CONFIG = Path(__file__).resolve().parents[1] / "config.yaml"
NO_CROP = {"top": 0, "bottom": 0, "left": 0, "right": 0}
RESIZE = {"width": 20, "height": 10}
W, H = 40, 20
# a rectified camera 2: fx = fy = 10, principal point (19.3, 9.2); no baseline (P_rect_02[:, 3] = 0)
P_RECT = [10, 0, 19.3, 0, 0, 10, 9.2, 0, 0, 0, 1, 0]
VELO_TO_CAM_R = [0, -1, 0, 0, 0, -1, 1, 0, 0]  # velodyne x forward, y left, z up -> camera x right, y down, z fwd


def fmt(values):
    return " ".join(f"{v:.6e}" for v in values)


def write_png(path, array):
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), array)


def write_velo(path, points):
    path.parent.mkdir(parents=True, exist_ok=True)
    np.asarray(points, dtype="<f4").reshape(-1, 4).tofile(path)


def kitti_raw_fixture(root, n_frames=2, oxts=None, points=None):
    """<root>/2011_09_26/{calib_*.txt, 2011_09_26_drive_0001_sync/{image_02, velodyne_points}/data/...}."""
    date = root / "2011_09_26"
    date.mkdir(parents=True)
    (date / "calib_cam_to_cam.txt").write_text(
        "calib_time: 09-Jan-2012 13:57:47\ncorner_dist: 9.950000e-02\n"
        f"S_rect_00: {fmt([W, H])}\nR_rect_00: {fmt(np.eye(3).ravel())}\nP_rect_00: {fmt(P_RECT)}\n"
        f"S_rect_02: {fmt([W, H])}\nR_rect_02: {fmt(np.eye(3).ravel())}\nP_rect_02: {fmt(P_RECT)}\n")
    (date / "calib_velo_to_cam.txt").write_text(
        f"calib_time: 15-Mar-2012 11:37:16\nR: {fmt(VELO_TO_CAM_R)}\nT: {fmt([0, 0, 0])}\n"
        "delta_f: 0.000000e+00 0.000000e+00\ndelta_c: 0.000000e+00 0.000000e+00\n")
    (date / "calib_imu_to_velo.txt").write_text(
        f"calib_time: 25-May-2012 16:47:16\nR: {fmt(np.eye(3).ravel())}\nT: {fmt([-0.8, 0.3, -0.8])}\n")
    drive = date / "2011_09_26_drive_0001_sync"
    if points is None:
        points = [[10.0, -0.25, 0.1, 0.5],   # cam (0.25, -0.1, 10): (u, v) = (19.55, 9.1), see the depth test
                  [5.0, -0.125, 0.05, 0.5],  # same ray, nearer: wins the pixel
                  [-5.0, 0.0, 0.0, 0.5],     # behind the camera: dropped
                  [100.0, -2.0, 1.0, 0.5]]   # beyond 80 m: dropped
    for i in range(n_frames):
        write_png(drive / "image_02" / "data" / f"{i:010d}.png", np.full((H, W, 3), 40 * i, np.uint8))
        write_velo(drive / "velodyne_points" / "data" / f"{i:010d}.bin", points)
        if oxts is not None:
            packet = list(oxts[i]) + [0.0] * 24
            (drive / "oxts" / "data").mkdir(parents=True, exist_ok=True)
            (drive / "oxts" / "data" / f"{i:010d}.txt").write_text(" ".join(f"{v:.12g}" for v in packet))
    return drive


def raw_spec(root, **extra):
    return {"kind": "kitti_raw", "path": str(root), "crop": NO_CROP, "resize": RESIZE, **extra}


# ----------------------------------------------------------------------------------------------- RLE
def test_compressed_rle_strings_hand_decoded():
    # '1','2','3': single 5-bit groups; the 4th run is stored minus the run two before it (4 - 2 = 2 -> '2')
    assert rle.string_to_counts("1232") == [1, 2, 3, 4]
    # 40 = 0b01000 + 1 << 5: group 8 with the "more" bit (8 + 32 + 48 = 'X'), then group 1 ('1')
    assert rle.string_to_counts("X1") == [40]
    # a negative delta: counts [5, 1, 2, 0]: 0 - 1 = -1 -> group 31 (sign bit set) -> chr(79) = 'O'
    assert rle.string_to_counts("512O") == [5, 1, 2, 0]
    assert rle.counts_to_string([1, 2, 3, 4]) == "1232" and rle.counts_to_string([5, 1, 2, 0]) == "512O"


def test_rle_decode_is_column_major_and_round_trips():
    # 3x2 mask, column-major runs: 1 zero, 2 ones (rest of column 0), 1 zero, 2 ones
    mask = rle.decode({"size": [3, 2], "counts": [1, 2, 1, 2]})
    assert mask.tolist() == [[False, False], [True, True], [True, True]]
    rng = np.random.default_rng(0)
    for _ in range(5):
        m = rng.random((13, 7)) < 0.3
        assert np.array_equal(rle.decode(rle.encode(m)), m)
    with pytest.raises(rle.RLEError, match="sum to 5"):
        rle.decode({"size": [3, 2], "counts": [1, 2, 2]})


# --------------------------------------------------------------------------------------- KITTI raw
def test_kitti_raw_depth_follows_the_monodepth2_pixel_convention(tmp_path):
    kitti_raw_fixture(tmp_path / "raw")
    spec = raw_spec(tmp_path / "raw", split="test")
    assert scene_ids("kr", spec) == ["test_2011_09_26_drive_0001_sync"]
    out = tmp_path / "kr" / "test_2011_09_26_drive_0001_sync"
    summary = adapt_scene("kr", spec, out.name, out)
    assert summary["frames"] == 2 and summary["poses_from_oxts"] == 0.0
    meta = sceneio.read_meta(out)
    assert meta["n_frames"] == 2 and meta["split"] == "test" and meta["cameras"] == ["cam_front"]
    # point (10, -0.25, 0.1) in the velodyne frame -> camera (0.25, -0.1, 10) -> (u, v) = (19.55, 9.1):
    # Monodepth2 pixel = round - 1 -> column 19, row 8 (`exact`: column 20, row 9);
    # the nearer point on the same ray (z = 5) wins; the point behind and the one beyond 80 m are dropped
    lidar_depth_maps(out, "cam_front", NO_CROP, (0.1, 80.0), tmp_path / "d.npz")
    depth = np.load(tmp_path / "d.npz")["depth"]
    assert depth.shape == (2, H, W)
    assert np.flatnonzero(depth[0]).tolist() == [8 * W + 19] and depth[0, 8, 19] == pytest.approx(5.0)
    K, size = sceneio.read_intrinsics(out / "cam_front.txt")
    assert size == (W, H) and K[0, 2] == pytest.approx(18.3) and K[1, 2] == pytest.approx(8.2)
    exact = tmp_path / "exact" / out.name
    adapt_scene("kr", raw_spec(tmp_path / "raw", split="test", depth_convention="exact"), out.name, exact)
    lidar_depth_maps(exact, "cam_front", NO_CROP, (0.1, 80.0), tmp_path / "e.npz")
    assert np.flatnonzero(np.load(tmp_path / "e.npz")["depth"][0]).tolist() == [9 * W + 20]


def test_kitti_raw_vehicle_frame_and_oxts_poses(tmp_path):
    # frame 1 is 1e-5 degrees of longitude east at the equator: Mercator x = 6378137 * 1e-5 * pi / 180 m
    oxts = [[0.0, 0.0, 100.0, 0.0, 0.0, 0.0], [0.0, 1e-5, 100.5, 0.0, 0.0, math.pi / 2]]
    kitti_raw_fixture(tmp_path / "raw", oxts=oxts)
    spec = raw_spec(tmp_path / "raw")
    out = tmp_path / "kr" / "train_2011_09_26_drive_0001_sync"
    assert adapt_scene("kr", spec, out.name, out)["poses_from_oxts"] == 1.0
    poses = sceneio.read_poses(out / "ego_poses.txt")
    # T_world_vehicle = T_world_imu T_imu_vehicle; the vehicle origin is 0.93 m below the IMU
    assert poses[0][:3, 3] == pytest.approx([0.0, 0.0, -0.93])
    assert poses[1][:3, 3] == pytest.approx([6378137 * 1e-5 * math.pi / 180, 0.0, 0.5 - 0.93])
    assert poses[1][:3, :3] @ np.array([1.0, 0, 0]) == pytest.approx([0.0, 1.0, 0.0], abs=1e-9)  # yaw 90 deg
    extr = sceneio.read_extrinsics(out / "extrinsics.json")
    # velodyne at -T_imu_to_velo from the IMU (identity rotation), 0.93 m up: (0.8, -0.3, 0.8 + 0.93)
    assert extr["lidar_top"][:3, 3] == pytest.approx([0.8, -0.3, 1.73])
    assert extr["cam_front"][:3, :3] @ np.array([0, 0, 1.0]) == pytest.approx([1.0, 0, 0])  # optical axis = +x


def test_kitti_raw_windows_and_split_files(tmp_path):
    kitti_raw_fixture(tmp_path / "raw", n_frames=5)
    split = tmp_path / "test_files.txt"
    split.write_text("2011_09_26/2011_09_26_drive_0001_sync 0000000001 l\n"
                     "2011_09_26/2011_09_26_drive_0001_sync 0000000004 l\n")
    spec = raw_spec(tmp_path / "raw", splits={"test": str(split)}, window=3)
    assert scene_ids("kr", spec) == ["test_2011_09_26_drive_0001_sync_000000", "test_2011_09_26_drive_0001_sync_000003"]
    out = tmp_path / "kr" / "test_2011_09_26_drive_0001_sync_000003"
    adapt_scene("kr", spec, out.name, out)
    meta = sceneio.read_meta(out)
    assert meta["n_frames"] == 2 and meta["split_frames"] == [1]
    assert meta["source"]["frames"] == ["0000000003", "0000000004"]
    missing = tmp_path / "missing.txt"
    missing.write_text("2011_09_26/2011_09_26_drive_0099_sync 0000000001 l\n")
    with pytest.raises(AdapterError, match="2011_09_26_drive_0099_sync"):
        scene_ids("kr2", raw_spec(tmp_path / "raw", splits={"test": str(missing)}))


def test_incomplete_inputs_name_what_is_missing(tmp_path):
    with pytest.raises(AdapterError, match=r"datasets\.kr .*nowhere.*KITTI raw root missing"):
        scene_ids("kr", raw_spec(tmp_path / "nowhere"))
    drive = kitti_raw_fixture(tmp_path / "raw", n_frames=3)
    (drive / "velodyne_points" / "data" / "0000000001.bin").unlink()
    spec = raw_spec(tmp_path / "raw")
    out = tmp_path / "kr" / "train_2011_09_26_drive_0001_sync"
    with pytest.raises(AdapterError, match=r"velodyne_points/data: 1 of 3 velodyne sweeps missing \(0000000001.bin\)"):
        adapt_scene("kr", spec, out.name, out)
    assert not out.exists() and not list(out.parent.glob(".*tmp*"))
    (drive.parent / "calib_velo_to_cam.txt").write_text("R: 1 0 0 0 1 0 0 0 1\n")
    with pytest.raises(AdapterError, match=r"calib_velo_to_cam.txt: calibration keys missing: \['T'\]"):
        adapt_scene("kr", spec, out.name, out)


def test_schema_rejects_unknown_kinds_and_keys():
    base = {"crop": NO_CROP, "resize": RESIZE}
    with pytest.raises(config.ConfigError, match="'kitti' is not one of"):
        config.load(CONFIG, {"datasets": {"k": {"kind": "kitti", "path": "/x", **base}}})
    with pytest.raises(config.ConfigError, match="'path' is a required property"):
        config.load(CONFIG, {"datasets": {"k": {"kind": "kitti_raw", **base}}})
    with pytest.raises(config.ConfigError, match="'window' was unexpected"):
        config.load(CONFIG, {"datasets": {"k": {"kind": "kitti_object", "path": "/x", "window": 3, **base}}})
    with pytest.raises(config.ConfigError, match="'gt' was unexpected|'pth' was unexpected"):
        config.load(CONFIG, {"velocity_clips": {"source": {"kind": "tusimple", "splits": {"train": {"pth": "/x"}}}}})
    cfg = config.load(CONFIG, {"datasets": {"k": {"kind": "kitti_raw", "path": "/x", "cameras": ["cam_front"],
                                                         "instances": {"source": "detections", "path": "/d"}, **base}}})
    assert cameras(cfg["datasets"]["k"]) == ["cam_front"]


# ------------------------------------------------------------------------------------ KITTI object
def kitti_object_fixture(root):
    t = root / "training"
    calib = ("P0: {p}\nP1: {p}\nP2: {p}\nP3: {p}\nR0_rect: {r}\nTr_velo_to_cam: {v}\nTr_imu_to_velo: {i}\n").format(
        p=fmt(P_RECT), r=fmt(np.eye(3).ravel()),
        v=fmt(np.hstack([np.reshape(VELO_TO_CAM_R, (3, 3)), np.zeros((3, 1))]).ravel()),
        i=fmt(np.hstack([np.eye(3), np.zeros((3, 1))]).ravel()))
    (t / "calib").mkdir(parents=True)
    (t / "calib" / "000007.txt").write_text(calib)
    write_png(t / "image_2" / "000007.png", np.zeros((H, W, 3), np.uint8))
    # two LiDAR returns inside the car's box, one outside
    write_velo(t / "velodyne" / "000007.bin", [[20.0, -1.0, -0.5, 0.1], [20.5, -2.5, -0.9, 0.1], [5.0, 5.0, 0.0, 0.1]])
    (t / "label_2").mkdir()
    # every field: type truncated occluded alpha x1 y1 x2 y2 h w l x y z rotation_y
    (t / "label_2" / "000007.txt").write_text(
        "Car 0.12 1 -1.62 18.40 6.10 25.60 14.90 1.50 1.60 4.00 1.00 1.50 20.00 0.00\n"
        "DontCare -1 -1 -10 2.00 3.00 6.00 8.00 -1 -1 -1 -1000 -1000 -1000 -10\n")
    return t


def test_kitti_object_label_to_canonical_box(tmp_path):
    kitti_object_fixture(tmp_path / "obj")
    spec = {"kind": "kitti_object", "path": str(tmp_path / "obj"), "crop": NO_CROP, "resize": RESIZE,
            "instances": {"source": "label_boxes"}}
    assert scene_ids("ko", spec) == ["train_000007"]
    out = tmp_path / "ko" / "train_000007"
    adapt_scene("ko", spec, "train_000007", out)
    boxes = sceneio.read_boxes(out / "gt" / "boxes.csv")
    car, dc = boxes.iloc[0], boxes.iloc[1]
    # bottom centre (1, 1.5, 20) in camera 0, height 1.5: centre (1, 0.75, 20) -> velodyne (20, -1, -0.75)
    # -> vehicle (IMU = velodyne here, 0.93 m up): (20, -1, 0.18); ry = 0 faces camera +x = velodyne -y: yaw -pi/2
    assert [car.x, car.y, car.z] == pytest.approx([20.0, -1.0, 0.18])
    assert [car.l, car.w, car.h, car.yaw] == pytest.approx([4.0, 1.6, 1.5, -math.pi / 2])
    assert (car.cls, car.occlusion, car.truncation, car.n_lidar) == ("Car", 1, pytest.approx(0.12), 2)
    assert [car.x1, car.y1, car.x2, car.y2] == pytest.approx([18.4, 6.1, 25.6, 14.9])
    assert dc.cls == "DontCare" and np.isnan(dc.x) and dc.occlusion == -1 and dc.x2 == pytest.approx(6.0)
    # pseudo-mask: pixels whose centres lie in [18.4, 25.6] x [6.1, 14.9] -> columns 19..25, rows 7..14
    inst = sceneio.read_label_png(out / "gt" / "instance" / "cam_front" / "000000.png")
    rows, cols = np.nonzero(inst == 1)
    assert (cols.min(), cols.max(), rows.min(), rows.max()) == (19, 25, 7, 14) and car.visible_px == 7 * 8
    assert inst.dtype == np.uint16 and set(np.unique(inst)) == {0, 1}


def test_coco_detections_become_instances(tmp_path):
    root = tmp_path / "obj"
    kitti_object_fixture(root)
    mask = np.zeros((H, W), bool)
    mask[7:15, 19:26] = True
    other = np.zeros((H, W), bool)
    other[0:3, 0:4] = True
    dets = [{"image_id": 7, "category_id": 3, "score": 0.9, "segmentation": rle.encode(mask), "bbox": [19, 7, 7, 8]},
            {"image_id": 7, "category_id": 3, "score": 0.8,
             "segmentation": {"size": [H, W], "counts": rle.string_to_counts(rle.encode(other)["counts"])}},
            {"image_id": 7, "category_id": 1, "score": 0.99, "segmentation": rle.encode(other)},   # person: skipped
            {"image_id": 7, "category_id": 3, "score": 0.1, "segmentation": rle.encode(other)}]    # low score
    det_file = tmp_path / "dets" / "training" / "image_2" / "000007.json"
    det_file.parent.mkdir(parents=True)
    det_file.write_text(json.dumps(dets))
    spec = {"kind": "kitti_object", "path": str(root), "crop": NO_CROP, "resize": RESIZE,
            "instances": {"source": "detections", "path": str(tmp_path / "dets")}}
    out = tmp_path / "ko" / "train_000007"
    summary = adapt_scene("ko", spec, "train_000007", out)
    inst = sceneio.read_label_png(out / "gt" / "instance" / "cam_front" / "000000.png")
    # the car detection takes the label's id 1; the unmatched one (a false positive) is kept with a new id
    records = json.loads((out / "gt" / "detections" / "cam_front" / "000000.json").read_text())
    fp_id = records[1]["track_id"]                           # first id after the frame's labels
    assert [{k: r[k] for k in ("track_id", "score", "cls")} for r in records] == [
        {"track_id": 1, "score": 0.9, "cls": "car"}, {"track_id": fp_id, "score": 0.8, "cls": "car"}]
    assert np.array_equal(rle.decode(records[0]["segmentation"]), mask)
    assert np.array_equal(rle.decode(records[1]["segmentation"]), other)
    assert np.array_equal(inst == 1, mask) and np.array_equal(inst == fp_id, other) and fp_id > 1
    assert summary["detections_kept"] == 2 and summary["detections_unmatched"] == 1
    # preparation: the supplied detections enter as they are (no stand-in noise), the false positive with its score
    cfg = config.load(CONFIG)["detection"]
    level = next(iter(cfg["levels"]))
    arrays, _ = detect_scene(out, {**cfg, "score_threshold": 0.85}, level, seed=0)
    assert sorted(arrays["score"].tolist()) == pytest.approx([0.8, 0.9])
    fp = int(np.argmin(arrays["score"]))
    assert arrays["matched_track"][fp] == -1 and arrays["matched_track"][1 - fp] == 1
    bad = [{"category_id": 3, "score": 0.9, "segmentation": {"size": [H + 1, W], "counts": [H * W + W]}}]
    det_file.write_text(json.dumps(bad))
    with pytest.raises(AdapterError, match=r"000007.json: entry 0: mask size \[21, 40\]"):
        adapt_scene("ko", spec, "train_000007", out)


def covered_car_scene(tmp_path, seg_of_car=None):
    """The KITTI object fixture with two supplied detections: the car's (score 0.55, its label's pixels: rows 7..14,
    columns 19..25, 56 px) wholly under a false positive (0.70, rows 5..16, columns 15..30, 192 px). Mask boxes
    against the label box 18.4..25.6 x 6.1..14.9 (63.36 px^2): the car's 18.5..25.5 x 6.5..14.5 has IoU
    56 / 63.36 = 0.88, the false positive's 14.5..30.5 x 4.5..16.5 has 63.36 / 192 = 0.33 < match_iou 0.5."""
    root = tmp_path / "obj"
    kitti_object_fixture(root)
    car = np.zeros((H, W), bool)
    car[7:15, 19:26] = True
    fp = np.zeros((H, W), bool)
    fp[5:17, 15:31] = True
    det_file = tmp_path / "dets" / "training" / "image_2" / "000007.json"
    det_file.parent.mkdir(parents=True)
    det_file.write_text(json.dumps([
        {"category_id": 3, "score": 0.55, "segmentation": rle.encode(car) if seg_of_car is None else seg_of_car},
        {"category_id": 3, "score": 0.70, "segmentation": rle.encode(fp)}]))
    spec = {"kind": "kitti_object", "path": str(root), "crop": NO_CROP, "resize": RESIZE,
            "instances": {"source": "detections", "path": str(tmp_path / "dets")}}
    return spec, det_file, car, fp


def test_detection_covered_by_a_better_one_reaches_the_detections(tmp_path):
    spec, _, car, fp = covered_car_scene(tmp_path)
    out = tmp_path / "ko" / "train_000007"
    summary = adapt_scene("ko", spec, "train_000007", out)
    assert summary["detections_kept"] == 2 and summary["detections_unmatched"] == 1
    # ids: the car label 1, DontCare 2, the false positive 3. The composite has no pixel of the car left: counted
    inst = sceneio.read_label_png(out / "gt" / "instance" / "cam_front" / "000000.png")
    assert set(np.unique(inst)) == {0, 3} and np.array_equal(inst == 3, fp)
    assert summary["detections_hidden_in_instance_image"] == 1
    records = json.loads((out / "gt" / "detections" / "cam_front" / "000000.json").read_text())
    assert [(r["track_id"], r["score"]) for r in records] == [(3, 0.70), (1, 0.55)]
    assert [int(rle.decode(r["segmentation"]).sum()) for r in records] == [192, 56]
    # both reach detections_<level>.npz, each with its whole mask; the car keeps its label's id
    cfg = config.load(CONFIG)["detection"]
    arrays, numbers = detect_scene(out, cfg, next(iter(cfg["levels"])), seed=0)
    assert arrays["score"].tolist() == pytest.approx([0.70, 0.55])
    assert np.array_equal(masks_io.mask_of(arrays, 0), fp) and np.array_equal(masks_io.mask_of(arrays, 1), car)
    assert arrays["matched_track"].tolist() == [-1, 1] and arrays["iou_gt"].tolist() == [0.0, 1.0]
    assert arrays["kind"].tolist() == [KIND_FALSE_POSITIVE, KIND_SINGLE]
    assert numbers["n_detections"] == 2 and numbers["n_false_positive"] == 1
    # the car's two LiDAR returns project to pixels (20, 9) and (21, 10), inside both masks; the third to (9, 9)
    assert masks_io.n_points(arrays).tolist() == [2, 2]
    # the in-mask outlier analysis measures the car's own mask too, not its (empty) share of the composite
    rec = [r for r in scene_records(out, "cam_front") if r["track"] == 1]
    assert len(rec) == 1 and (rec[0]["n_mask"], rec[0]["out_mask"]) == (2, 0)


@pytest.mark.parametrize("seg, problem", [
    ({"size": [H, W], "counts": "S<8<~"}, "entry 0: compressed RLE has a character outside"),
    ({"size": [H, W], "counts": ["a", 3]}, "entry 0: RLE counts must be a string or a list of run lengths"),
    ({"size": [H, W], "counts": [5, 10, W * H - 16]}, f"entry 0: RLE run lengths sum to {W * H - 1}"),
    (7, "entry 0: segmentation must be an RLE dict or polygon list"),
], ids=["bad-character", "counts-not-numbers", "one-pixel-short", "not-a-mask"])
def test_malformed_supplied_mask_names_the_file(tmp_path, seg, problem):
    spec, det_file, _, _ = covered_car_scene(tmp_path, seg_of_car=seg)
    with pytest.raises(AdapterError, match=problem) as err:
        adapt_scene("ko", spec, "train_000007", tmp_path / "ko" / "train_000007")
    assert str(det_file) in str(err.value)


@pytest.mark.parametrize("text, problem", [
    ('[{"track_id": 1, "score": 0.55', "not valid JSON"),
    ('{"track_id": 1}', "expected a list of detections"),
    ('[{"track_id": 1, "score": 0.55, "cls": "car"}]', "detection 0 needs track_id, score, cls and segmentation"),
    (json.dumps([{"track_id": 1, "score": 0.55, "cls": "car", "segmentation": rle.encode(np.ones((H + 1, W), bool))}]),
     f"detection 0: mask is {W}x{H + 1}, the image {W}x{H}"),
    (json.dumps([{"track_id": 1, "score": 0.55, "cls": "car", "segmentation": {"size": [H, W], "counts": [3]}}]),
     f"detection 0: RLE run lengths sum to 3, but size {H}x{W}"),
], ids=["truncated-json", "not-a-list", "no-mask", "wrong-size", "runs-short"])
def test_malformed_detection_records_name_the_file(tmp_path, text, problem):
    spec, _, _, _ = covered_car_scene(tmp_path)
    out = tmp_path / "ko" / "train_000007"
    adapt_scene("ko", spec, "train_000007", out)
    records = out / "gt" / "detections" / "cam_front" / "000000.json"
    records.write_text(text)
    cfg = config.load(CONFIG)["detection"]
    with pytest.raises(sceneio.SceneError, match=problem) as err:
        detect_scene(out, cfg, next(iter(cfg["levels"])), seed=0)
    assert str(records) in str(err.value)


def test_detections_on_unlabelled_raw_frames_add_rows(tmp_path):
    kitti_raw_fixture(tmp_path / "raw", n_frames=1)
    mask = np.zeros((H, W), bool)
    mask[2:5, 3:9] = True
    det_file = tmp_path / "dets" / "2011_09_26" / "2011_09_26_drive_0001_sync" / "image_02" / "data" / "0000000000.json"
    det_file.parent.mkdir(parents=True)
    det_file.write_text(json.dumps([{"category_id": 3, "score": 0.7, "segmentation": rle.encode(mask)}]))
    road = tmp_path / "road" / "2011_09_26" / "2011_09_26_drive_0001_sync" / "image_02" / "data" / "0000000000.png"
    write_png(road, np.where(np.arange(H)[:, None] > 12, 7, 23).astype(np.uint8).repeat(W, axis=1))
    spec = raw_spec(tmp_path / "raw", instances={"source": "detections", "path": str(tmp_path / "dets")},
                    road={"path": str(tmp_path / "road")})
    out = tmp_path / "kr" / "train_2011_09_26_drive_0001_sync"
    adapt_scene("kr", spec, out.name, out)
    boxes = sceneio.read_boxes(out / "gt" / "boxes.csv")
    assert len(boxes) == 1 and boxes.cls[0] == "car" and boxes.track_id[0] == 1 and np.isnan(boxes.x[0])
    assert [boxes.x1[0], boxes.y1[0], boxes.x2[0], boxes.y2[0]] == [2.5, 1.5, 8.5, 4.5] and boxes.visible_px[0] == 18
    semantic = sceneio.read_label_png(out / "gt" / "semantic" / "cam_front" / "000000.png")
    assert (semantic == 7).sum() == (H - 13) * W and sceneio.read_meta(out)["semantic"] == "png"


# ------------------------------------------------------------------------------------ scene folders
def test_scene_folder_lens_focal_and_depth_maps_as_virtual_lidar(tmp_path):
    assert focal_from_lens(5.49, 3.0) == pytest.approx(1830.0)  # Galteland eq. 3.36
    scene = tmp_path / "lyft" / "scene-0001"
    for i in range(3):
        write_png(scene / "front" / f"{i:04d}.jpg", np.full((H, W, 3), 60 * i, np.uint8))
        depth = np.zeros((H, W), np.uint16)
        depth[5 + i, 7] = 256 * (10 + i)  # 10 m, 11 m, 12 m (KITTI scale 256)
        depth[15, 30] = 256 * 90         # beyond prepare.depth_range: absent from the prepared map
        write_png(scene / "front_depth" / f"{i:04d}.png", depth)
    (scene / "front.txt").write_text("0 0 19.5\n0 0 9.5\n0 0 1\n")  # NAP-lab style: fx, fy missing
    spec = {"kind": "scene_folder", "path": str(tmp_path / "lyft"), "crop": NO_CROP, "resize": RESIZE,
            "cameras": {"cam_front": {"folder": "front", "focal_mm": 0.03, "pixel_pitch_um": 3.0,
                                      "depth_folder": "front_depth"}}}
    assert scene_ids("ly", spec) == ["train_scene_0001"]
    out = tmp_path / "ly" / "train_scene_0001"
    adapt_scene("ly", spec, "train_scene_0001", out)
    K, size = sceneio.read_intrinsics(out / "cam_front.txt")
    assert K[0, 0] == pytest.approx(10.0) and size == (W, H)
    assert sceneio.read_image(out / "cam_front" / "000002.png")[0, 0, 0] == pytest.approx(120, abs=2)
    lidar_depth_maps(out, "cam_front", NO_CROP, (0.1, 80.0), tmp_path / "d.npz")
    depth = np.load(tmp_path / "d.npz")["depth"]
    for i in range(3):
        assert np.flatnonzero(depth[i]).tolist() == [(5 + i) * W + 7]
        assert depth[i, 5 + i, 7] == pytest.approx(10 + i, abs=1e-5)
    (scene / "front.txt").write_text("0 0 19.5\n0 0 9.5\n0 0 1\n")
    del spec["cameras"]["cam_front"]["focal_mm"]
    with pytest.raises(AdapterError, match=r"front.txt: fx missing; set the camera's focal_mm and pixel_pitch_um"):
        adapt_scene("ly", spec, "train_scene_0001", out)


# ---------------------------------------------------------------------------------------- TuSimple
def test_tusimple_split_in_canonical_clip_shape(tmp_path):
    root = tmp_path / "tusimple_test"
    (root / "clips" / "3" / "imgs").mkdir(parents=True)
    for k in range(1, 41):  # a clip's 40 frames (linked, not decoded: empty files do)
        (root / "clips" / "3" / "imgs" / f"{k:03d}.jpg").write_bytes(b"")
    (root / "calibration.txt").write_text("Intrinsic matrix:\n714.1526    0.      675.5754\n   0.      710.3725  "
                                          "376.2563\n   0.        0.        1.    \n\nCamera Height:\n\n1.80m\n")
    # a test clip: the indication file has boxes only ([top, left, bottom, right]); the gt file has the rest
    (root / "clips" / "3" / "annotation.json").write_text(json.dumps([{"bbox": [340.0, 784.0, 393.0, 868.0]}]))
    gt = tmp_path / "gt.json"
    gt.write_text(json.dumps({"3": [{"bbox": {"top": 340.0, "left": 784.0, "bottom": 393.0, "right": 868.0},
                                     "velocity": [-1.2, 0.1], "position": [21.3, 2.7]}]}))
    cal = read_calibration(root / "calibration.txt")
    assert (cal["fx"], cal["fy"], cal["cx"], cal["cy"], cal["height"]) == (714.1526, 710.3725, 675.5754, 376.2563, 1.8)
    source = {"kind": "tusimple", "splits": {"test": {"path": str(root), "gt": str(gt)}}}
    summary = adapt_clips(source, "test", tmp_path / "out" / "test")
    assert summary == {"clips": 1, "vehicles": 1, "fx": 714.1526, "camera_height": 1.8}
    out = tmp_path / "out" / "test"
    assert read_calibration(out / "calibration.txt") == cal  # canonical "fx fy cx cy" / height, read back
    ann = json.loads((out / "clips" / "3" / "annotation.json").read_text())
    assert ann == [{"bbox": {"top": 340.0, "left": 784.0, "bottom": 393.0, "right": 868.0},
                    "velocity": [-1.2, 0.1], "position": [21.3, 2.7], "track_id": 0}]
    assert (out / "clips" / "3" / "imgs").resolve() == (root / "clips" / "3" / "imgs").resolve()
    source["splits"]["test"].pop("gt")
    with pytest.raises(AdapterError, match="vehicle 0 has no velocity"):
        adapt_clips(source, "test", tmp_path / "out2" / "test")
    assert not (tmp_path / "out2" / "test").exists()


def test_truncated_velodyne_sweep_fails_at_adaptation_naming_the_source(tmp_path):
    drive = kitti_raw_fixture(tmp_path / "raw", n_frames=3)
    src = drive / "velodyne_points" / "data" / "0000000001.bin"
    src.write_bytes(src.read_bytes()[:-6])                   # not a multiple of the 16-byte record
    out = tmp_path / "kr" / "train_2011_09_26_drive_0001_sync"
    with pytest.raises(AdapterError, match=r"velodyne_points/data/0000000001\.bin: velodyne sweep of \d+ bytes"):
        adapt_scene("kr", raw_spec(tmp_path / "raw"), out.name, out)
    assert not out.exists()


def test_images_vanished_after_listing_raise_adapter_error(tmp_path):
    drive = kitti_raw_fixture(tmp_path / "raw", n_frames=3)
    spec = raw_spec(tmp_path / "raw")
    ids = scene_ids("kr", spec)                              # the listing is cached for the process
    for p in (drive / "image_02" / "data").glob("*.png"):
        p.unlink()
    out = tmp_path / "kr" / ids[0]
    with pytest.raises(AdapterError, match=r"image_02/data: scene .* the folder now has 0 images"):
        adapt_scene("kr", spec, ids[0], out)
