"""The embedded world: ray casting against hand-computed cases, sensor agreement, photometric consistency,
glass pass-through, ground truth, determinism, the canonical scene format and the velocity clips."""
import copy
import json
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest

from redsup import config, geometry, sceneio
from redsup.world import shards, textures
from redsup.world.clips import merge_shards, render_shard, write_clips
from redsup.world.common import derive_rng, pose
from redsup.world.ego import make_ego, speed_profile
from redsup.world.generate import depth_png, write_scene
from redsup.world.gt import frame_rows, own_pixels
from redsup.world.layout import build_world, frame_state, make_style
from redsup.world.lidar import sweep
from redsup.world.motorway import build_motorway
from redsup.world.prims import KIND_BUILDING, Prims, car_parts, car_prims
from redsup.world.raycast import cast
from redsup.world.road import PART_ROAD, Road
from redsup.world.sensors import R_VEHICLE_FRONT, Camera, Lidar, fine_camera, intrinsics
from redsup.world.shade import SceneView, render_camera

ROOT = Path(__file__).resolve().parents[1]
LABELS = {7, 8, 11, 17, 21, 23, 26}


@pytest.fixture(scope="module")
def cfg():
    """The tiny profile, with small renders so the tests stay fast."""
    c = config.load(ROOT / "config.yaml", {"profile": "tiny"})
    world = copy.deepcopy(c["world"])
    world["frames"] = {"train": 3, "test": 2, "long": 4}
    world["lidar"]["azimuth_steps"] = 512
    for dom in world["domains"].values():
        dom["width"], dom["height"] = 192, 96
    c["world"] = world
    return c


@pytest.fixture(scope="module")
def scene(cfg, tmp_path_factory):
    out = tmp_path_factory.mktemp("world") / "train_000"
    summary = write_scene(cfg["world"], "world_kitti", "lyft_like", "train", 0, 11, out)
    return out, summary


def flat_view(cfg, cars=None, grade=(0.0, 0.0), camber=0.0):
    """A hand-made scene: a straight road with the given knot slopes, the kitti_like style."""
    slopes = np.array([grade[0], grade[0], grade[1], grade[1]])
    knots = np.array([-1000.0, 0.0, 60.0, 1000.0])
    heights = np.concatenate([[0.0], np.cumsum(0.5 * (slopes[1:] + slopes[:-1]) * np.diff(knots))])
    heights -= heights[1]
    road = Road(knots, slopes, heights, camber, 5.8, 0.13)
    dom = cfg["world"]["domains"]["kitti_like"]
    style = make_style(3, dom, cfg["world"]["road"], [[0.0, 0.12, 3.0, 6.0]], [1.75, -1.75], [], 5.8, 3.5)
    return SceneView(road, style, cars or {}, {})


def car_table(sizes):
    n = len(sizes)
    return {"track_id": np.arange(1, n + 1), "size": np.asarray(sizes, float),
            "colour": np.tile([0.6, 0.1, 0.1], (n, 1)), "phase": np.zeros(n)}


def camera(width=33, height=33, hfov=60.0, name="cam_front"):
    return Camera(name, intrinsics(width, height, hfov), width, height, np.eye(4))


# --------------------------------------------------------------------------------------- ray casting
def test_ray_straight_down_hits_road_at_camera_height(cfg):
    view = flat_view(cfg, grade=(0.03, -0.05))
    x0, h = 37.0, 1.65
    down = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # columns: cam x, y, z in world
    ground = float(view.road.height(np.array([x0]), np.array([0.0]))[0])
    T = pose(down, [x0, 0.0, ground + h])
    cam = camera()
    out = render_camera(cam, T, Prims.empty(), view, cfg["world"]["domains"]["kitti_like"]["appearance"], 0.0,
                        200.0, 350.0, derive_rng(0))
    assert out["depth"][16, 16] == pytest.approx(h, abs=1e-9)
    assert depth_png(out["depth"])[16, 16] == round(h * 256)
    assert out["label"][16, 16] == textures.ROAD


def test_sloped_ray_meets_the_quadratic_profile(cfg):
    view = flat_view(cfg, grade=(-0.04, 0.06), camber=0.01)
    origin = np.array([-20.0, -1.0, 1.7])
    dirs = np.array([[1.0, 0.05, -0.02], [1.0, -0.02, 0.01], [0.3, 1.0, -0.2]])
    t, part = view.road.intersect(origin, dirs, 400.0)
    assert np.all(np.isfinite(t))
    hit = origin + dirs * t[:, None]
    assert np.allclose(hit[:, 2], view.road.height(hit[:, 0], hit[:, 1]), atol=1e-7)
    for k in range(3):  # nothing crossed before: the ray stays above the ground up to t
        s = np.linspace(0.0, t[k] * 0.999, 2000)
        p = origin + dirs[k] * s[:, None]
        assert np.all(p[:, 2] > view.road.height(p[:, 0], p[:, 1]))
    assert part[0] == PART_ROAD  # the first ray stays between the kerbs (crossing the grade change at x = 0)


