"""Road-plane calibration (McCraith ch. 5): LMedS plane fit, road points, scale from the camera height."""
import math

import numpy as np
import pytest

from redsup.depth import calibration

H_CAM = 1.65
K = np.array([[100.0, 0.0, 63.5], [0.0, 100.0, 31.5], [0.0, 0.0, 1.0]])
SIZE = (64, 128)  # (H, W)


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def test_lmeds_recovers_tilted_plane_with_40_percent_outliers():
    rng = np.random.default_rng(0)
    normal = _unit([0.06, -1.0, 0.09])  # up (-y) with roll and pitch
    offset = 1.65
    n_in, n_out = 600, 400
    xz = np.column_stack([rng.uniform(-4, 4, n_in), rng.uniform(3, 30, n_in)])
    # solve n.X + c = 0 for y, add 5 mm noise along the normal
    y = -(normal[0] * xz[:, 0] + normal[2] * xz[:, 1] + offset) / normal[1]
    inliers = np.column_stack([xz[:, 0], y, xz[:, 1]]) + 0.005 * rng.standard_normal((n_in, 1)) * normal
    outliers = np.column_stack([rng.uniform(-4, 4, n_out), rng.uniform(-3, 1.5, n_out), rng.uniform(3, 30, n_out)])
    pts = np.vstack([inliers, outliers])[rng.permutation(n_in + n_out)]
    plane = calibration.fit_plane_lmeds(pts, n_iter=300, seed=1)
    angle = math.degrees(math.acos(min(1.0, abs(float(plane.normal @ normal)))))
    assert angle < 1.0
    assert plane.offset == pytest.approx(offset, abs=0.01)
    assert plane.normal @ normal > 0  # oriented towards the camera, offset positive
    assert 550 <= plane.inlier_mask.sum() <= 700
    assert calibration.fit_plane_lmeds(pts, n_iter=300, seed=1).offset == plane.offset  # seeded


def test_lmeds_rejects_degenerate_input():
    with pytest.raises(ValueError):
        calibration.fit_plane_lmeds(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="collinear"):
        calibration.fit_plane_lmeds(np.outer(np.arange(10.0), [1.0, 2.0, 3.0]), n_iter=20)


def _road_depth(normal, offset):
    """Exact camera-z depth of the plane n.X + c = 0 at every pixel (NaN where the ray misses it)."""
    v, u = np.mgrid[0:SIZE[0], 0:SIZE[1]].astype(float)
    rays = np.stack([u, v, np.ones_like(u)], -1) @ np.linalg.inv(K).T
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -offset / (rays @ normal)
    return np.where(t > 0, t, np.nan)  # rays have z = 1, so t is the depth


