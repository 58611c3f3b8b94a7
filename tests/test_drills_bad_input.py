"""Drill 2 (issue 14): a matrix of malformed inputs, one test per kind.

Each malformed input is fed to the function the workflow's job calls with it (reader, adapter, config
loader). Every case must raise the module's error type with a message naming the file (or the config key)
and the problem, and leave no partial output behind: an adapter builds its scene in a temporary sibling
and renames it only on success, so after a failure neither the output folder nor a temporary sibling
exists. `test_bad_label_fails_its_own_jobs_only` runs one case end to end with the tiny profile and
`--keep-going`: the bad scene's job fails naming the file, the good scene's chain finishes.
"""
import json
import shutil

import numpy as np
import pytest
import yaml

from conftest import ROOT, run_snakemake
from redsup import config, sceneio
from redsup.adapters import AdapterError, adapt_scene, rle
from redsup.adapters.masks import load_detections
from redsup.adapters.tusimple import adapt_clips
from redsup.prep.medianflow import read_annotations
from test_adapters import (H, NO_CROP, RESIZE, W, fmt, kitti_object_fixture, kitti_raw_fixture, raw_spec,
                           write_png, write_velo)

CONFIG = ROOT / "config.yaml"
RAW_SCENE = "train_2011_09_26_drive_0001_sync"


def assert_no_output(out):
    """Neither the output folder nor a temporary sibling of the adapter's writer survives a failure."""
    assert not out.exists(), f"{out} left behind"
    leftovers = [p.name for p in out.parent.glob(f".{out.name}.tmp*")] if out.parent.exists() else []
    assert not leftovers, leftovers


def raw_drive(tmp_path, n_frames=2, **kw):
    drive = kitti_raw_fixture(tmp_path / "kitti", n_frames=n_frames, **kw)
    return drive, raw_spec(tmp_path / "kitti")


def scene_folder_dataset(tmp_path, n_frames=2, cameras=("cam_front",)):
    """<root>/s1/<camera>/00000N.png and <camera>.txt: the smallest valid scene-folder dataset."""
    root = tmp_path / "sf"
    for camera in cameras:
        for i in range(n_frames):
            write_png(root / "s1" / camera / f"{i:06d}.png", np.full((H, W, 3), 10 * i, np.uint8))
        (root / "s1" / f"{camera}.txt").write_text(f"10 0 {W / 2}\n0 10 {H / 2}\n0 0 1\n{W} {H}\n")
    spec = {"kind": "scene_folder", "path": str(root), "crop": NO_CROP, "resize": RESIZE,
            "cameras": {c: {} for c in cameras}}
    return root / "s1", spec


def tusimple_split(tmp_path, n_frames=40):
    root = tmp_path / "tusimple"
    imgs = root / "clips" / "1" / "imgs"
    imgs.mkdir(parents=True)
    for k in range(1, n_frames + 1):
        (imgs / f"{k:03d}.jpg").write_bytes(b"")   # the adapter links imgs/, it does not decode
    (root / "calibration.txt").write_text("714.1526 710.3725 675.5754 376.2563\n1.8\n")
    (root / "clips" / "1" / "annotation.json").write_text(json.dumps(
        [{"bbox": {"top": 340.0, "left": 784.0, "bottom": 393.0, "right": 868.0},
          "velocity": [-1.2, 0.1], "position": [21.3, 2.7]}]))
    return root, {"kind": "tusimple", "splits": {"train": {"path": str(root)}}}


# ------------------------------------------------------------------------ 1. intrinsics, wrong count
def test_intrinsics_with_a_wrong_number_of_values(tmp_path):
    path = tmp_path / "cam_front.txt"
    path.write_text("100 0 50 7\n0 100 25\n0 0 1\n104 32\n")      # 4 values in the first row
    with pytest.raises(sceneio.SceneError, match="malformed intrinsics") as err:
        sceneio.read_intrinsics(path)
    assert str(path) in str(err.value)
    path.write_text("100 0 50\n0 100 25\n0 0 1\n104 32 3\n")      # a size row of 3 values
    with pytest.raises(sceneio.SceneError, match=r"size row \(104, 32, 3\)") as err:
        sceneio.read_intrinsics(path)
    assert str(path) in str(err.value)