def test_ray_at_box_faces_returns_hand_computed_distance(cfg):
    view = flat_view(cfg)
    cam = camera()
    T = pose(R_VEHICLE_FRONT, [0.0, 0.0, 1.0])  # looking along world +x from (0, 0, 1)
    for yaw, expected in ((0.0, 9.0), (np.radians(30.0), 10.0 - 1.0 / np.cos(np.radians(30.0)))):
        c, s = np.cos(yaw), np.sin(yaw)
        R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        box = Prims.boxes([[10.0, 0.0, 1.0]], R[None], [[1.0, 1.0, 1.0]], KIND_BUILDING, 0)
        hits, _, _ = cast(cam, T, box, view.road, 200.0)
        centre = 16 * 33 + 16
        assert hits.prim[centre] == 0
        assert hits.t[centre] == pytest.approx(expected, abs=1e-4)
    lidar = Lidar("lidar_top", np.array([0.0]), 360, 120.0, np.eye(4))
    box = Prims.boxes([[10.0, 0.0, 1.0]], np.eye(3)[None], [[1.0, 1.0, 1.0]], KIND_BUILDING, 0)
    hits, _, _ = cast(lidar, pose(np.eye(3), [0.0, 0.0, 1.0]), box, view.road, 120.0)
    assert hits.t[0] == pytest.approx(9.0, abs=1e-4)          # azimuth 0: the face at x = 9
    assert hits.t[90] == np.inf and hits.prim[180] == -1      # azimuth 90, 180: nothing (no ground at 0 deg)


# ------------------------------------------------------------------------------ photometric consistency
def test_same_world_point_looks_the_same_from_two_poses(cfg):
    wc = cfg["world"]
    dom = copy.deepcopy(wc["domains"]["kitti_like"])
    dom["width"], dom["height"] = 320, 160
    world = build_world(wc, dom, derive_rng(5, "photo"), 4)
    view = SceneView(world.road, world.style, world.cars, world.buildings)
    state = frame_state(world, 0, 230.0)
    cam = Camera("cam_front", intrinsics(320, 160, dom["hfov_deg"]), 320, 160, np.eye(4))
    T_a = state.T_world_vehicle @ pose(R_VEHICLE_FRONT, [1.6, 0.0, 1.65])
    T_b = T_a @ pose(np.eye(3), [0.1, 0.0, 1.0])  # 1 m forward, 0.1 m right
    render = [render_camera(cam, T, state.prims, view, dom["appearance"], 0.0, 200.0, 350.0, derive_rng(1))
              for T in (T_a, T_b)]
    a, b = (r["rgb"].astype(np.float32) for r in render)
    depth_b = render[1]["depth"]
    v, u = np.nonzero((render[1]["label"] == textures.ROAD) & (depth_b > 4) & (depth_b < 25))
    pts_b = geometry.backproject(cam.K, np.stack([u, v], 1).astype(float), depth_b[v, u])
    pts_a = geometry.transform_points(np.linalg.inv(T_a) @ T_b, pts_b)
    uv_a, _ = geometry.project(cam.K, pts_a)
    inside = (uv_a[:, 0] > 1) & (uv_a[:, 0] < 318) & (uv_a[:, 1] > 1) & (uv_a[:, 1] < 158)
    assert inside.sum() > 2000
    ua, va = uv_a[inside, 0].astype(np.float32)[None], uv_a[inside, 1].astype(np.float32)[None]
    vi, ui = v[inside], u[inside]
    # geometry: the depth buffer of A, sampled where B's road points project, equals their depth in A
    depth_a = cv2.remap(render[0]["depth"], ua, va, cv2.INTER_NEAREST)[0]
    assert np.median(np.abs(depth_a - pts_a[inside, 2]) / pts_a[inside, 2]) < 0.01
    # photometry: B's road pixels match A warped onto them far better than unwarped, and than their spread
    warped = cv2.remap(a, ua, va, cv2.INTER_LINEAR)[0]
    diff = np.abs(warped - b[vi, ui]).mean()
    unwarped = np.abs(a[vi, ui] - b[vi, ui]).mean()
    spread = b[vi, ui].std()
    assert spread > 8.0                 # the road is textured at this resolution
    assert diff < 0.35 * unwarped and diff < 0.2 * spread


def test_texture_is_a_pure_function_of_position(cfg):
    view = flat_view(cfg)
    p = np.array([[3.0, -1.0, 0.0], [12.5, 1.7, 0.0], [40.0, 0.05, 0.0]])
    part = np.full(3, PART_ROAD, np.int8)
    fp = np.full(3, 0.01)
    a = textures.ground(p, part, view.style, fp)
    b = textures.ground(p[::-1].copy(), part, view.style, fp[::-1].copy())
    assert np.array_equal(a.albedo, b.albedo[::-1]) and np.ptp(a.albedo[:, 0]) > 0


