"""The occlusion proxy of studies/velocity_oracle.py (`redsup.velocity.diagnosis.hidden_fraction`: the far bin's
drift split by partial occlusion), by hand."""
import numpy as np

from redsup.velocity.diagnosis import hidden_fraction


def test_hidden_fraction_by_hand():
    # vehicle 0: a 10 x 10 box at 60 m; vehicle 1 at 20 m covers its right half in frame 1 only and a quarter of
    # it in frame 2; vehicle 2 at 90 m (farther) covers all of it in every frame and must not count.
    boxes = np.array([
        [[0, 0, 10, 10], [0, 0, 10, 10], [0, 0, 10, 10]],
        [[50, 0, 30, 30], [5, 0, 30, 30], [5, 5, 30, 30]],
        [[-5, -5, 40, 40], [-5, -5, 40, 40], [-5, -5, 40, 40]],
    ], dtype=float)
    depth = np.array([[60.0] * 3, [20.0] * 3, [90.0] * 3])
    out = hidden_fraction(boxes, depth, [0, 1, 2])
    assert out[0] == 0.5                      # frame 1: 5 x 10 of 10 x 10
    assert out[1] == 0.0                      # nothing is nearer than vehicle 1
    # vehicle 2 (90 m): vehicle 0 covers 100 of 1600 px, vehicle 1 in frame 0 covers x 35..50 of -5..35 -> 0
    # columns, in frame 1 the x range 5..35, y 0..30 -> 900 / 1600
    assert out[2] == 900 / 1600


def test_hidden_fraction_ignores_vehicles_behind_the_camera():
    boxes = np.array([[[0, 0, 10, 10]], [[0, 0, 10, 10]]], dtype=float)
    assert hidden_fraction(boxes, np.array([[30.0], [-5.0]]), [0])[0] == 0.0
    assert hidden_fraction(boxes, np.array([[30.0], [5.0]]), [0])[0] == 1.0
