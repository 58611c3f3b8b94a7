"""Dataset adapters on the genuine samples of the `realdata` fixture ($REDSUP_REALDATA, else ../shared/realdata:
KITTI object frames 000000-000003, a 10-frame 2011_09_26 raw drive with its real calibration, one TuSimple clip).
Skipped when that folder is absent; the files are read in place, never copied into the repository.
"""
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import yaml

from conftest import run_snakemake
from redsup import eval_frame, geometry, sceneio
from redsup.adapters import adapt_scene, scene_ids
from redsup.adapters.tusimple import adapt_clips
from redsup.boxes3d import points_in_box
from redsup.det3d.kitti_eval import evaluate
from redsup.det3d.kitti_types import FrameDet
from redsup.det3d.scenes import gt_frames
from redsup.depth.evaluation import garg_crop_mask
from redsup.prep.depthmap import lidar_depth_maps
from redsup.prep.medianflow import track_split

pytestmark = pytest.mark.usefixtures("realdata")  # skipped without the real data samples

NO_CROP = {"top": 0, "bottom": 0, "left": 0, "right": 0}
RAW_SCENE = "test_2011_09_26_drive_0000_sync"


def object_spec(real: Path):
    return {"kind": "kitti_object", "path": str(real / "kitti_object"), "crop": NO_CROP,
            "resize": {"width": 320, "height": 96}, "instances": {"source": "label_boxes"}}


def raw_spec(real: Path):
    return {"kind": "kitti_raw", "path": str(real / "kitti_raw"), "split": "test", "crop": NO_CROP,
            "resize": {"width": 320, "height": 96}}


@pytest.fixture(scope="module")
def object_scenes(tmp_path_factory, realdata):
    out = tmp_path_factory.mktemp("kitti_object")
    ids = scene_ids("kitti_object", object_spec(realdata))
    assert ids == ["train_000000", "train_000001", "train_000002", "train_000003"]
    for scene in ids:
        adapt_scene("kitti_object", object_spec(realdata), scene, out / scene)
    return [out / s for s in ids]


def test_lidar_points_of_each_car_project_into_its_2d_box(object_scenes):
    """Real calibration: the Velodyne returns inside each labelled car's 3D box land in its 2D label box."""
    n_cars = 0
    for scene in object_scenes:
        boxes = sceneio.read_boxes(scene / "gt" / "boxes.csv")
        extr = sceneio.read_extrinsics(scene / "extrinsics.json")
        K, _ = sceneio.read_intrinsics(scene / "cam_front.txt")
        vehicle = geometry.transform_points(extr["lidar_top"],
                                            sceneio.read_lidar(scene / "lidar_top" / "000000.bin")[:, :3].astype(float))
        camera = geometry.transform_points(geometry.invert_pose(extr["cam_front"]), vehicle)
        T_eval = eval_frame.scene_eval_transform(scene)       # n_lidar: counted upright in rect0, as the devkit
        points_eval = geometry.transform_points(T_eval, vehicle)
        for _, car in boxes[boxes.cls == "Car"].iterrows():
            box = eval_frame.to_eval_frame(car[["x", "y", "z", "l", "w", "h", "yaw"]].to_numpy(float), T_eval)[0]
            inside = points_in_box(points_eval, box)
            assert inside.sum() == car.n_lidar >= 5
            uv, z = geometry.project(K, camera[inside])
            in_2d = ((uv[:, 0] >= car.x1 - 2) & (uv[:, 0] <= car.x2 + 2)
                     & (uv[:, 1] >= car.y1 - 2) & (uv[:, 1] <= car.y2 + 2))
            assert (z > 0).all() and in_2d.mean() >= 0.9, (scene.name, car.to_dict(), in_2d.mean())
            n_cars += 1
    assert n_cars == 3