def test_kitti_projection_with_11_values_fails_adaptation(tmp_path):
    drive, spec = raw_drive(tmp_path)
    calib = drive.parent / "calib_cam_to_cam.txt"
    text = calib.read_text().replace("P_rect_02: " + fmt([10, 0, 19.3, 0, 0, 10, 9.2, 0, 0, 0, 1, 0]),
                                     "P_rect_02: " + fmt([10, 0, 19.3, 0, 0, 10, 9.2, 0, 0, 0, 1]))
    calib.write_text(text)
    out = tmp_path / "out" / RAW_SCENE
    with pytest.raises(AdapterError, match="'P_rect_02' has 11 numbers, expected 12") as err:
        adapt_scene("k", spec, RAW_SCENE, out)
    assert str(calib) in str(err.value)
    assert_no_output(out)


# ----------------------------------------------------------------- 2. LiDAR size not a multiple of 16
def test_lidar_file_not_a_multiple_of_16_bytes(tmp_path):
    path = tmp_path / "000000.bin"
    path.write_bytes(np.zeros(8, "<f4").tobytes()[:-4])           # 28 bytes
    with pytest.raises(sceneio.SceneError, match="size 28 bytes is not a multiple of the 16-byte record") as err:
        sceneio.read_lidar(path)
    assert str(path) in str(err.value)
    drive, spec = raw_drive(tmp_path)
    sweep = drive / "velodyne_points" / "data" / "0000000001.bin"
    sweep.write_bytes(sweep.read_bytes()[:-3])
    out = tmp_path / "out" / RAW_SCENE
    with pytest.raises(AdapterError, match="not a non-empty multiple of the 16-byte record") as err:
        adapt_scene("k", spec, RAW_SCENE, out)
    assert str(sweep) in str(err.value)
    assert_no_output(out)


# --------------------------------------------------------------------------------- 3. truncated PNG
def test_truncated_png(tmp_path):
    src, spec = scene_folder_dataset(tmp_path)
    png = src / "cam_front" / "000001.png"
    png.write_bytes(png.read_bytes()[:-20])                         # header intact, IEND gone
    with pytest.raises(sceneio.SceneError, match="unreadable") as err:
        sceneio.read_image(png)
    assert str(png) in str(err.value)
    out = tmp_path / "out" / "train_s1"
    with pytest.raises(AdapterError, match="truncated PNG") as err:    # linked files are checked at adaptation
        adapt_scene("sf", spec, "train_s1", out)
    assert str(png) in str(err.value)
    assert_no_output(out)


# --------------------------------------------------------------------- 4. a frame missing from one sensor
def test_frame_missing_from_one_sensor(tmp_path):
    drive, spec = raw_drive(tmp_path, n_frames=3)
    (drive / "velodyne_points" / "data" / "0000000001.bin").unlink()
    out = tmp_path / "out" / RAW_SCENE
    with pytest.raises(AdapterError, match=r"1 of 3 velodyne sweeps missing \(0000000001.bin\)") as err:
        adapt_scene("k", spec, RAW_SCENE, out)
    assert str(drive / "velodyne_points" / "data") in str(err.value)
    assert_no_output(out)
    scene = tmp_path / "canonical"                                   # and in a canonical scene
    (scene / "cam_front").mkdir(parents=True)
    for i in (0, 2):
        (scene / "cam_front" / f"{i:06d}.png").write_bytes(b"x")
    with pytest.raises(sceneio.SceneError, match=r"1 of 3 frames missing \(000001.png\)"):
        sceneio.sensor_frames(scene, "cam_front", "png", 3)


def test_scene_folder_camera_with_a_frame_fewer(tmp_path):
    src, spec = scene_folder_dataset(tmp_path, n_frames=3, cameras=("cam_front", "cam_back"))
    (src / "cam_back" / "000002.png").unlink()
    out = tmp_path / "out" / "train_s1"
    with pytest.raises(AdapterError, match="2 images, but .* has 3") as err:
        adapt_scene("sf", spec, "train_s1", out)
    assert str(src / "cam_back") in str(err.value)
    assert_no_output(out)


# ---------------------------------------------------------------------- 5. non-finite / non-orthonormal poses
POSE_ROW = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0]