def test_scale_from_flat_road_and_the_box_filter():
    raw_scale = 20.0  # network units are metres / 20
    metric = _road_depth(_unit([0.0, -1.0, 0.0]), H_CAM)
    road = np.isfinite(metric)
    road[: SIZE[0] // 2 + 2] = False  # no road at the horizon
    raw = np.where(road, metric, 50.0) / raw_scale
    pts = calibration.road_points(raw, road, K, max_length=15.0, max_width=2.0, camera_height=H_CAM)
    assert len(pts) > 50
    assert np.all(np.abs(pts[:, 0] * raw_scale) < 2.0) and np.all(pts[:, 2] * raw_scale < 15.0)
    assert np.allclose(pts[:, 1] * raw_scale, H_CAM)
    scale, reason = calibration.calibrate_frame(raw, road, K, H_CAM, max_length=15.0, max_width=2.0)
    assert reason is None and scale == pytest.approx(raw_scale, rel=1e-6)
    fixed, _ = calibration.fixed_plane_scale(raw, road, K, H_CAM)
    assert fixed == pytest.approx(raw_scale, rel=1e-6)
    plane = calibration.Plane(np.array([0.0, -1.0, 0.0]), H_CAM / raw_scale, np.ones(1, bool))
    assert calibration.scale_from_camera_height(plane, H_CAM) == pytest.approx(raw_scale)


def test_tilted_road_needs_the_fitted_plane():
    """A pitched camera: the fitted plane gives the exact scale, the fixed horizontal plane does not."""
    raw_scale = 30.0
    normal = _unit([0.0, -1.0, -0.05])  # about 3 deg of pitch
    metric = _road_depth(normal, H_CAM)
    road = np.isfinite(metric) & (metric < 40)
    road[: SIZE[0] // 2 + 2] = False
    raw = np.where(road, metric, 50.0) / raw_scale
    scale, _ = calibration.calibrate_frame(raw, road, K, H_CAM)
    assert scale == pytest.approx(raw_scale, rel=1e-6)
    fixed, _ = calibration.fixed_plane_scale(raw, road, K, H_CAM)
    assert abs(fixed / raw_scale - 1) > 0.05


def test_no_road_pixels_gives_a_reason():
    raw = np.ones(SIZE)
    scale, reason = calibration.calibrate_frame(raw, np.zeros(SIZE, bool), K, H_CAM)
    assert scale is None and "road points" in reason
    assert calibration.fixed_plane_scale(raw, np.zeros(SIZE, bool), K, H_CAM)[0] is None
    with pytest.raises(ValueError):
        calibration.scale_from_camera_height(calibration.Plane(np.array([0, -1.0, 0]), 0.0, np.ones(1, bool)), H_CAM)


def test_gt_scale_baselines():
    gt = np.zeros((100, 200))
    gt[50:90, 20:180] = np.linspace(2, 30, 160)
    pairs = [(gt, gt / s) for s in (10.0, 20.0, 40.0)]
    assert calibration.per_frame_gt_scale(*pairs[1])[0] == pytest.approx(20.0)
    scale, n = calibration.single_gt_scale(pairs + [(np.zeros_like(gt), gt)])
    assert (scale, n) == (pytest.approx(20.0), 3)
    assert calibration.per_frame_gt_scale(np.zeros_like(gt), gt) == (None, "no valid ground-truth pixel")


def test_road_selection_length_and_width_by_hand():
    """Flat road Y = 1 m seen by a 10 x 10 camera (f = 10, cx = 4.5, horizon above the image):
    pixel (u, v) lies at Z = 10 / (v + 0.5), X = (u - 4.5) / (v + 0.5)."""
    K_small = np.array([[10.0, 0.0, 4.5], [0.0, 10.0, -0.5], [0.0, 0.0, 1.0]])
    road = np.ones((10, 10), bool)
    sel = calibration.road_selection(road, K_small, 1.0, max_length=3.0, max_width=0.9)
    expected = np.zeros((10, 10), bool)  # row 2 is at Z = 4 m: too far
    expected[3, 2:8] = True  # Z = 2.86 m: |u - 4.5| < 0.9 * 3.5 = 3.15
    expected[4, 1:9] = True  # Z = 2.22 m: |u - 4.5| < 0.9 * 4.5 = 4.05
    expected[5:, :] = True   # Z <= 1.82 m: |u - 4.5| < 0.9 * 5.5 = 4.95 holds for every column
    assert np.array_equal(sel, expected)
    # the length limit alone: Z < 5 m from v + 0.5 > 2, i.e. rows 2..9; a wide box keeps every column
    sel = calibration.road_selection(road, K_small, 1.0, max_length=5.0, max_width=100.0)
    assert np.array_equal(sel.any(axis=1), np.arange(10) >= 2) and sel[2:].all()
    # pixels not labelled road are never selected
    road[6, 3] = False
    assert not calibration.road_selection(road, K_small, 1.0, max_length=3.0, max_width=0.9)[6, 3]


def test_degenerate_plane_reasons():
    raw = _road_depth(_unit([0.0, -1.0, 0.0]), H_CAM)
    road = np.isfinite(raw)
    road[: SIZE[0] // 2 + 2] = False
    raw = np.where(road, raw, 50.0) / 10.0
    # one pixel column: the selected points are collinear
    column = np.zeros(SIZE, bool)
    column[40:, 64] = True
    scale, reason = calibration.calibrate_frame(raw, column, K, H_CAM, min_points=5)
    assert scale is None and reason.startswith("degenerate road plane")
    # a plane through the camera centre (zero offset) is degenerate too
    plane = calibration.Plane(np.array([0.0, -1.0, 0.0]), 0.0, np.ones(1, bool))
    with pytest.raises(ValueError, match="positive"):
        calibration.scale_from_camera_height(plane, H_CAM)
    # optional tilt limit: a wall facing the camera is not a road
    wall = np.full(SIZE, 10.0)
    scale, reason = calibration.calibrate_frame(wall, np.ones(SIZE, bool), K, H_CAM, max_tilt_deg=20.0)
    assert scale is None and "from the camera's vertical" in reason
    assert calibration.plane_tilt_deg(np.array([0.0, -1.0, 0.0])) == pytest.approx(0.0)
    assert calibration.plane_tilt_deg(np.array([0.0, 0.0, 1.0])) == pytest.approx(90.0)
