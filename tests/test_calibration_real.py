"""Calibration (McCraith ch. 5) on an adapted KITTI raw scene of the shared real-data sample
(`realdata`/kitti_raw, 10 frames of a 2011_09_26 drive with its real calibration files): the camera
height comes from that scene's extrinsics (checked against the height computed by hand from the KITTI
calibration files), and a calibration job runs on the scene's real LiDAR ground truth. Skipped when the
sample is absent; the files are read in place, never copied into the repository.
"""
from pathlib import Path

import numpy as np
import pytest

import yaml

from conftest import run_snakemake
from redsup import geometry, sceneio
from redsup.adapters import adapt_scene, scene_ids
from redsup.calib import inputs, methods
from redsup.prep import masks_io
from redsup.prep.depthmap import lidar_depth_maps

pytestmark = pytest.mark.usefixtures("realdata")  # skipped without the real data samples

NO_CROP = {"top": 0, "bottom": 0, "left": 0, "right": 0}
RAW_SCENE = "test_2011_09_26_drive_0000_sync"
IMU_HEIGHT = 0.93  # the adapter's default: the vehicle origin lies 0.93 m below the OXTS IMU, on the road


def _read_calib(path: Path) -> dict:
    out = {}
    for line in path.read_text().splitlines():
        key, _, value = line.partition(":")
        try:
            out[key.strip()] = np.array([float(v) for v in value.split()])
        except ValueError:
            pass
    return out


def _rigid(calib: dict) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = calib["R"].reshape(3, 3)
    T[:3, 3] = calib["T"]
    return T


def height_by_hand(date_dir: Path) -> float:
    """Height of the rectified camera 2 above the road, from the three KITTI calibration files only:
    camera 2's centre in the rectified camera-0 frame is -K^-1 P_rect_02[:, 3]; un-rectify with R_rect_00^T,
    go to the Velodyne frame (inverse of calib_velo_to_cam), to the IMU frame (inverse of calib_imu_to_velo)
    and add the IMU's height above the road."""
    cam = _read_calib(date_dir / "calib_cam_to_cam.txt")
    P = cam["P_rect_02"].reshape(3, 4)
    centre_rect = -np.linalg.solve(P[:, :3], P[:, 3])
    centre_cam0 = cam["R_rect_00"].reshape(3, 3).T @ centre_rect
    T_cam_velo = _rigid(_read_calib(date_dir / "calib_velo_to_cam.txt"))
    T_velo_imu = _rigid(_read_calib(date_dir / "calib_imu_to_velo.txt"))
    centre_imu = np.linalg.inv(T_velo_imu) @ np.linalg.inv(T_cam_velo) @ np.append(centre_cam0, 1.0)
    return float(centre_imu[2] + IMU_HEIGHT)


def raw_spec(real: Path):
    return {"kind": "kitti_raw", "path": str(real / "kitti_raw"), "split": "test", "crop": NO_CROP,
            "resize": {"width": 320, "height": 96}}


@pytest.fixture(scope="module")
def scene(tmp_path_factory, realdata):
    out = tmp_path_factory.mktemp("kitti_raw") / RAW_SCENE
    assert scene_ids("kitti_raw", raw_spec(realdata)) == [RAW_SCENE]
    adapt_scene("kitti_raw", raw_spec(realdata), RAW_SCENE, out)
    return out


def test_camera_height_of_the_adapted_scene_is_the_one_of_the_kitti_calibration(scene, realdata):
    by_hand = height_by_hand(realdata / "kitti_raw" / "2011_09_26")
    assert 1.6 < by_hand < 1.7  # KITTI's camera rig: about 1.65 m
    geo = inputs.camera_geometry(scene, "cam_front")
    assert geo["camera_height"] == pytest.approx(by_hand, abs=1e-6)
    assert geo["fps"] == 10.0  # KITTI raw, the scene's scene.json


def _flat_road_prediction(scene_dir: Path, size=(96, 320), scale=25.0):
    """A stand-in network output on the scene's real camera: the road plane z_vehicle = 0 (seen through the
    real extrinsics and intrinsics) divided by ``scale``, a wall at 30 m above the horizon; and road masks
    of the lower image half (raw resolution), as the road segmenter would give."""
    K_raw, (w, h) = sceneio.read_intrinsics(scene_dir / "cam_front.txt")
    K = geometry.crop_resize_intrinsics(K_raw, NO_CROP, (w, h), (size[1], size[0]))
    T = sceneio.read_extrinsics(scene_dir / "extrinsics.json")["cam_front"]  # T_vehicle_camera
    normal, offset = T[2, :3], T[2, 3]  # vehicle z of a camera point X: normal . X + offset
    v, u = np.mgrid[0:size[0], 0:size[1]].astype(float)
    rays = np.stack([u, v, np.ones_like(u)], -1) @ np.linalg.inv(K).T
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -offset / (rays @ normal)
    depth = np.where((t > 0) & (t < 30.0), t, 30.0) / scale
    road_raw = np.zeros((h, w), bool)
    road_raw[int(0.6 * h):, :] = True
    return depth.astype(np.float32), K, road_raw, (w, h)


