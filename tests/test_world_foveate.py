"""Foveated clip rendering (redsup.world.foveate): the cars' windows are the full render's pixels."""
from __future__ import annotations

import copy
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from redsup import config
from redsup.world.clips import annotate, clip_camera, clip_motorway, write_clips
from redsup.world.common import derive_rng, pose
from redsup.world.foveate import (car_sampling, car_windows, coarse_camera, crop_camera, merge_rects,
                                  radiance_foveated, render_foveated, snap_rect)
from redsup.world.gt import own_pixels
from redsup.world.motorway import motorway_state
from redsup.world.prims import car_prims
from redsup.world.sensors import R_VEHICLE_FRONT, Camera, fine_camera, intrinsics
from redsup.world.shade import SceneView, radiance, render_camera
from redsup.world.textures import SKY

from test_world import car_table, flat_view

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def cfg():
    return config.load(ROOT / "config.yaml", {"profile": "tiny"})


def test_crop_camera_casts_the_full_grids_rays(cfg):
    """Pixel (u, v) of the crop [r0, r1) x [c0, c1) is pixel (c0 + u, r0 + v) of the full camera: the same hit,
    depth, label and instance, and the same colour wherever a surface is hit (the sky is interpolated on a grid
    anchored at the image's corner: its clouds may differ by the interpolation)."""
    size = np.array([[3.9, 1.6, 1.5]])
    view = flat_view(cfg, cars=car_table(size))
    prims = car_prims([[12.0, 0.8, 0.0]], np.eye(3)[None], size, np.array([0]))
    w, h = 64, 32
    cam = Camera("cam_front", intrinsics(w, h, 80.0), w, h, pose(R_VEHICLE_FRONT, [0.0, 0.0, 1.6]))
    crop = crop_camera(cam, 9, 27, 21, 50)
    assert (crop.width, crop.height) == (29, 18)
    assert crop.K[0, 2] == pytest.approx(cam.K[0, 2] - 21) and crop.K[1, 2] == pytest.approx(cam.K[1, 2] - 9)
    look = cfg["world"]["domains"]["kitti_like"]["appearance"]
    T = cam.T_vehicle_sensor
    full = radiance(cam, T, prims, view, look, 100.0, 500.0)
    part = radiance(crop, T, prims, view, look, 100.0, 500.0)
    for k in ("label", "instance", "depth"):
        assert np.array_equal(part[k], full[k][9:27, 21:50]), k
    assert (part["instance"] > 0).sum() > 20                  # the car is in the crop
    lin_full = full["linear"].reshape(h, w, 3)[9:27, 21:50]
    lin_part = part["linear"].reshape(18, 29, 3)
    hit = part["label"] != SKY
    assert np.allclose(lin_part[hit], lin_full[hit], atol=1e-6)
    assert np.mean(np.abs(lin_part[~hit] - lin_full[~hit])) < 0.1


