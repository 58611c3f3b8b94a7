"""KITTI AP and AOS equal the official python port of the devkit (traveller59/kitti-object-eval-python) on a
stored fixture: 90 generated frames (Car, Van, Pedestrian, Cyclist, Person_sitting, DontCare; detections with
scores, localisation and orientation noise and false positives) in tests/data/kitti_official/{gt,det}, and the
port's AP and AOS computed once by tests/data/kitti_official/make_fixture.py (expected.json; the port is not
vendored).

With the real, tilted KITTI calibration (the `realdata` samples; skipped when absent) every box goes through the
workflow's vehicle frame and back, and the AP must still be the port's.
"""
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT
from redsup import eval_frame
from redsup.adapters.kitti import label_to_row
from redsup.det3d import kitti_eval
from redsup.det3d.kitti_files import _vehicle_frame, read_folders, read_objects

DATA = ROOT / "tests" / "data" / "kitti_official"
EXPECTED = json.loads((DATA / "expected.json").read_text())


def _ours(argv):
    from redsup.det3d.kitti_eval import main
    import contextlib
    import io
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(argv) == 0
    return json.loads(buf.getvalue())


def _assert_equal(got, want, tol=0.01):
    assert set(got) == set(want)
    bad = {k: (got[k], want[k]) for k in want if not abs(got[k] - want[k]) <= tol}
    assert not bad, bad


def test_fixture_covers_every_metric_class_and_recall():
    assert len(EXPECTED) == 168            # 2d/bev/3d/aos x (Car, Van: 2 IoU; 3 classes: 1) x 3 difficulties x R11/R40
    assert EXPECTED["Car_3d_0.7/moderate_R40"] > 5 and EXPECTED["Car_3d_0.7/moderate_R40"] < 95
    # the detections' orientation errors cost AOS more than the comparison's tolerance below AP
    assert 0.05 < EXPECTED["Car_2d_0.7/moderate_R40"] - EXPECTED["Car_aos_0.7/moderate_R40"] < 5


def test_command_equals_the_official_port():
    _assert_equal(_ours(["--gt", str(DATA / "gt"), "--det", str(DATA / "det")]), EXPECTED)


def test_command_line_help_explains_the_format():
    out = subprocess.run([sys.executable, "-m", "redsup.det3d.kitti_eval", "--help"], capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT / "workflow")}, check=True).stdout
    assert "16" in out and "rotation_y" in out and "R40" in out and "score" in out and "aos" in out and "alpha" in out


def test_label_box_is_the_devkits_box():
    """Hand check: a car at x=2, y=1.6 (bottom), z=20, h=1.5, ry=0 (heading +x_rect = right)."""
    box = eval_frame.label_box(2.0, 1.6, 20.0, 1.5, 1.6, 4.0, 0.0)
    np.testing.assert_allclose(box, [20.0, -2.0, -(1.6 - 0.75), 4.0, 1.6, 1.5, -math.pi / 2])
    back = eval_frame.label_fields(box)
    assert back["cx"] == pytest.approx(2.0) and back["cy"] == pytest.approx(1.6) and back["ry"] == pytest.approx(0.0)


def _tilted_T():
    """A vehicle frame tilted 0.5 deg about two axes from rect0's vertical (as on real KITTI)."""
    a, b = math.radians(0.5), math.radians(0.4)
    Rx = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    Ry = np.array([[math.cos(b), 0, math.sin(b)], [0, 1, 0], [-math.sin(b), 0, math.cos(b)]])
    T = np.eye(4)
    T[:3, :3] = Rx @ Ry @ eval_frame.R_UPRIGHT_RECT
    T[:3, 3] = [0.27, 0.0, 1.65]
    return T


def test_label_to_vehicle_and_back_is_exact_on_a_tilted_frame():
    T = _tilted_T()
    T_eval = eval_frame.eval_transform(T)
    for lab in read_objects(DATA / "gt" / "000003.txt", scored=False):
        if lab["cls"] == "DontCare":
            continue
        row = label_to_row(lab, 0, 1, T)
        got = eval_frame.to_eval_frame(np.array([[row[k] for k in ("x", "y", "z", "l", "w", "h", "yaw")]]), T_eval)[0]
        want = eval_frame.label_box(*(lab[k] for k in ("cx", "cy", "cz", "h", "w", "l", "ry")))
        np.testing.assert_allclose(got[:6], want[:6], atol=1e-9)
        assert abs(eval_frame.wrap_angle(got[6] - want[6])) < 1e-9


def test_workflow_path_on_the_real_tilted_calibration_equals_the_official_port(tmp_path, realdata):
    real_calib = realdata / "kitti_object" / "training" / "calib" / "000000.txt"
    T = _vehicle_frame(real_calib)
    up_vehicle_in_rect = np.linalg.inv(T)[:3, :3] @ np.array([0.0, 0.0, 1.0])
    tilt = math.degrees(math.acos(-up_vehicle_in_rect[1]))
    assert 0.2 < tilt < 1.0, tilt                   # the real calibration is tilted
    calib = tmp_path / "calib"
    calib.mkdir()
    for p in (DATA / "gt").glob("*.txt"):
        (calib / p.name).symlink_to(real_calib)
    _assert_equal(_ours(["--gt", str(DATA / "gt"), "--det", str(DATA / "det"), "--calib", str(calib)]), EXPECTED)