def test_ground_truth_against_itself_is_perfect(object_scenes):
    """KITTI AP of the labels as detections. With n valid objects the devkit's 41 recall points give a perfect
    detector 100 (n - 1) / 40 for R40 (see kitti_eval); repeating the frames to >= 41 valid cars gives 100."""
    gts = [g for scene in object_scenes for g in gt_frames(scene)]

    def as_dets(g):
        keep = np.array([c.lower() != "dontcare" for c in g.cls], bool)
        return FrameDet(boxes=g.boxes[keep], bbox=g.bbox[keep], score=np.ones(keep.sum()), cls=g.cls[keep])

    metrics = ("2d", "bev", "3d")
    ap = evaluate(gts, [as_dets(g) for g in gts], metrics=metrics)
    # the 3 cars: 21.6 px tall (ignored), 33 px (moderate, hard), 103 px (every difficulty)
    n_valid = {"easy": 1, "moderate": 2, "hard": 2}
    for metric in metrics:
        for difficulty, n in n_valid.items():
            assert ap[f"Car_{metric}_0.7/{difficulty}_R40"] == pytest.approx(100 * (n - 1) / 40)
    repeated = gts * 41
    ap = evaluate(repeated, [as_dets(g) for g in repeated], metrics=metrics)
    assert all(v == pytest.approx(100.0) for v in ap.values()), ap


def monodepth2_depth(calib_dir: Path, velo_path: Path, verbatim_sub2ind: bool = False) -> np.ndarray:
    """Monodepth2's `generate_depth_map` (kitti_utils.py) with plain numpy: P_rect_02 R_rect_00 T_velo_cam,
    depth = the third homogeneous coordinate, points behind the Velodyne dropped, pixel = round - 1, nearest
    depth per pixel. Monodepth2's own `sub2ind` (row * (W - 1) + col - 1) also merges pixel (r, W - 1) with
    (r + 1, 0); `verbatim_sub2ind` reproduces that too (it only touches the first and last columns)."""
    def read(path):
        out = {}
        for line in path.read_text().splitlines():
            key, _, value = line.partition(":")
            try:
                out[key] = np.array([float(v) for v in value.split()])
            except ValueError:
                pass
        return out

    cam2cam, velo2cam = read(calib_dir / "calib_cam_to_cam.txt"), read(calib_dir / "calib_velo_to_cam.txt")
    velo2cam = np.vstack([np.hstack([velo2cam["R"].reshape(3, 3), velo2cam["T"][:, None]]), [0, 0, 0, 1.0]])
    im_shape = cam2cam["S_rect_02"][::-1].astype(np.int32)
    R_cam2rect = np.eye(4)
    R_cam2rect[:3, :3] = cam2cam["R_rect_00"].reshape(3, 3)
    P_velo2im = cam2cam["P_rect_02"].reshape(3, 4) @ R_cam2rect @ velo2cam
    velo = np.fromfile(velo_path, dtype=np.float32).reshape(-1, 4)
    velo = velo[velo[:, 0] >= 0, :].astype(np.float64)
    velo[:, 3] = 1.0
    pts = (P_velo2im @ velo.T).T
    pts[:, :2] = pts[:, :2] / pts[:, 2][..., None]
    pts[:, 0] = np.round(pts[:, 0]) - 1
    pts[:, 1] = np.round(pts[:, 1]) - 1
    ok = (pts[:, 0] >= 0) & (pts[:, 1] >= 0) & (pts[:, 0] < im_shape[1]) & (pts[:, 1] < im_shape[0])
    pts = pts[ok]
    depth = np.zeros(im_shape[:2])
    depth[pts[:, 1].astype(int), pts[:, 0].astype(int)] = pts[:, 2]
    inds = pts[:, 1] * (im_shape[1] - 1) + pts[:, 0] - 1 if verbatim_sub2ind else pts[:, 1] * im_shape[1] + pts[:, 0]
    for dd in [i for i, c in Counter(inds).items() if c > 1]:
        sel = np.where(inds == dd)[0]
        depth[int(pts[sel[0], 1]), int(pts[sel[0], 0])] = pts[sel, 2].min()
    depth[depth < 0] = 0
    return depth