@pytest.mark.parametrize("bad, problem", [
    ([1, 0, 0, float("nan"), 0, 1, 0, 0, 0, 0, 1, 0], "non-finite"),
    ([1, 0, 0, float("inf"), 0, 1, 0, 0, 0, 0, 1, 0], "non-finite"),
    ([2, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0], "not a rotation"),      # scaled axis
    ([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, -1, 0], "not a rotation"),     # a reflection: orthonormal, det -1
], ids=["nan", "inf", "scaled", "reflection"])
def test_bad_poses(tmp_path, bad, problem):
    path = tmp_path / "ego_poses.txt"
    np.savetxt(path, np.array([POSE_ROW, bad, POSE_ROW], dtype=float))
    with pytest.raises(sceneio.SceneError, match=problem) as err:
        sceneio.read_poses(path)
    assert str(path) in str(err.value) and "line 2" in str(err.value)


def test_bad_poses_of_a_dataset_fail_adaptation(tmp_path):
    src, spec = scene_folder_dataset(tmp_path)
    np.savetxt(src / "ego_poses.txt", np.array([POSE_ROW, [1.01, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0]]))
    out = tmp_path / "out" / "train_s1"
    with pytest.raises(sceneio.SceneError, match="line 2.*not a rotation") as err:
        adapt_scene("sf", spec, "train_s1", out)
    assert str(src / "ego_poses.txt") in str(err.value)
    assert_no_output(out)
    drive, spec = raw_drive(tmp_path, oxts=[[49.0, 8.4, 110.0, 0.0, 0.0, 0.0], [49.0, float("nan"), 110.0, 0, 0, 0]])
    out = tmp_path / "out" / RAW_SCENE
    with pytest.raises(AdapterError, match="non-finite") as err:
        adapt_scene("k", spec, RAW_SCENE, out)
    assert "0000000001.txt" in str(err.value)
    assert_no_output(out)


def test_non_rigid_extrinsics(tmp_path):
    path = tmp_path / "extrinsics.json"
    T = np.eye(4)
    T[0, 1] = 0.5
    path.write_text(json.dumps({"cam_front": T.tolist()}))
    with pytest.raises(sceneio.SceneError, match="'cam_front'.*not a rotation") as err:
        sceneio.read_extrinsics(path)
    assert str(path) in str(err.value)


# ---------------------------------------------------------------------------- 6. duplicate timestamps
def test_duplicate_timestamps(tmp_path):
    drive, spec = raw_drive(tmp_path, n_frames=3)
    stamps = drive / "velodyne_points" / "timestamps.txt"
    stamps.write_text("2011-09-26 13:02:25.964389445\n2011-09-26 13:02:26.073976565\n"
                      "2011-09-26 13:02:26.073976565\n")
    out = tmp_path / "out" / RAW_SCENE
    with pytest.raises(AdapterError, match="line 3 repeats the timestamp of line 2") as err:
        adapt_scene("k", spec, RAW_SCENE, out)
    assert str(stamps) in str(err.value)
    assert_no_output(out)
    stamps.write_text("2011-09-26 13:02:25.964389445\n2011-09-26 13:02:26.073976565\nnot a time\n")
    with pytest.raises(AdapterError, match="line 3 is not a timestamp"):
        adapt_scene("k", spec, RAW_SCENE, out)
    stamps.write_text("2011-09-26 13:02:25.964389445\n2011-09-26 13:02:26.073976565\n"
                      "2011-09-26 13:02:26.173976565\n")                 # strictly increasing: accepted
    assert adapt_scene("k", spec, RAW_SCENE, out)["frames"] == 3


# --------------------------------------------------------------------------------- 7. empty scene folder
def test_empty_scene_folder(tmp_path):
    scene = tmp_path / "world_kitti" / "test_000"
    scene.mkdir(parents=True)
    with pytest.raises(sceneio.SceneError, match="scene.json: missing") as err:
        sceneio.read_meta(scene)
    assert str(scene / "scene.json") in str(err.value)
    src, spec = scene_folder_dataset(tmp_path)
    for png in (src / "cam_front").iterdir():
        png.unlink()
    out = tmp_path / "out" / "train_s1"
    with pytest.raises(AdapterError, match="no images") as err:
        adapt_scene("sf", spec, "train_s1", out)
    assert str(src / "cam_front") in str(err.value)
    assert_no_output(out)