# ------------------------------------------------------------------------------------- LiDAR and glass
def _car_scene(cfg, p_pass):
    size = np.array([[3.9, 1.6, 1.5]])
    cars = car_table(size)
    view = flat_view(cfg, cars=cars)
    car = car_prims([[9.0, 0.0, 0.0]], np.eye(3)[None], size, np.array([0]))
    wall = Prims.boxes([[22.0, 0.0, 3.0]], np.eye(3)[None], [[1.0, 8.0, 3.0]], KIND_BUILDING, 0)
    prims = Prims.concat([car, wall])
    lidar_cfg = dict(cfg["world"]["lidar"], glass_pass_prob=p_pass, dropout=0.0, range_noise=0.0)
    lidar = Lidar("lidar_top", np.radians(np.linspace(2.0, -24.8, 64)), 2048, 120.0, np.eye(4))
    out = sweep(lidar, pose(np.eye(3), [0.0, 0.0, 1.73]), prims, view, lidar_cfg, derive_rng(4))
    _, _, cab_off, cab_half = car_parts(size)
    shrink = 0.02  # stay clear of grazing rays at the cabin's edges
    lo = np.array([9.0, 0.0, 0.0]) + cab_off[0] - cab_half[0] + shrink - np.array([0, 0, 1.73])
    hi = np.array([9.0, 0.0, 0.0]) + cab_off[0] + cab_half[0] - shrink - np.array([0, 0, 1.73])
    xyz = out["points"][:, :3].astype(np.float64)
    rng_ = np.linalg.norm(xyz, axis=1)
    d = xyz / rng_[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = lo / d, hi / d
    t_in = np.minimum(t1, t2).max(axis=1)
    t_out = np.maximum(t1, t2).min(axis=1)
    through_cabin = (t_in < t_out) & (t_in > 0)
    behind = through_cabin & (rng_ > t_out + 0.05)
    return out, behind, through_cabin


def test_glass_pass_probability_zero_and_one(cfg):
    out0, behind0, through0 = _car_scene(cfg, 0.0)
    assert through0.sum() > 50 and behind0.sum() == 0 and not out0["passed"].any()
    out1, behind1, _ = _car_scene(cfg, 1.0)
    assert behind1.sum() > 20 and out1["passed"].any()
    on_wall = behind1 & (out1["points"][:, 0] > 20.9)  # through both panes, onto the wall behind
    assert on_wall.sum() > 10 and np.all(out1["instance"][on_wall] == 0)
    assert (out0["points"][:, 3] >= 0).all() and (out0["points"][:, 3] <= 1).all()


def test_lidar_points_lie_on_rendered_surfaces(scene):
    folder, _ = scene
    K, (w, h) = sceneio.read_intrinsics(folder / "cam_front.txt")
    extr = sceneio.read_extrinsics(folder / "extrinsics.json")
    errors = []
    for i in range(3):
        pts = sceneio.read_lidar(folder / "lidar_top" / f"{i:06d}.bin")
        T_cl = np.linalg.inv(extr["cam_front"]) @ extr["lidar_top"]
        cam_pts = geometry.transform_points(T_cl, pts[:, :3].astype(np.float64))
        sparse = geometry.sparse_depth_map(cam_pts, K, w, h, (0.1, 80.0))
        depth = sceneio.read_depth_png(folder / "gt" / "depth" / "cam_front" / f"{i:06d}.png")
        valid = (sparse > 0) & (depth > 0)
        assert valid.sum() > 300
        errors.append(np.abs(sparse[valid] - depth[valid]) / depth[valid])
    err = np.concatenate(errors)
    assert np.median(err) < 0.01 and np.mean(err < 0.05) > 0.9


# ------------------------------------------------------------------------------------------ ground truth
def test_occlusion_truncation_and_visible_pixels(cfg):
    sizes = np.array([[3.9, 1.6, 1.5], [3.9, 1.6, 1.5], [3.9, 1.6, 1.5]])
    cars = car_table(sizes)
    view = flat_view(cfg, cars=cars)
    pos = np.array([[10.0, 0.0, 0.0], [18.0, 1.0, 0.0], [6.0, 3.5, 0.0]])  # ahead, behind it, beside
    rot = np.repeat(np.eye(3)[None], 3, 0)
    prims = car_prims(pos, rot, sizes, np.arange(3))
    cam = Camera("cam_front", intrinsics(200, 100, 81.0), 200, 100, pose(R_VEHICLE_FRONT, [1.6, 0.0, 1.65]))
    T_wv = np.eye(4)
    T_wc = T_wv @ cam.T_vehicle_sensor
    out = render_camera(cam, T_wc, prims, view, cfg["world"]["domains"]["kitti_like"]["appearance"], 0.0,
                        200.0, 350.0, derive_rng(0))
    own = own_pixels(out["pairs"], prims, 3)
    rows = frame_rows(0, pos, rot, np.zeros((3, 3)), cars, T_wv, cam, T_wc, out["instance"], own,
                      np.zeros(4, int), cfg["world"]["gt"])
    df = pd.DataFrame(rows, columns=sceneio.BOX_COLUMNS).set_index("track_id")
    assert df.loc[1, "occlusion"] == 0 and df.loc[1, "truncation"] == 0.0
    assert df.loc[2, "occlusion"] in (1, 2) and df.loc[2, "visible_px"] < own[1]
    assert df.loc[3, "truncation"] > 0.2
    for tid in (1, 2):
        v, u = np.nonzero(out["instance"] == tid)
        assert df.loc[tid, "visible_px"] == len(v)
        tight = [u.min() - 0.5, v.min() - 0.5, u.max() + 0.5, v.max() + 0.5]
        assert df.loc[tid, ["x1", "y1", "x2", "y2"]].tolist() == tight
    assert df.loc[1, ["x", "y", "z"]].tolist() == pytest.approx([10.0, 0.0, 0.75], abs=1e-3)  # box centre


def test_ego_motion_stops_pitch_and_pose_on_road(cfg):
    t, v, a, s = speed_profile(derive_rng(1), 60.0, (5.0, 15.0), 0.5, (1.0, 4.0), (2.0, 5.0), 2.5, False)
    assert (v == 0).any() and v.max() > 5.0 and np.abs(a).max() <= 2.5 + 1e-6
    assert np.all(np.diff(s) >= 0)
    ego_cfg = dict(cfg["world"]["ego"], body_noise=0.0)
    view = flat_view(cfg, grade=(0.04, -0.02), camber=0.01)
    ego = make_ego(derive_rng(2), ego_cfg, view.road, 50, 10.0, -1.75, stationary=False)
    assert np.allclose(ego.pitch, ego_cfg["pitch_per_accel"] * ego.a)
    origin = ego.poses[:, :3, 3]
    assert np.allclose(origin[:, 2], view.road.height(origin[:, 0], origin[:, 1]))
    still = make_ego(derive_rng(3), cfg["world"]["ego"], view.road, 10, 10.0, -1.75, stationary=True)
    assert np.allclose(still.poses, still.poses[0]) and (still.v == 0).all()


# ---------------------------------------------------------------------------------- the written scene
def test_scene_folder_matches_the_format(scene, cfg):
    folder, summary = scene
    meta = sceneio.read_meta(folder)
    dom = cfg["world"]["domains"]["lyft_like"]
    assert meta["cameras"] == dom["cameras"] == ["cam_front", "cam_back"] and meta["lidars"] == ["lidar_top"]
    assert meta["n_frames"] == 3 and meta["split"] == "train" and meta["domain"] == "lyft_like"
    assert meta["fps"] == cfg["world"]["fps"] and meta["seed"] == 11 and meta["scene"] == "train_000"
    n = meta["n_frames"]
    for cam in meta["cameras"]:
        K, (w, h) = sceneio.read_intrinsics(folder / f"{cam}.txt")
        assert (w, h) == (192, 96)
        for i, path in enumerate(sceneio.sensor_frames(folder, cam, "png", n)):
            rgb = sceneio.read_image(path)
            assert rgb.shape == (h, w, 3) and rgb.dtype == np.uint8 and rgb.std() > 10
            inst = sceneio.read_label_png(folder / "gt" / "instance" / cam / path.name)
            sem = sceneio.read_label_png(folder / "gt" / "semantic" / cam / path.name)
            depth = sceneio.read_label_png(folder / "gt" / "depth" / cam / path.name)
            assert inst.dtype == np.uint16 and sem.dtype == np.uint8 and depth.dtype == np.uint16
            assert inst.shape == sem.shape == depth.shape == (h, w)
            assert set(np.unique(sem)) <= LABELS
            assert np.array_equal(depth == 0, sem == textures.SKY)  # every surface is nearer than 256 m
            assert np.all(sem[inst > 0] == textures.CAR)
    for path in sceneio.sensor_frames(folder, "lidar_top", "bin", n):
        raw = path.read_bytes()
        assert len(raw) % 16 == 0 and len(raw) > 16 * 10000
        pts = np.frombuffer(raw, "<f4").reshape(-1, 4)
        assert np.isfinite(pts).all() and np.linalg.norm(pts[:, :3], axis=1).max() < 120.5
    extr = sceneio.read_extrinsics(folder / "extrinsics.json")
    assert set(extr) == {"cam_front", "cam_back", "lidar_top"}
    assert extr["cam_front"][2, 3] == pytest.approx(dom["camera_height"])
    assert extr["cam_back"][:3, 2] == pytest.approx([-1, 0, 0])  # cam_back looks backwards
    poses = sceneio.read_poses(folder / "ego_poses.txt")
    assert poses.shape == (n, 4, 4)
    for T in poses:
        assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-6)
    boxes = sceneio.read_boxes(folder / "gt" / "boxes.csv")
    assert list(boxes.columns) == sceneio.BOX_COLUMNS and len(boxes) > 0
    assert set(boxes["frame"]) <= set(range(n)) and boxes["occlusion"].isin([0, 1, 2, 3]).all()
    assert boxes["truncation"].between(0, 1).all() and (boxes["cls"] == "Car").all()
    seen = boxes[boxes["visible_px"] > 0]
    assert len(seen) > 0 and (seen["x2"] > seen["x1"]).all() and (seen["y2"] > seen["y1"]).all()
    assert boxes[boxes["visible_px"] == 0][["x1", "y1", "x2", "y2"]].isna().all().all()
    inst0 = sceneio.read_label_png(folder / "gt" / "instance" / "cam_front" / "000000.png")
    for _, row in boxes[boxes["frame"] == 0].iterrows():
        assert row["visible_px"] == int((inst0 == row["track_id"]).sum())
    assert boxes["l"].between(2.0, 6.0).all() and boxes["l"].std() > 0.15 and boxes["n_lidar"].sum() > 0
    assert summary["frames"] == n and summary["lidar_points_per_sweep"] > 10000
    assert not any(p.name.startswith(".") for p in folder.parent.iterdir())  # no temporary folder left