def test_coarse_camera_by_hand():
    """factor 2 on a 4 x 2 camera with f 2, c (1.5, 0.5): 2 x 1 pixels, f 1, c ((1.5 + 0.5) / 2 - 0.5, 0)."""
    cam = Camera("c", np.array([[2.0, 0.0, 1.5], [0.0, 2.0, 0.5], [0.0, 0.0, 1.0]]), 4, 2, np.eye(4))
    c = coarse_camera(cam, 2)
    assert (c.width, c.height) == (2, 1)
    assert np.allclose(c.K, [[1.0, 0.0, 0.5], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    with pytest.raises(ValueError, match="divide"):
        coarse_camera(cam, 3)


def test_merge_rects_by_hand():
    """Overlapping rectangles become their bounding rectangle, also through a chain; touching ones stay apart."""
    assert merge_rects([(0, 2, 0, 2), (1, 3, 1, 3), (5, 6, 5, 6)]) == [(0, 3, 0, 3), (5, 6, 5, 6)]
    # (0,2,0,2) and (3,5,3,5) are apart, but (1,4,1,4) overlaps both: one rectangle
    assert merge_rects([(0, 2, 0, 2), (3, 5, 3, 5), (1, 4, 1, 4)]) == [(0, 5, 0, 5)]
    assert merge_rects([(0, 2, 0, 2), (2, 4, 0, 2)]) == [(0, 2, 0, 2), (2, 4, 0, 2)]
    assert merge_rects([(3, 3, 0, 5)]) == []                # empty
    # extra integers after the bounds: a merged rectangle keeps their maximum, an unmerged one its own
    assert merge_rects([(0, 2, 0, 2, 3), (1, 3, 1, 3, 2), (5, 6, 5, 6, 1)]) == [(0, 3, 0, 3, 3), (5, 6, 5, 6, 1)]


def _two_cars(cfg):
    """A 320 x 180 camera 1.8 m above a flat road, a car 1.6 m wide 10 m ahead and one 40 m ahead, 8 m left."""
    size = np.array([[3.9, 1.6, 1.5], [3.9, 1.6, 1.5]])
    view = flat_view(cfg, cars=car_table(size))
    prims = car_prims([[10.0 + 1.95, 0.0, 0.0], [40.0 + 1.95, 8.0, 0.0]], np.stack([np.eye(3)] * 2), size,
                      np.array([0, 1]))
    cam = Camera("cam_front", intrinsics(320, 180, 83.7), 320, 180, pose(R_VEHICLE_FRONT, [0.0, 0.0, 1.8]))
    return view, prims, cam


def test_car_sampling_by_hand(cfg):
    """f = 160 / tan(41.85 deg) = 178.6 px: the near car's rear, 1.6 m wide at 10 m, is 28.6 px wide, the far one's
    7.1 px at 40 m, plus the side it shows and the pixel rectangle's padding (``Camera.rects``: floor(u_lo - 0.5) to floor(u_hi + 0.5) + 2, up to 4 px).
    rays_across 64: k = ceil(64 / the width), so the near car (32 px) gets 2 and the far one (13 px) 5, at most
    max_rays; with rays_across 24 the near car needs one ray a pixel and is left out."""
    view, prims, cam = _two_cars(cfg)
    T = cam.T_vehicle_sensor
    f = cam.K[0, 0]
    assert f == pytest.approx(160 / np.tan(np.radians(83.7 / 2)))
    rects = car_sampling(cam, T, prims, 100.0, 64, 8)
    assert len(rects) == 2
    far, near = sorted(rects, key=lambda r: r[3] - r[2])
    assert 1.6 * f / 10 <= near[3] - near[2] <= 1.6 * f / 10 + 4      # straight ahead: the rear face only
    assert 1.6 * f / 40 <= far[3] - far[2] <= 1.6 * f / 40 + 0.2 * 3.9 * f / 40 + 4   # and a little of its side
    assert near[4] == -(-64 // (near[3] - near[2])) == 2
    assert far[4] == -(-64 // (far[3] - far[2])) and far[4] > 4
    assert sorted(car_sampling(cam, T, prims, 100.0, 64, 4)) == sorted([(*near[:4], 2), (*far[:4], 4)])
    assert car_sampling(cam, T, prims, 100.0, 24, 4) == [(*far[:4], 2)]     # ceil(24 / 13 px)
    assert car_sampling(cam, T, prims, 5.0, 64, 4) == []      # nothing within 5 m


def test_car_sampling_colour_is_the_supersampled_render(cfg):
    """rays_across > 0: inside each car's rectangle the linear colour is the k x k supersampled full render's
    (``render_camera``'s average over the fine grid), everywhere else the one-ray foveated render's; label,
    instance and depth stay the one-ray ones, so the annotations do not change."""
    view, prims, cam = _two_cars(cfg)
    T = cam.T_vehicle_sensor
    look = cfg["world"]["domains"]["kitti_like"]["appearance"]
    one = radiance_foveated(cam, T, prims, view, look, 100.0, 500.0, 4, 8)
    ss = radiance_foveated(cam, T, prims, view, look, 100.0, 500.0, 4, 8, rays_across=64, max_rays=3)
    for k in ("label", "instance", "depth"):
        assert np.array_equal(ss[k], one[k]), k
    lin_one, lin_ss = one["linear"].reshape(180, 320, 3), ss["linear"].reshape(180, 320, 3)
    inside = np.zeros((180, 320), bool)
    rects = car_sampling(cam, T, prims, 100.0, 64, 3)
    assert sorted(r[4] for r in rects) == [2, 3]             # the near car 2 x 2 rays, the far one 3 x 3
    for r0, r1, c0, c1, k in rects:
        inside[r0:r1, c0:c1] = True
        ref = radiance(cam_fine := fine_camera(cam, k), T, prims, view, look, 100.0, 500.0)["linear"]
        ref = ref.reshape(cam_fine.height // k, k, cam_fine.width // k, k, 3).mean(axis=(1, 3))
        hit = (one["label"] != SKY)[r0:r1, c0:c1]
        assert np.allclose(lin_ss[r0:r1, c0:c1][hit], ref[r0:r1, c0:c1][hit], atol=1e-5)
        edge = np.abs(lin_ss[r0:r1, c0:c1] - lin_one[r0:r1, c0:c1]).max(axis=-1) > 0.02
        assert 0 < edge.mean() < 0.6          # the outline and the glass differ, the flat paint does not
    assert np.array_equal(lin_ss[~inside], lin_one[~inside])


def _clip_cfg(cfg):
    world = copy.deepcopy(cfg["world"])
    world["pixel_noise"] = 0.0
    clips = copy.deepcopy(cfg["velocity_clips"])
    clips.update(width=320, height=180, frames=3, supersample=1, foveate={"factor": 1, "margin_px": 0, "tile_px": 1},
                 image_format="png")                       # every pixel cast: the reference
    clips["splits"]["train"] = {"clips": 2, "velocity_scale": 1.0}
    return world, clips


def test_foveated_frame_is_the_full_render_at_every_car(cfg):
    """One frame of a motorway clip (noise off): the foveated render's instances, per-car unoccluded pixel
    counts and annotations equal the full render's; inside every window its colour and depth do too, while
    outside the image is the coarse render upsampled (close to the full one, not equal)."""
    world, clips = _clip_cfg(cfg)
    cam = clip_camera(world, clips)
    dom = world["domains"][clips["domain"]]
    checked = 0
    for c in range(3):
        mw, _ = clip_motorway(world, clips, "train", 5, c)
        view = SceneView(mw.road, mw.style, mw.cars, mw.buildings)
        state = motorway_state(mw, clips["frames"] - 1)
        T_wc = state.T_world_vehicle @ cam.T_vehicle_sensor
        args = (cam, T_wc, state.prims, view, dom["appearance"], 0.0, clips["render_distance"],
                world["fog_distance"], derive_rng(3))
        full = render_camera(*args)
        fov = render_foveated(*args, factor=4, margin=12, tile=8)
        n = len(mw.cars["size"])
        assert np.array_equal(fov["instance"], full["instance"])
        assert np.array_equal(own_pixels(fov["pairs"], state.prims, n), own_pixels(full["pairs"], state.prims, n))
        assert annotate(mw, state, cam, fov, clips) == annotate(mw, state, cam, full, clips)
        inside = np.zeros((cam.height, cam.width), bool)
        for r0, r1, c0, c1 in fov["windows"]:
            inside[r0:r1, c0:c1] = True
        assert inside[full["instance"] > 0].all()
        assert np.array_equal(fov["rgb"][inside], full["rgb"][inside])
        assert np.array_equal(fov["depth"][inside], full["depth"][inside])
        assert (full["label"][inside] == SKY).any() or c < 2      # the sky's case is met
        if (~inside).any():
            diff = np.abs(fov["rgb"][~inside].astype(int) - full["rgb"][~inside].astype(int))
            assert np.median(diff) <= 8 and diff.max() > 0
        checked += int((full["instance"] > 0).any())
        assert inside.mean() < 0.9                           # the point: most of the frame is not cast finely
    assert checked >= 2


def test_car_windows_cover_every_car_part_with_the_margin(cfg):
    """Windows hold each car's projection grown by the margin, clipped to the image, and are disjoint."""
    world, clips = _clip_cfg(cfg)
    cam = clip_camera(world, clips)
    mw, _ = clip_motorway(world, clips, "train", 5, 0)
    state = motorway_state(mw, 0)
    T_wc = state.T_world_vehicle @ cam.T_vehicle_sensor
    wins = car_windows(cam, T_wc, state.prims, 10, clips["render_distance"])
    assert wins
    for i, a in enumerate(wins):
        assert 0 <= a[0] < a[1] <= cam.height and 0 <= a[2] < a[3] <= cam.width
        for b in wins[i + 1:]:
            assert not (a[0] < b[1] and b[0] < a[1] and a[2] < b[3] and b[2] < a[3])
    none = car_windows(cam, T_wc, state.prims, 10, 1.0)     # nothing within 1 m
    assert none == []


def test_snap_rect_by_hand():
    """Rows 5..40 x columns 33..70 on a 32-px grid: rows 0..64, columns 32..96; at the image's border the grid's
    last tile is cut to the image; tile 1 changes nothing."""
    assert snap_rect((5, 40, 33, 70), 32, 720, 1280) == (0, 64, 32, 96)
    assert snap_rect((700, 715, 1250, 1279), 32, 720, 1280) == (672, 720, 1248, 1280)
    assert snap_rect((64, 96, 0, 32), 32, 720, 1280) == (64, 96, 0, 32)       # already on the grid
    assert snap_rect((5, 40, 33, 70), 1, 720, 1280) == (5, 40, 33, 70)


def test_car_windows_lie_on_the_tile_grid_and_do_not_follow_the_car(cfg):
    """With tiles, every window edge is a multiple of the tile or the image border, and every window without
    tiles lies inside one with tiles. Over a clip the untiled windows' edges take a new position whenever a car's
    projection moves or grows (each one a frame of the car's true size); the tiled edges only visit grid lines:
    far fewer positions, fixed in the image."""
    world, clips = _clip_cfg(cfg)
    tile, frames = 32, 40
    clips.update(frames=frames, width=1280, height=720)       # the default's frame (no pixel is rendered here)
    cam = clip_camera(world, clips)
    mw, _ = clip_motorway(world, clips, "train", 5, 0)
    edges, edges_tiled = set(), set()
    for i in range(frames):
        state = motorway_state(mw, i)
        T_wc = state.T_world_vehicle @ cam.T_vehicle_sensor
        plain = car_windows(cam, T_wc, state.prims, 48, clips["render_distance"])
        tiled = car_windows(cam, T_wc, state.prims, 48, clips["render_distance"], tile)
        assert plain and tiled
        for r0, r1, c0, c1 in tiled:
            assert r0 % tile == 0 and c0 % tile == 0
            assert r1 % tile == 0 or r1 == cam.height
            assert c1 % tile == 0 or c1 == cam.width
        for a in plain:
            assert any(b[0] <= a[0] and a[1] <= b[1] and b[2] <= a[2] and a[3] <= b[3] for b in tiled)
        edges |= {(k, v) for w in plain for k, v in enumerate(w)}
        edges_tiled |= {(k, v) for w in tiled for k, v in enumerate(w)}
    assert len(edges_tiled) * 3 <= len(edges)


def test_foveated_jpeg_clips(cfg, tmp_path):
    """foveate + image_format jpg: the frames are 001.jpg ... and the annotations those of the full render."""
    world, clips = _clip_cfg(cfg)
    write_clips(world, clips, "train", 5, tmp_path / "full")
    fov = dict(clips, foveate={"factor": 4, "margin_px": 12, "tile_px": 8}, image_format="jpg", jpeg_quality=80)
    write_clips(world, fov, "train", 5, tmp_path / "fov")
    for k in (1, 2):
        a, b = (json.loads((tmp_path / d / "clips" / str(k) / "annotation.json").read_text()) for d in ("full", "fov"))
        assert a == b
        names = sorted(p.name for p in (tmp_path / "fov" / "clips" / str(k) / "imgs").iterdir())
        assert names == ["001.jpg", "002.jpg", "003.jpg"]
        img = cv2.imread(str(tmp_path / "fov" / "clips" / str(k) / "imgs" / "003.jpg"))
        ref = cv2.imread(str(tmp_path / "full" / "clips" / str(k) / "imgs" / "003.png"))
        assert img.shape == ref.shape == (180, 320, 3)
        assert np.mean(np.abs(img.astype(int) - ref.astype(int))) < 12     # JPEG at quality 80, the 80 x 45 blur
    with pytest.raises(ValueError, match="supersample"):
        write_clips(world, dict(fov, supersample=2), "train", 5, tmp_path / "bad")
    assert not (tmp_path / "bad").exists() and not list(tmp_path.glob(".*bad*"))   # refused before rendering