# ------------------------------------------------------------------------- 8. KITTI label with 14 fields
def test_kitti_label_line_with_14_fields(tmp_path):
    t = kitti_object_fixture(tmp_path / "obj")
    label = t / "label_2" / "000007.txt"
    label.write_text("Car 0.12 1 -1.62 18.40 6.10 25.60 14.90 1.50 1.60 4.00 1.00 1.50 20.00\n")
    spec = {"kind": "kitti_object", "path": str(tmp_path / "obj"), "crop": NO_CROP, "resize": RESIZE}
    out = tmp_path / "out" / "train_000007"
    with pytest.raises(AdapterError, match="line 1 has 14 fields, a KITTI label has 15") as err:
        adapt_scene("ko", spec, "train_000007", out)
    assert str(label) in str(err.value)
    assert_no_output(out)


# -------------------------------------------------------------------- 9. RLE mask size vs the image
def test_rle_mask_whose_size_disagrees_with_the_image(tmp_path):
    path = tmp_path / "000007.json"
    mask = np.zeros((H + 1, W), bool)
    mask[2:5, 3:9] = True
    path.write_text(json.dumps([{"category_id": 3, "score": 0.9, "segmentation": rle.encode(mask)}]))
    with pytest.raises(AdapterError, match=rf"entry 0: mask size \[{H + 1}, {W}\] is not the image's") as err:
        load_detections(path, (W, H), {3: "car"}, 0.5)
    assert str(path) in str(err.value)
    # the stated size matches, the run lengths do not (one pixel short)
    seg = {"size": [H, W], "counts": [5, 10, W * H - 16]}
    path.write_text(json.dumps([{"category_id": 3, "score": 0.9, "segmentation": seg}]))
    with pytest.raises(AdapterError, match=f"entry 0: RLE run lengths sum to {W * H - 1}") as err:
        load_detections(path, (W, H), {3: "car"}, 0.5)
    assert str(path) in str(err.value)


def test_bad_detection_file_fails_adaptation_without_output(tmp_path):
    root = tmp_path / "obj"
    kitti_object_fixture(root)
    dets = tmp_path / "dets"
    (dets / "training" / "image_2").mkdir(parents=True)
    seg = rle.encode(np.ones((H, W + 2), bool))
    (dets / "training" / "image_2" / "000007.json").write_text(
        json.dumps([{"category_id": 3, "score": 0.9, "segmentation": seg}]))
    spec = {"kind": "kitti_object", "path": str(root), "crop": NO_CROP, "resize": RESIZE,
            "instances": {"source": "detections", "path": str(dets)}}
    out = tmp_path / "out" / "train_000007"
    with pytest.raises(AdapterError, match="mask size") as err:
        adapt_scene("ko", spec, "train_000007", out)
    assert "000007.json" in str(err.value)
    assert_no_output(out)


# ---------------------------------------------------------------------- 10. malformed annotation.json
@pytest.mark.parametrize("text, problem", [
    ('[{"bbox": {"top": 1, "left": 2', "not valid JSON"),
    ('{"bbox": [1, 2, 3, 4]}', "expected a list of annotated vehicles"),
    ('[{"bbox": [1, 2, 3], "velocity": [0, 0], "position": [10, 0]}]', "bbox must be"),
], ids=["truncated-json", "not-a-list", "bbox-3-values"])
def test_malformed_annotation_json(tmp_path, text, problem):
    root, source = tusimple_split(tmp_path)
    ann = root / "clips" / "1" / "annotation.json"
    ann.write_text(text)
    out = tmp_path / "out" / "train"
    with pytest.raises(AdapterError, match=problem) as err:
        adapt_clips(source, "train", out)
    assert str(ann) in str(err.value)
    assert_no_output(out)


def test_malformed_annotation_json_of_a_canonical_clip(tmp_path):
    clip = tmp_path / "clips" / "1"
    clip.mkdir(parents=True)
    (clip / "annotation.json").write_text('[{"bbox": {"top": 1}, "velocity": [0, 0], "position": [1, 0]}]')
    with pytest.raises(sceneio.SceneError, match="each entry needs bbox") as err:
        read_annotations(clip)
    assert str(clip / "annotation.json") in str(err.value)