def test_raw_prepared_depth_equals_the_monodepth2_ground_truth(tmp_path, realdata):
    scene = tmp_path / RAW_SCENE
    assert scene_ids("kitti_raw", raw_spec(realdata)) == [RAW_SCENE]
    assert adapt_scene("kitti_raw", raw_spec(realdata), RAW_SCENE, scene)["frames"] == 10
    depth_range = (0.1, 80.0)
    lidar_depth_maps(scene, "cam_front", NO_CROP, depth_range, tmp_path / "depth.npz")  # what rule lidar_depth runs
    ours = np.load(tmp_path / "depth.npz")["depth"]
    date = realdata / "kitti_raw" / "2011_09_26"
    sweeps = sorted((date / "2011_09_26_drive_0000_sync" / "velodyne_points" / "data").glob("*.bin"))
    assert ours.shape == (10, 375, 1242) and len(sweeps) == 10
    for i, sweep in enumerate(sweeps):
        ref = monodepth2_depth(date, sweep)
        ref[(ref <= depth_range[0]) | (ref >= depth_range[1])] = 0  # the evaluation's depth cap
        assert np.array_equal(ours[i] > 0, ref > 0), i
        assert np.abs(ours[i] - ref).max() < 1e-4  # float32 storage
        assert (ref > 0).sum() > 15000
        # Monodepth2's published ground truth (its sub2ind quirk included) is the same inside the Garg crop
        verbatim = monodepth2_depth(date, sweep, verbatim_sub2ind=True)
        verbatim[(verbatim <= depth_range[0]) | (verbatim >= depth_range[1])] = 0
        crop = garg_crop_mask(*ours[i].shape)
        assert np.abs(ours[i][crop] - verbatim[crop]).max() < 1e-4


def test_medianflow_track_on_the_real_tusimple_clip(tmp_path, realdata):
    source = {"kind": "tusimple", "splits": {"train": {"path": str(realdata / "tusimple_velocity" / "train")}}}
    assert adapt_clips(source, "train", tmp_path / "train")["vehicles"] == 1
    arrays, summary = track_split(tmp_path / "train", {"n_frames": 40, "near": 20.0, "far": 45.0})
    assert summary["n_vehicles"] == 1 and summary["n_medium"] == 1 and not arrays["failed"].any()
    left, top, right, bottom = 784.6638793945, 340.3418273926, 868.1537475586, 393.3275146484
    assert arrays["boxes"][0, -1] == pytest.approx([left, top, right - left, bottom - top], abs=1e-3)
    assert arrays["position"][0] == pytest.approx([21.30970213, 2.7243980956])
    # the car closes in at 1.2 m/s: its box 2 s earlier is smaller
    assert arrays["boxes"][0, 0, 2] < arrays["boxes"][0, -1, 2]


@pytest.mark.workflow
def test_dag_with_real_datasets_configured(tmp_path, realdata):
    """Dry run: a kitti_raw and a kitti_object dataset and a TuSimple train split go through the same rules."""
    clips = str(realdata / "tusimple_velocity" / "train")
    extra = {"datasets": {"real_raw": raw_spec(realdata), "real_object": object_spec(realdata)},
             "velocity_clips": {"source": {"kind": "tusimple", "splits": {"train": {"path": clips}}}}}
    cfg = tmp_path / "real.yaml"
    cfg.write_text(yaml.safe_dump(extra))
    raw = f"results/prepared/real_raw/{RAW_SCENE}"
    obj = "results/prepared/real_object/train_000003"
    targets = [f"{raw}/cam_front_depth.npz", f"{raw}/tracks3d_coco.csv", f"{raw}/road.npz",
               f"{obj}/cam_front.npz", f"{obj}/detections_cityscapes.npz",
               "results/prepared/clips/train/medianflow.npz",
               "results/prepared/clips/abnormal/medianflow.npz"]
    proc = run_snakemake(tmp_path / "w", "-n", *targets, "--configfile", str(cfg))  # --configfile takes several
    out = proc.stdout
    for rule, n in (("adapt_scene", 2), ("adapt_clips", 1), ("world_clips", 1), ("lidar_depth", 1), ("medianflow", 2)):
        assert any(line.split()[:2] == [rule, str(n)] for line in out.splitlines()), (rule, out[-3000:])
    assert "world_scene" not in out
    assert f"results/raw/real_raw/{RAW_SCENE}" in out