def test_generation_is_deterministic(scene, cfg, tmp_path):
    folder, _ = scene
    again = tmp_path / "train_000"
    write_scene(cfg["world"], "world_kitti", "lyft_like", "train", 0, 11, again)
    files = sorted(p.relative_to(folder) for p in folder.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(again) for p in again.rglob("*") if p.is_file())
    for rel in files:
        assert (folder / rel).read_bytes() == (again / rel).read_bytes(), rel
    other = tmp_path / "train_001"
    write_scene(cfg["world"], "world_kitti", "lyft_like", "train", 1, 11, other)
    assert (other / "cam_front" / "000000.png").read_bytes() != (folder / "cam_front" / "000000.png").read_bytes()


def test_misspelled_world_key_is_named():
    with pytest.raises(config.ConfigError, match="beamz"):
        config.load(ROOT / "config.yaml", {"world": {"lidar": {"beamz": 64}}})
    with pytest.raises(config.ConfigError, match="velocity_scal"):
        config.load(ROOT / "config.yaml", {"velocity_clips": {"splits": {"test": {"velocity_scal": 2.0}}}})


def test_bad_arguments_are_named(cfg, tmp_path):
    with pytest.raises(ValueError, match="split"):
        write_scene(cfg["world"], "d", "kitti_like", "validation", 0, 1, tmp_path / "x")
    with pytest.raises(ValueError, match="mars_like"):
        write_scene(cfg["world"], "d", "mars_like", "train", 0, 1, tmp_path / "x")
    assert not any(tmp_path.iterdir())