# ----------------------------------------------------------------------- 11. TuSimple clip missing frames
def test_tusimple_clip_with_missing_frames(tmp_path):
    root, source = tusimple_split(tmp_path)
    imgs = root / "clips" / "1" / "imgs"
    (imgs / "017.jpg").unlink()
    (imgs / "040.jpg").unlink()
    out = tmp_path / "out" / "train"
    with pytest.raises(AdapterError, match=r"2 of 40 frames missing \(017, 040\)") as err:
        adapt_clips(source, "train", out)
    assert str(imgs) in str(err.value)
    assert_no_output(out)
    (imgs / "017.jpg").write_bytes(b"")
    (imgs / "040.jpg").write_bytes(b"")
    assert adapt_clips(source, "train", out)["clips"] == 1


# ------------------------------------------------------------------------ 12-14. configuration
def test_misspelled_config_key():
    with pytest.raises(config.ConfigError, match=r"depth.train: Additional properties .*'stpes' was unexpected"):
        config.load(CONFIG, {"depth": {"train": {"stpes": 3}}})
    with pytest.raises(config.ConfigError, match=r"profiles.tiny.depth.trian is not a known key"):
        config.load(CONFIG, {"profiles": {"tiny": {"depth": {"trian": {"steps": 3}}}}})


@pytest.mark.parametrize("override, key, problem", [
    ({"depth": {"train": {"steps": "ten"}}}, "depth.train.steps", "is not of type 'integer'"),
    ({"depth": {"train": {"steps": -5}}}, "depth.train.steps", "less than the minimum of 1"),
    ({"depth": {"train": {"lr": 0}}}, "depth.train.lr", "less than or equal to the minimum of 0"),
    ({"depth": {"train": {"lr": -1e-4}}}, "depth.train.lr", "less than or equal to the minimum of 0"),
    ({"seed": 1.5}, "seed", "is not of type 'integer'"),
], ids=["steps-string", "steps-negative", "lr-zero", "lr-negative", "seed-float"])
def test_config_value_of_wrong_type_or_out_of_range(override, key, problem):
    with pytest.raises(config.ConfigError) as err:
        config.load(CONFIG, override)
    lines = [ln for ln in str(err.value).splitlines() if ln.strip().startswith(f"- {key}:")]
    assert lines and problem in lines[0], str(err.value)


def test_profile_that_does_not_exist():
    with pytest.raises(config.ConfigError, match=r"profile: 'huge' is not one of \['tiny', 'default', 'paper'\]"):
        config.load(CONFIG, {"profile": "huge"})


# ------------------------------------------------------------------- end to end, --keep-going, tiny
@pytest.mark.workflow
def test_bad_label_fails_its_own_jobs_only(tmp_path):
    """Two KITTI object frames, one with a 14-field label line: with --keep-going the good frame is
    adapted and prepared; the bad frame's adapt_scene fails naming the label file and leaves no scene."""
    root = tmp_path / "obj"
    t = kitti_object_fixture(root)
    for sub, ext in (("calib", ".txt"), ("image_2", ".png"), ("velodyne", ".bin"), ("label_2", ".txt")):
        shutil.copyfile(t / sub / f"000007{ext}", t / sub / f"000008{ext}")
    (t / "label_2" / "000008.txt").write_text("Car 0.12 1 -1.62 18.40 6.10 25.60 14.90 1.50 1.60 4.00 1.00 1.50 20.00\n")
    extra = tmp_path / "extra.yaml"
    extra.write_text(yaml.safe_dump({"datasets": {"drill_object": {
        "kind": "kitti_object", "path": str(root), "crop": NO_CROP, "resize": RESIZE}}}))
    good = "results/prepared/drill_object/train_000007/cam_front.npz"
    bad = "results/prepared/drill_object/train_000008/cam_front.npz"
    work = tmp_path / "w"
    proc = run_snakemake(work, "--keep-going", good, bad, "--configfile", str(extra), check=False)
    out = proc.stdout + proc.stderr
    assert proc.returncode != 0, out[-3000:]
    assert (work / good).is_file(), out[-3000:]
    assert not (work / bad).exists()
    assert_no_output(work / "results" / "raw" / "drill_object" / "train_000008")
    logs = "".join(p.read_text() for p in (work / "results" / "logs").rglob("*train_000008*") if p.is_file())
    assert "000008.txt: line 1 has 14 fields" in logs, out[-3000:]
