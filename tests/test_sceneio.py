"""Bad input gets an error naming the file and the problem."""
import json

import numpy as np
import pytest

from redsup import sceneio


def test_intrinsics_round_trip(tmp_path):
    K = np.array([[700.0, 0, 600.5], [0, 710.0, 180.25], [0, 0, 1]])
    sceneio.write_intrinsics(tmp_path / "cam_front.txt", K, (1242, 375))
    K2, size = sceneio.read_intrinsics(tmp_path / "cam_front.txt")
    assert np.allclose(K, K2) and size == (1242, 375)


@pytest.mark.parametrize("text, problem", [
    ("700 0 600\n0 700 180\n", "malformed"),
    ("700 0 600\n0 700 abc\n0 0 1\n1242 375\n", "malformed"),
    ("700 0 600\n0 700 180\n0 0 2\n1242 375\n", "implausible"),
    ("-700 0 600\n0 700 180\n0 0 1\n1242 375\n", "implausible"),
])
def test_malformed_intrinsics_named(tmp_path, text, problem):
    path = tmp_path / "cam_front.txt"
    path.write_text(text)
    with pytest.raises(sceneio.SceneError, match=problem) as err:
        sceneio.read_intrinsics(path)
    assert str(path) in str(err.value)


def test_truncated_lidar_named(tmp_path):
    path = tmp_path / "000000.bin"
    np.arange(12, dtype="<f4").tofile(path)
    path.write_bytes(path.read_bytes()[:-3])
    with pytest.raises(sceneio.SceneError, match="not a multiple of the 16-byte record") as err:
        sceneio.read_lidar(path)
    assert str(path) in str(err.value)


def test_lidar_nan_rows_dropped(tmp_path):
    path = tmp_path / "000000.bin"
    np.array([[1, 2, 3, 0.5], [np.nan, 0, 0, 0], [4, 5, 6, 0.1]], dtype="<f4").tofile(path)
    assert np.array_equal(sceneio.read_lidar(path), np.array([[1, 2, 3, 0.5], [4, 5, 6, 0.1]], dtype="<f4"))


def test_unreadable_image_named(tmp_path):
    path = tmp_path / "000000.png"
    path.write_bytes(b"not a png")
    with pytest.raises(sceneio.SceneError, match="unreadable"):
        sceneio.read_image(path)
    with pytest.raises(sceneio.SceneError, match="missing"):
        sceneio.read_image(tmp_path / "000001.png")


def test_missing_frames_listed(tmp_path):
    (tmp_path / "lidar_top").mkdir()
    for i in (0, 1, 3):
        (tmp_path / "lidar_top" / f"{i:06d}.bin").write_bytes(b"")
    with pytest.raises(sceneio.SceneError, match=r"1 of 4 frames missing \(000002.bin\)"):
        sceneio.sensor_frames(tmp_path, "lidar_top", "bin", 4)


def test_bad_poses_and_extrinsics(tmp_path):
    (tmp_path / "ego_poses.txt").write_text("1 0 0 0 0 1 0 0 0 0 1\n")
    with pytest.raises(sceneio.SceneError, match="12 numbers"):
        sceneio.read_poses(tmp_path / "ego_poses.txt")
    (tmp_path / "extrinsics.json").write_text(json.dumps({"cam_front": [[1, 0], [0, 1]]}))
    with pytest.raises(sceneio.SceneError, match="cam_front"):
        sceneio.read_extrinsics(tmp_path / "extrinsics.json")
    with pytest.raises(sceneio.SceneError, match="scene.json"):
        sceneio.read_meta(tmp_path)