# ------------------------------------------------------------------------------------- velocity clips
def test_clips_have_40_frames_and_pinhole_consistent_annotations(cfg, tmp_path):
    world = copy.deepcopy(cfg["world"])
    world["road"]["camber_sigma"] = 0.0
    world["ego"].update(pitch_per_accel=0.0, roll_per_lateral_accel=0.0, body_noise=0.0)
    clips = copy.deepcopy(cfg["velocity_clips"])
    clips.update(grade_max=0.0, grade_sigma=0.0, max_distance=45.0, width=320, height=180)
    clips["traffic"].update(lateral_sigma=0.0, lane_change_prob=0.0)
    clips["splits"]["train"] = {"clips": 3, "velocity_scale": 1.0}
    summary = write_clips(world, clips, "train", 5, tmp_path / "train")
    root = tmp_path / "train"
    fx, fy, cx, cy = (float(v) for v in (root / "calibration.txt").read_text().split("\n")[0].split())
    height = float((root / "calibration.txt").read_text().split("\n")[1])
    assert height == clips["camera_height"] and fx == pytest.approx(fy)
    n_ann = 0
    for k in range(1, 4):
        frames = sorted((root / "clips" / str(k) / "imgs").glob("*.jpg"))      # the tiny profile's: foveated JPEG
        assert [p.name for p in frames] == [f"{i:03d}.jpg" for i in range(1, 41)]
        assert cv2.imread(str(frames[0])).shape == (180, 320, 3)
        for ann in json.loads((root / "clips" / str(k) / "annotation.json").read_text()):
            n_ann += 1
            assert set(ann) == {"bbox", "velocity", "position", "track_id"}
            b, (z, x) = ann["bbox"], ann["position"]
            assert b["bottom"] == pytest.approx(cy + fy * height / z, abs=1.0)   # eq. (1) of McCraith ch.3
            assert b["left"] - 1 <= cx + fx * x / z <= b["right"] + 1
            assert np.hypot(*ann["velocity"]) < 8.0
    assert n_ann >= 2 and summary["annotated"] == n_ann


def test_fine_camera_grid_by_hand(cfg):
    """k = 2: f doubles and pixel (u, v) covers fine pixels 2u, 2u + 1: the fine pixel 2u looks where the camera
    shifted by a quarter pixel (c + 0.25) puts pixel u, so their ray-cast depth buffers agree ray for ray."""
    K = np.array([[2.0, 0.0, 1.5], [0.0, 2.0, 0.5], [0.0, 0.0, 1.0]])
    cam = Camera("c", K, 4, 2, np.eye(4))
    fine = fine_camera(cam, 2)
    assert (fine.width, fine.height) == (8, 4) and fine_camera(cam, 1) is cam
    assert np.allclose(fine.K, [[4.0, 0.0, 3.5], [0.0, 4.0, 1.5], [0.0, 0.0, 1.0]])
    p = np.array([0.3, -0.2, 1.0])                     # a camera-frame point: u = 2.1, v = 0.1 on cam
    u, v = (K @ p)[:2]
    uf, vf = (fine.K @ p)[:2]
    assert (uf, vf) == pytest.approx(((u + 0.5) * 2 - 0.5, (v + 0.5) * 2 - 0.5))
    w, h = 48, 24
    size = np.array([[3.9, 1.6, 1.5]])
    view = flat_view(cfg, cars=car_table(size))
    prims = car_prims([[9.0, 0.5, 0.0]], np.eye(3)[None], size, np.array([0]))
    base = Camera("cam_front", intrinsics(w, h, 80.0), w, h, pose(R_VEHICLE_FRONT, [0.0, 0.0, 1.6]))
    shifted = Camera("cam_front", base.K + np.array([[0, 0, 0.25], [0, 0, 0.25], [0, 0, 0]]), w, h,
                     base.T_vehicle_sensor)
    T_wc = base.T_vehicle_sensor
    fine_hits = cast(fine_camera(base, 2), T_wc, prims, view.road, 100.0)[0]
    shifted_hits = cast(shifted, T_wc, prims, view.road, 100.0)[0]
    assert np.array_equal(fine_hits.t.reshape(2 * h, 2 * w)[0::2, 0::2], shifted_hits.t.reshape(h, w))
    assert np.array_equal(fine_hits.prim.reshape(2 * h, 2 * w)[0::2, 0::2], shifted_hits.prim.reshape(h, w))


