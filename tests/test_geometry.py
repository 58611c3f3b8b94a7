"""Pure geometry against hand-computed cases."""
import numpy as np
import pytest

from redsup import geometry
from redsup.prep.camera import crop_resize

K = np.array([[200.0, 0.0, 160.0], [0.0, 200.0, 60.0], [0.0, 0.0, 1.0]])
POINTS = np.array([[0.0, 0.0, 10.0], [2.0, -1.0, 5.0], [-3.0, 1.5, 20.0], [1.0, 0.5, 4.0]])


def test_project_hand_case():
    uv, z = geometry.project(K, POINTS[:2])
    assert np.allclose(uv, [[160.0, 60.0], [240.0, 20.0]])
    assert np.allclose(z, [10.0, 5.0])


def test_backproject_inverts_project():
    uv, z = geometry.project(K, POINTS)
    assert np.allclose(geometry.backproject(K, uv, z), POINTS)


def test_crop_then_resize_moves_projections_exactly():
    crop = {"top": 20, "bottom": 10, "left": 32, "right": 0}
    raw_size, out_size = (320, 120), (144, 45)  # cropped 288x90 -> scale 0.5
    K2 = geometry.crop_resize_intrinsics(K, crop, raw_size, out_size)
    uv, _ = geometry.project(K, POINTS)
    uv2, _ = geometry.project(K2, POINTS)
    expected = (uv - [crop["left"], crop["top"]] + 0.5) * 0.5 - 0.5
    assert np.allclose(uv2, expected)
    assert K2[0, 0] == pytest.approx(100.0) and K2[1, 1] == pytest.approx(100.0)


def _blob(width, height, centre, sigma=2.5):
    yy, xx = np.mgrid[0:height, 0:width]
    g = np.exp(-((xx - centre[0]) ** 2 + (yy - centre[1]) ** 2) / (2 * sigma**2))
    return np.repeat((255 * g)[..., None], 3, axis=2).astype(np.uint8)


def _centroid(image):
    w = image[..., 0].astype(float)
    yy, xx = np.mgrid[0:image.shape[0], 0:image.shape[1]]
    return np.array([(w * xx).sum() / w.sum(), (w * yy).sum() / w.sum()])


@pytest.mark.parametrize("out_size", [(144, 45), (96, 30), (288, 90)])
def test_cropped_resized_image_agrees_with_adjusted_intrinsics(out_size):
    """A bright blob drawn where a 3D point projects lands where the new K projects it."""
    crop = {"top": 20, "bottom": 10, "left": 32, "right": 0}
    raw_size = (320, 120)
    point = np.array([[1.2, 0.3, 6.0]])
    uv, _ = geometry.project(K, point)
    image = crop_resize(_blob(*raw_size, uv[0], sigma=4.0), crop, out_size)
    uv2, _ = geometry.project(geometry.crop_resize_intrinsics(K, crop, raw_size, out_size), point)
    assert np.allclose(_centroid(image), uv2[0], atol=0.15)


def test_crop_leaving_nothing_is_an_error():
    with pytest.raises(ValueError, match="leaves nothing"):
        geometry.crop_resize_intrinsics(K, {"top": 60, "bottom": 60, "left": 0, "right": 0}, (320, 120), (10, 10))


def test_sparse_depth_nearest_wins_and_range():
    pts = np.array([[0.0, 0.0, 10.0], [0.0, 0.0, 5.0], [0.0, 0.0, 90.0], [1.0, 0.0, 10.0], [0, 0, -3.0]])
    depth = geometry.sparse_depth_map(pts, K, 320, 120, (0.1, 80.0))
    assert depth[60, 160] == 5.0  # nearer of the two on one pixel
    assert depth[60, 180] == 10.0  # u = 160 + 200 * 1 / 10
    assert (depth > 0).sum() == 2  # 90 m beyond range, behind camera dropped


def _pose(yaw, t):
    c, s = np.cos(yaw), np.sin(yaw)
    T = np.eye(4)
    T[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    T[:3, 3] = t
    return T


def test_invert_pose():
    T = _pose(0.3, [1.0, -2.0, 0.5])
    assert np.allclose(geometry.invert_pose(T) @ T, np.eye(4))


def test_lidar_to_camera_chain_hand_case():
    """A LiDAR point 10 m ahead, taken 1 m earlier along x, is 9 m ahead of the camera now."""
    T_v_l = _pose(0.0, [0.0, 0.0, 1.73])
    cam_axes = np.array([[0, 0, 1, 0], [-1, 0, 0, 0], [0, -1, 0, 0], [0, 0, 0, 1]], float)  # vehicle<-camera
    T_v_c = cam_axes.copy()
    T_v_c[:3, 3] = [0.0, 0.0, 1.73]
    T = geometry.lidar_to_camera(T_v_l, _pose(0, [0, 0, 0]), _pose(0, [1.0, 0, 0]), T_v_c)
    p = geometry.transform_points(T, np.array([[10.0, 2.0, 0.0]]))
    assert np.allclose(p, [[-2.0, 0.0, 9.0]])