def test_calibration_runs_on_the_adapted_kitti_raw_scene(scene, tmp_path, realdata):
    n = sceneio.read_meta(scene)["n_frames"]
    lidar_depth_maps(scene, "cam_front", NO_CROP, (0.1, 80.0), tmp_path / "gt.npz")  # rule lidar_depth
    depth, K, road_raw, (w, h) = _flat_road_prediction(scene)
    np.savez(tmp_path / "pred.npz", depth=np.stack([depth] * n), K=K)
    np.savez(tmp_path / "road.npz", road=masks_io.pack_masks([road_raw] * n, (w, h)), image_size=np.array([w, h]))
    test = [inputs.load_scene(tmp_path / "pred.npz", tmp_path / "gt.npz", tmp_path / "road.npz", crop=NO_CROP,
                              name=scene.name)]
    # what calibration_eval does: the height from the scene's extrinsics, no world domain in the config
    heights = {scene.name: inputs.camera_geometry(scene, "cam_front")["camera_height"]}
    cal = {"length": 30.0, "width": 3.0, "min_points": 20, "lmeds_iterations": 100, "max_tilt_deg": None,
           "fallback": "hold", "eval": {"min_depth": 1e-3, "max_depth": 80.0, "crop": "garg"}}
    result = methods.evaluate_method("road_L30_W3", test, cal, heights=heights, seed=0)
    assert result["camera_height"] == {scene.name: pytest.approx(height_by_hand(realdata / "kitti_raw" / "2011_09_26"))}
    s = result["summary"]
    assert (s["n_frames"], s["n_not_evaluable"], s["coverage"]) == (n, 0, 1.0)
    # the road plane seen through the real rig at the real height gives back the prediction's scale
    assert all(f["scale"] == pytest.approx(25.0, rel=1e-3) for f in result["frames"])
    assert np.isfinite(s["abs_rel"]) and 0 <= s["a1"] <= 1
    # a wrong height scales the depth by the ratio: the height matters
    wrong = methods.evaluate_method("road_L30_W3", test, cal, heights={scene.name: 2 * heights[scene.name]}, seed=0)
    assert wrong["frames"][0]["scale"] == pytest.approx(50.0, rel=1e-3)
    gt_med = methods.evaluate_method("gt_median", test, cal, heights=heights, seed=0)
    assert sorted(methods.per_frame(gt_med, "abs_rel")) == sorted(methods.per_frame(result, "abs_rel"))


@pytest.mark.workflow
def test_dag_calibrates_a_kitti_raw_dataset(tmp_path, realdata):
    """Dry run: calibration.dataset set to an adapted KITTI raw dataset (test scenes only) plans
    calibration_eval on its scene, predicted by the model of calibration.model_dataset; the raw scene folder,
    hence its extrinsics, is an input. Without model_dataset the plan fails, naming the key to set."""
    cfg = tmp_path / "real.yaml"
    target = "results/calibration/real_raw/M/road_L30_W3.json"
    cal = {"dataset": "real_raw", "model_dataset": None}
    cfg.write_text(yaml.safe_dump({"datasets": {"real_raw": raw_spec(realdata)}, "calibration": cal}))
    failed = run_snakemake(tmp_path / "w0", "-n", target, "--configfile", str(cfg), check=False)
    assert failed.returncode != 0
    assert "no depth model 'real_raw/M'" in failed.stderr + failed.stdout
    assert "calibration.model_dataset" in failed.stderr + failed.stdout

    cfg.write_text(yaml.safe_dump({"datasets": {"real_raw": raw_spec(realdata)},
                                   "calibration": {**cal, "model_dataset": "world_kitti"}}))
    out = run_snakemake(tmp_path / "w", "-n", target, "--configfile", str(cfg)).stdout
    assert any(line.split()[:2] == ["calibration_eval", "1"] for line in out.splitlines()), out[-3000:]
    assert f"results/raw/real_raw/{RAW_SCENE}" in out
    assert "results/depth/models/world_kitti/M.pt" in out and "results/depth/models/real_raw" not in out
    assert "results/raw/world_kitti/test_" not in out  # the world's test scenes are not consulted