def test_supersampled_clip_pixels_integrate_their_area(cfg, tmp_path):
    """supersample 2: the image keeps the camera's size and the calibration, a pixel is the mean of its four
    rays in linear colour (noise off, gamma 1 identity look: the 2 x 2 block mean of the fine render), and the
    annotated boxes lie on the half-pixel grid (sub-pixel), still consistent with eq. (1)."""
    world = copy.deepcopy(cfg["world"])
    clips = copy.deepcopy(cfg["velocity_clips"])
    clips.update(width=160, height=90, frames=2, supersample=2, foveate={"factor": 1, "margin_px": 0, "tile_px": 1},
                 image_format="png")
    clips["splits"]["train"] = {"clips": 2, "velocity_scale": 1.0}
    write_clips(world, clips, "train", 5, tmp_path / "ss")
    plain = dict(clips, supersample=1)
    write_clips(world, plain, "train", 5, tmp_path / "plain")
    cal = [(p / "calibration.txt").read_text() for p in (tmp_path / "ss", tmp_path / "plain")]
    assert cal[0] == cal[1]
    fx, fy, cx, cy = (float(v) for v in cal[0].split("\n")[0].split())
    height = float(cal[0].split("\n")[1])
    img = cv2.imread(str(tmp_path / "ss" / "clips" / "1" / "imgs" / "002.png"))
    assert img.shape == (90, 160, 3)
    boxes = []
    for k in (1, 2):
        for ann in json.loads((tmp_path / "ss" / "clips" / str(k) / "annotation.json").read_text()):
            b, (z, _) = ann["bbox"], ann["position"]
            boxes += [b["left"], b["top"], b["right"], b["bottom"]]
            assert b["bottom"] == pytest.approx(cy + fy * height / z, abs=1.0)
    halves = np.asarray(boxes) * 2
    assert len(boxes) >= 4 and np.allclose(halves, np.round(halves))
    assert not np.allclose(np.asarray(boxes) + 0.5, np.round(np.asarray(boxes) + 0.5))   # some off the pixel grid


def test_supersample_averages_linear_colour(cfg):
    """render_camera(k = 2) = the domain look of the 2 x 2 block means of the fine grid's linear colour."""
    from redsup.world.shade import finish, radiance

    size = np.array([[3.9, 1.6, 1.5]])
    view = flat_view(cfg, cars=car_table(size))
    prims = car_prims([[9.0, 0.5, 0.0]], np.eye(3)[None], size, np.array([0]))
    w, h = 32, 16
    cam = Camera("cam_front", intrinsics(w, h, 80.0), w, h, pose(R_VEHICLE_FRONT, [0.0, 0.0, 1.6]))
    look = cfg["world"]["domains"]["kitti_like"]["appearance"]
    T = cam.T_vehicle_sensor
    out = render_camera(cam, T, prims, view, look, 0.0, 100.0, 500.0, derive_rng(1), supersample=2)
    lin = radiance(fine_camera(cam, 2), T, prims, view, look, 100.0, 500.0)["linear"]
    block = lin.reshape(h, 2, w, 2, 3).mean(axis=(1, 3)).reshape(-1, 3)
    assert out["rgb"].shape == (h, w, 3) and out["instance"].shape == (2 * h, 2 * w)
    assert np.array_equal(out["rgb"], finish(block, look, 0.0, derive_rng(1)).reshape(h, w, 3))
    edge = (out["instance"].reshape(h, 2, w, 2) > 0).mean(axis=(1, 3))
    assert ((edge > 0) & (edge < 1)).any()          # pixels the car covers in part: their grey is a mix


def test_abnormal_velocity_scale(cfg):
    world, clips = cfg["world"], cfg["velocity_clips"]
    dom = world["domains"][clips["domain"]]
    spread = {}
    for scale in (1.0, 3.0):
        rel = []
        for c in range(30):
            mw = build_motorway(world, clips, dom, derive_rng(9, c), scale)
            rel.extend(mw.cars["vel"][mw.target, 0] - mw.ego.v[-1])
        spread[scale] = np.sqrt(np.mean(np.square(rel)))
    assert spread[3.0] == pytest.approx(3.0 * spread[1.0], rel=0.25)   # the traffic model's dv, scaled


def test_true_distances_end_at_the_annotated_position(cfg, tmp_path):
    """The diagnostic per-frame distances rebuild the clip's motorway from its seed: in the last frame they equal
    the annotated z of every vehicle (annotations keep 4 decimals), and they span the clip's frames."""
    from redsup.world.clips import true_distances

    world = copy.deepcopy(cfg["world"])
    clips = copy.deepcopy(cfg["velocity_clips"])
    clips.update(width=160, height=90, frames=3, supersample=1)
    clips["splits"]["val"] = {"clips": 2, "velocity_scale": 1.0}
    write_clips(world, clips, "val", 5, tmp_path / "c")
    n = 0
    for c in (1, 2):
        ann = json.loads((tmp_path / "c" / "clips" / str(c) / "annotation.json").read_text())
        z = true_distances(world, clips, "val", 5, c, [a["track_id"] for a in ann])
        assert z.shape == (len(ann), 3)
        assert np.allclose(z[:, -1], [a["position"][0] for a in ann], atol=1e-3)
        n += len(ann)
    assert n >= 2


def _files(root: Path) -> list[Path]:
    """Every file below root but Snakemake's marker in a directory output."""
    return sorted(p.relative_to(root) for p in root.rglob("*") if p.is_file() and p.name != ".snakemake_timestamp")


def _same_files(a: Path, b: Path) -> int:
    """Asserts that folders a and b hold the same files, byte for byte; returns how many."""
    files = _files(a)
    assert _files(b) == files
    for f in files:
        assert (a / f).read_bytes() == (b / f).read_bytes(), f
    return len(files)


def _small_clips(cfg, n=3):
    world = copy.deepcopy(cfg["world"])
    clips = copy.deepcopy(cfg["velocity_clips"])
    clips.update(width=96, height=54, frames=3)
    clips["splits"]["train"] = {"clips": n, "velocity_scale": 1.0}
    return world, clips


def test_clip_shard_names():
    """Shards are consecutive clips named by their first and last (1-based); the last shard takes the rest."""
    assert shards.ranges(6, 3) == [range(0, 3), range(3, 6)]
    assert shards.names(4, 3) == ["001-003", "004-004"] and shards.names(3, 25) == ["001-003"]
    assert shards.names(0, 3) == []
    assert [shards.clips_of(n) for n in shards.names(7, 2)] == shards.ranges(7, 2)
    for bad in ("3-1", "0-2", "x-2", "001"):
        with pytest.raises(ValueError, match="not <first>-<last>"):
            shards.clips_of(bad)
    with pytest.raises(ValueError, match="at least 1"):
        shards.ranges(5, 0)


def test_sharded_split_is_byte_identical_to_one_job(cfg, tmp_path):
    """A split rendered in shards of 1 and of 2 clips (2: an uneven last shard) and merged holds the same files,
    byte for byte, as the split rendered in one job, and the same summary: each clip's randomness is the clip's
    (seed, split, clip), not its shard's."""
    world, clips = _small_clips(cfg)
    whole = write_clips(world, clips, "train", 5, tmp_path / "whole")
    assert not list(tmp_path.glob(".whole*"))               # the one-job shard is gone
    for size in (1, 2):
        folders = []
        for r in shards.ranges(3, size):
            folders.append(tmp_path / f"size{size}" / shards.name(r))
            render_shard(world, clips, "train", 5, r, folders[-1])
        merged = merge_shards(world, dict(clips, shard_size=size), "train", 5, folders, tmp_path / f"split{size}")
        assert _same_files(tmp_path / "whole", tmp_path / f"split{size}") == 1 + 3 * (3 + 1)
        assert merged == {k: v for k, v in whole.items() if k not in ("workers", "seconds")} | {"shards": len(folders)}
        assert sorted(p.name for p in (tmp_path / f"size{size}").iterdir()) == sorted(f.name for f in folders)


def test_a_failed_shard_leaves_no_output(cfg, tmp_path, monkeypatch):
    """A shard that fails at its second clip leaves no folder and no temporary one; what a killed attempt left
    (its temporary folder) is removed by the next attempt, whose clips are those of an uninterrupted render."""
    import redsup.world.clips as clips_mod

    world, clips = _small_clips(cfg)
    write_clips(world, clips, "train", 5, tmp_path / "whole")
    real = clips_mod.render_clip

    def flaky(world_cfg, clips_cfg, split, seed, c, folder):
        if c == 2:
            (folder / "imgs").mkdir(parents=True)           # cut off mid-clip
            raise RuntimeError("killed")
        return real(world_cfg, clips_cfg, split, seed, c, folder)

    monkeypatch.setattr(clips_mod, "render_clip", flaky)
    out = tmp_path / "shards" / "002-003"
    with pytest.raises(RuntimeError, match="killed"):
        render_shard(world, clips, "train", 5, range(1, 3), out)
    assert not any((tmp_path / "shards").iterdir())
    monkeypatch.setattr(clips_mod, "render_clip", real)
    (tmp_path / "shards" / ".002-003.tmp999999" / "clips").mkdir(parents=True)   # a SIGKILLed attempt's
    summary = render_shard(world, clips, "train", 5, range(1, 3), out)
    assert sorted(p.name for p in (tmp_path / "shards").iterdir()) == ["002-003"]
    assert sorted(p.name for p in (out / "clips").iterdir()) == ["2", "3"] and summary["clips"] == 2
    for c in ("2", "3"):
        _same_files(tmp_path / "whole" / "clips" / c, out / "clips" / c)


def test_merge_takes_only_complete_current_shards(cfg, tmp_path):
    """The merge refuses shards rendered under another key (settings, renderer, numpy / OpenCV) and shards that do
    not hold every clip once, before it writes anything; clips out of the split are refused before rendering."""
    world, clips = _small_clips(cfg)
    first, second = tmp_path / "001-002", tmp_path / "003-003"
    render_shard(world, clips, "train", 5, range(0, 2), first)
    render_shard(world, clips, "train", 5, range(2, 3), second)
    with pytest.raises(ValueError, match="do not hold clips 1 to 3"):
        merge_shards(world, clips, "train", 5, [first], tmp_path / "train")
    with pytest.raises(ValueError, match="do not hold clips 1 to 3"):
        merge_shards(world, clips, "train", 5, [first, second, first], tmp_path / "train")
    (second / "key.txt").write_text("another renderer\n")
    with pytest.raises(ValueError, match="forcerun world_clips_shard"):
        merge_shards(world, clips, "train", 5, [first, second], tmp_path / "train")
    with pytest.raises(ValueError, match="not consecutive clips"):
        render_shard(world, clips, "train", 5, range(2, 4), tmp_path / "003-004")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["001-002", "003-003"]


@pytest.mark.workflow
def test_workflow_clip_split_is_the_one_job_render(tiny, tmp_path):
    """The tiny build renders its test split (4 clips) in two shards (3 + 1, velocity_clips.shard_size 3), merged
    by world_clips, and removes the shards: the split's files are byte for byte those of one job for the split."""
    c = config.load(ROOT / "config.yaml", {"profile": "tiny"})
    assert c["velocity_clips"]["shard_size"] == 3 and c["velocity_clips"]["splits"]["test"]["clips"] == 4
    bench = tiny / "results" / "benchmarks" / "world_clips_shard" / "raw" / "clip_shards" / "test"
    assert sorted(p.name for p in bench.iterdir()) == ["001-003.tsv", "004-004.tsv"]
    assert not (tiny / "results" / "raw" / "clip_shards" / "test").exists()      # temp(): gone after the merge
    write_clips(c["world"], c["velocity_clips"], "test", c["seed"], tmp_path / "test")
    assert _same_files(tmp_path / "test", tiny / "results" / "raw" / "clips" / "test") == 1 + 4 * 41


def test_clips_render_the_same_files_in_parallel(cfg, tmp_path):
    """Clips depend only on (seed, split, clip): two worker processes write byte-identical clips to one process,
    and the same summary counts (the rule's threads are the workers: a cluster renders a split in parallel)."""
    world = copy.deepcopy(cfg["world"])
    clips = copy.deepcopy(cfg["velocity_clips"])
    clips.update(width=96, height=54, frames=3)
    clips["splits"]["train"] = {"clips": 3, "velocity_scale": 1.0}
    one = write_clips(world, clips, "train", 5, tmp_path / "one")
    two = write_clips(world, clips, "train", 5, tmp_path / "two", workers=2)
    files = sorted(p.relative_to(tmp_path / "one") for p in (tmp_path / "one").rglob("*") if p.is_file())
    assert len(files) == 1 + 3 * (3 + 1)                    # calibration + per clip 3 frames and the annotation
    for f in files:
        assert (tmp_path / "one" / f).read_bytes() == (tmp_path / "two" / f).read_bytes(), f
    assert sorted(p.relative_to(tmp_path / "two") for p in (tmp_path / "two").rglob("*") if p.is_file()) == files
    assert {k: one[k] for k in ("annotated", "near", "medium", "far")} == \
        {k: two[k] for k in ("annotated", "near", "medium", "far")} and two["workers"] == 2


def test_finish_is_the_written_out_domain_look():
    """shade.finish (in place) against the look written out step by step: bit-identical, with gamma and noise."""
    from redsup.world.shade import finish

    look = {"brightness": 1.1, "tint": [1.0, 0.95, 0.9], "saturation": 0.8, "contrast": 1.2, "gamma": 1.3}
    col = derive_rng(4).random((500, 3), dtype=np.float32)
    ref = col * (np.float32(1.1) * np.asarray(look["tint"], np.float32))
    lum = np.einsum("ni,i->n", ref, np.array([0.299, 0.587, 0.114], np.float32))
    ref = lum[:, None] + (ref - lum[:, None]) * np.float32(0.8)
    ref = np.clip((ref - np.float32(0.45)) * np.float32(1.2) + np.float32(0.45), 0.0, 1.0) ** np.float32(1 / 1.3)
    ref = ref + np.float32(0.03) * derive_rng(5).standard_normal(ref.shape, dtype=np.float32)
    ref = np.clip(np.round(ref * 255.0), 0, 255).astype(np.uint8)
    before = col.copy()
    assert np.array_equal(finish(col, look, 0.03, derive_rng(5)), ref)
    assert np.array_equal(col, before)                   # the input is not modified
    # a hand case: grey 0.5, identity look, no noise -> round(127.5) = 128 (half to even)
    grey = np.full((1, 3), 0.5, np.float32)
    ident = {"brightness": 1.0, "tint": [1.0, 1.0, 1.0], "saturation": 1.0, "contrast": 1.0, "gamma": 1.0}
    assert finish(grey, ident, 0.0, derive_rng(1)).tolist() == [[128, 128, 128]]
