"""McCraith ch. 3 library: eq. (1), the geometric baseline, smoothing, the MLP, the synthetic generator,
the TuSimple metric and bad-input handling. (MedianFlow on a rendered clip: tests/test_tracks.py.)"""
from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from redsup.sceneio import SceneError
from redsup.velocity import geometry, mlp
from redsup.velocity.data import TrackSet, load_tracks
from redsup.velocity.experiment import evaluate, run_constant, run_geometric, training_tracks
from redsup.velocity.metrics import tusimple_metrics
from redsup.velocity.smoothing import gaussian_smooth
from redsup.velocity.summary import ablation_table, constraint_px, fig3_table, size_jitter, table2
from redsup.velocity.synthetic import box_size, fit_statistics, generate_tracks

CAL = geometry.Calibration(fx=714.0, fy=710.0, cx=640.0, cy=360.0, height=1.8)
FPS = 20.0


@pytest.fixture()
def one_thread():
    """Tiny models train far faster on one thread (and the machine is shared)."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


# ------------------------------------------------------------------------------------------ eq. (1)
def test_eq1_round_trip_hand_values():
    # ground point 2.5 m right, 30 m ahead: u = 640 + 714 * 2.5 / 30 = 699.5, v = 360 + 710 * 1.8 / 30 = 402.6
    box = geometry.box_from_ground(2.5, 30.0, 40.0, 30.0, CAL)
    np.testing.assert_allclose(box, [699.5 - 20.0, 402.6 - 30.0, 40.0, 30.0])
    u, v = geometry.bottom_centre(box)
    assert u == pytest.approx(699.5) and v == pytest.approx(402.6)
    X, Z, valid = geometry.box_ground_point(box, CAL)
    assert valid and X == pytest.approx(2.5) and Z == pytest.approx(30.0)


def test_eq1_round_trip_many_points_and_horizon():
    rng = np.random.default_rng(0)
    X, Z = rng.uniform(-12, 12, 500), rng.uniform(3, 120, 500)
    boxes = geometry.box_from_ground(X, Z, rng.uniform(2, 80, 500), rng.uniform(2, 60, 500), CAL)
    X2, Z2, valid = geometry.box_ground_point(boxes, CAL)
    assert valid.all()
    np.testing.assert_allclose(X2, X, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(Z2, Z, rtol=1e-9)
    # a box bottom on or above the horizon has no ground point
    X3, Z3, valid3 = geometry.ground_point(np.array([640.0, 700.0]), np.array([360.0, 300.0]), CAL)
    assert not valid3.any() and np.isnan(Z3).all() and np.isnan(X3).all()


def test_geometric_velocity_recovers_constant_motion():
    t = np.arange(40) / FPS
    X, Z = 2.0 + 0.5 * t, 30.0 - 2.0 * t  # vx = 0.5, vz = -2 m/s
    boxes = geometry.box_from_ground(X, Z, 50.0, 40.0, CAL)[None]
    out = geometry.geometric_velocity(boxes, CAL, FPS, window=10)
    np.testing.assert_allclose(out["velocity"][0], [0.5, -2.0], atol=1e-9)
    np.testing.assert_allclose(out["position"][0], [X[-1], Z[-1]])
    assert out["valid"][0]
    # window 2 is the backward difference
    noisy = boxes.copy()
    noisy[0, -1, 1] += 1.0  # box bottom one pixel lower in the last frame
    X_n, Z_n, _ = geometry.box_ground_point(noisy[0], CAL)
    out2 = geometry.geometric_velocity(noisy, CAL, FPS, window=2)
    np.testing.assert_allclose(out2["velocity"][0], [(X_n[-1] - X_n[-2]) * FPS, (Z_n[-1] - Z_n[-2]) * FPS])


def test_line_slope_skips_invalid_frames_and_flags_too_few():
    values = np.array([[0.0, 99.0, 2.0, 3.0], [1.0, 2.0, 3.0, 4.0]])
    valid = np.array([[True, False, True, True], [False, False, False, True]])
    slope, ok = geometry.line_slope_at_end(values, valid, window=4)
    assert slope[0] == pytest.approx(1.0) and ok[0]
    assert slope[1] == 0.0 and not ok[1]
    boxes = np.tile([[600.0, 300.0, 20.0, 20.0]], (1, 5, 1))  # bottom at v = 320 < cy: above the horizon
    out = geometry.geometric_velocity(boxes, CAL, FPS, window=3)
    assert not out["valid"][0] and (out["velocity"][0] == 0).all()


def test_read_calibration_ours_and_tusimple(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "calibration.txt").write_text("178.6 178.6 159.5 89.5\n1.8\n")
    cal = geometry.read_calibration(tmp_path / "a")
    assert (cal.fx, cal.fy, cal.cx, cal.cy, cal.height) == (178.6, 178.6, 159.5, 89.5, 1.8)
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "calibration.txt").write_text(
        "Intrinsic matrix:\n714.1526    0.      675.5754\n   0.      710.3725  376.2563\n"
        "   0.        0.        1.    \n"
        "\nCamera Height:\n\n1.80m\n")
    cal = geometry.read_calibration(tmp_path / "b")
    assert (cal.fx, cal.fy, cal.cx, cal.cy, cal.height) == (714.1526, 710.3725, 675.5754, 376.2563, 1.8)
    (tmp_path / "c").mkdir()
    (tmp_path / "c" / "calibration.txt").write_text("714 710 640\n")
    with pytest.raises(SceneError, match="calibration.txt"):
        geometry.read_calibration(tmp_path / "c")
    with pytest.raises(SceneError, match="missing"):
        geometry.read_calibration(tmp_path / "nowhere")


def test_real_tusimple_calibration_reads_and_eq1_is_defined(realdata):
    clips = realdata / "tusimple_velocity" / "train"
    cal = geometry.read_calibration(clips)
    assert (cal.fx, cal.fy, cal.cx, cal.cy, cal.height) == (714.1526, 710.3725, 675.5754, 376.2563, 1.8)
    import json

    vehicle = json.loads((clips / "clips" / "1" / "annotation.json").read_text())[0]
    b = vehicle["bbox"]
    box = np.array([b["left"], b["top"], b["right"] - b["left"], b["bottom"] - b["top"]])
    X, Z, valid = geometry.box_ground_point(box, cal)
    # the real camera is not level (the horizon is not at cy): eq. (1) puts this car, 21.3 m ahead by the
    # LiDAR, at about 75 m; that is the thesis' point about the geometric baseline, not a reading error
    assert valid and Z == pytest.approx(710.3725 * 1.8 / (b["bottom"] - 376.2563)) and Z > vehicle["position"][0]


# ------------------------------------------------------------------------------------- smoothing
def test_gaussian_smoothing_keeps_constants_and_interior_lines():
    t = np.arange(40, dtype=float)
    boxes = np.stack([t * 1.5, np.full(40, 7.0), t * 0.0 + 3.0, 100 - t], axis=-1)[None]
    out = gaussian_smooth(boxes, 5.0)
    np.testing.assert_allclose(out[0, :, 1], 7.0)
    np.testing.assert_allclose(out[0, 20, 0], 30.0, atol=1e-3)  # a line is kept where the kernel fits
    np.testing.assert_allclose(gaussian_smooth(boxes, 0.0), boxes)
    assert abs(out[0, -1, 0] - boxes[0, -1, 0]) > 1  # the end is pulled in (nearest-value boundary)


# -------------------------------------------------------------------------------------------- MLP
def test_crelu_and_architecture():
    x = torch.tensor([[1.5, -2.0, 0.0]])
    np.testing.assert_allclose(mlp.CReLU()(x).numpy(), [[1.5, 0.0, 0.0, 0.0, 2.0, 0.0]])
    model = mlp.VelocityMLP(160, hidden=70, layers=4, dropout=0.2)
    linears = [m for m in model.net if isinstance(m, torch.nn.Linear)]
    assert [(m.in_features, m.out_features) for m in linears] == [(160, 70), (140, 70), (140, 70), (140, 70),
                                                                 (140, 2)]
    assert sum(isinstance(m, mlp.CReLU) for m in model.net) == 4
    assert all(m.p == 0.2 for m in model.net if isinstance(m, torch.nn.Dropout))
    assert model(torch.zeros(3, 160)).shape == (3, 2)


def test_box_features_are_standardised_image_coordinates():
    boxes = np.array([[[640.0 + 71.4, 360.0 - 71.0, 714.0, 355.0]]])
    f = mlp.box_features(boxes, CAL, 0.0)
    np.testing.assert_allclose(f, [[0.1, -0.1, 1.0, 0.5]], rtol=1e-6)
    assert mlp.box_features(np.zeros((0, 40, 4)), CAL, 5.0).shape == (0, 160)


def test_velocity_loss_is_unreduced_squared_norm():
    loss = mlp.velocity_loss(torch.tensor([[1.0, 2.0], [0.0, 0.0]]), torch.tensor([[0.0, 0.0], [3.0, 4.0]]))
    np.testing.assert_allclose(loss.numpy(), [5.0, 25.0])


def test_training_reduces_the_loss_and_lr_decays(one_thread):
    rng = np.random.default_rng(1)
    feats = rng.normal(0, 1, (256, 8)).astype(np.float32) * 5 + 3  # standardised inside the model
    targets = (feats - 3) / 5 @ rng.normal(0, 1, (8, 2))
    model, curve = mlp.train_mlp(feats, targets, hidden=16, layers=2, dropout=0.0, lr=1e-2, lr_decay=0.9,
                                 epochs=10, batch_size=32, seed=0, eval_sets={"val": (feats[:50], targets[:50])})
    assert len(curve) == 10 and curve[-1]["train_loss"] < 0.1 * curve[0]["train_loss"]
    assert curve[1]["lr"] == pytest.approx(1e-2 * 0.9) and curve[-1]["val_loss"] < 0.1 * curve[0]["val_loss"]
    assert mlp.predict(model, feats[:4]).shape == (4, 2)
    boxes = generate_tracks(_stats(), 2, rng)["boxes"]
    model = mlp.VelocityMLP(160)
    timing = mlp.forward_time_ms(model, boxes, CAL, 5.0, repeats=5)
    assert 0 < timing["forward_ms_median"] < 1000


# ---------------------------------------------------------------------------------------- metric
def test_tusimple_metric_on_hand_made_predictions():
    true = np.array([[0.0, 1.0], [1.0, 0.0], [0.0, 0.0], [2.0, 2.0], [0.0, 0.0]])
    pred = np.array([[0.0, 2.0], [1.0, 2.0], [3.0, 4.0], [2.0, 2.0], [1.0, 1.0]])
    bins = np.array([0, 0, 1, 2, 2])
    m = tusimple_metrics(pred, true, bins)
    # near: (1 + 4) / 2 = 2.5; medium: 9 + 16 = 25; far: (0 + 2) / 2 = 1; E_v = (2.5 + 25 + 1) / 3 = 9.5
    assert m["E_v_near"] == 2.5 and m["E_v_medium"] == 25.0 and m["E_v_far"] == 1.0
    assert m["E_v"] == pytest.approx(9.5) and (m["n_near"], m["n_medium"], m["n_far"]) == (2, 1, 2)
    p = tusimple_metrics(pred, true, bins, p_pred=pred, p_true=true)
    assert p["E_p"] == pytest.approx(9.5)
    # an empty bin has no error and E_v averages the others
    m2 = tusimple_metrics(pred[:2], true[:2], np.array([0, 2]))
    assert math.isnan(m2["E_v_medium"]) and m2["E_v"] == pytest.approx((1 + 4) / 2) and m2["n_bins"] == 2


# ------------------------------------------------------------------------------- synthetic data
def _fake_training(n=400, seed=0) -> TrackSet:
    """Training vehicles with known statistics: 1.8 x 1.5 m boxes, constant velocities ~ N(mean, cov)."""
    rng = np.random.default_rng(seed)
    T = 40
    t = np.arange(T) / FPS
    X0, Z0 = rng.choice([-3.75, 0.0, 3.75], n) + rng.normal(0, 0.2, n), rng.uniform(8, 80, n)
    V = rng.multivariate_normal([0.1, -0.5], [[0.04, 0.01], [0.01, 2.25]], n)
    X, Z = X0[:, None] + V[:, :1] * t, Z0[:, None] + V[:, 1:] * t
    boxes = geometry.box_from_ground(X, Z, CAL.fx * 1.8 / Z, CAL.fy * 1.5 / Z, CAL)
    return TrackSet(boxes=boxes, velocity=V, position=np.stack([X[:, -1], Z[:, -1]], -1),
                    bins=np.digitize(Z[:, -1], (20, 45)), clip=np.arange(n), track_id=np.zeros(n, int),
                    tracker_failed=np.zeros(n, bool), degenerate=np.zeros(n, bool), calib=CAL)


def _stats(train=None):
    train = train if train is not None else _fake_training()
    return fit_statistics(train, CAL, n_frames=40, fps=FPS, size_degree=2, max_depth=150.0, min_depth=2.0)


def test_generator_fit_recovers_the_statistics():
    train = _fake_training()
    stats = _stats(train)
    np.testing.assert_allclose(np.polyval(stats["width_poly_inv_z"], 1 / np.array([10.0, 40.0])),
                               [1.8 / 10, 1.8 / 40], rtol=1e-6)
    assert stats["width_rel_std"] < 1e-6 and stats["n_start_points"] == 400
    np.testing.assert_allclose(stats["velocity_mean"], train.velocity.mean(0))
    np.testing.assert_allclose(stats["velocity_cov"], np.cov(train.velocity.T))
    X1, Z1, _ = geometry.box_ground_point(train.boxes[:, 0], CAL)  # eq. (1) of the first boxes
    np.testing.assert_allclose(stats["start_points"], np.stack([X1, Z1], -1))


def test_generated_tracks_obey_the_fitted_statistics():
    stats = _stats()
    gen = generate_tracks(stats, 6000, np.random.default_rng(3))
    boxes, V = gen["boxes"], gen["velocity"]
    assert boxes.shape == (6000, 40, 4) and np.isfinite(boxes).all()
    # start points are drawn from the empirical set
    X1, Z1, valid = geometry.box_ground_point(boxes[:, 0], CAL)
    points = np.asarray(stats["start_points"])
    assert valid.all()
    np.testing.assert_allclose(np.stack([X1, Z1], -1), points[gen["start_index"]], atol=1e-6)
    # velocities follow the fitted Gaussian
    np.testing.assert_allclose(V.mean(0), stats["velocity_mean"], atol=0.06)
    np.testing.assert_allclose(np.cov(V.T), stats["velocity_cov"], rtol=0.1, atol=0.005)
    # motion is the integrated constant velocity: eq. (1) of every box lies on P_1 + V t
    X, Z, _ = geometry.box_ground_point(boxes, CAL)
    t = np.arange(40) / FPS
    np.testing.assert_allclose(X, X1[:, None] + V[:, :1] * t, atol=1e-6)
    np.testing.assert_allclose(Z, Z1[:, None] + V[:, 1:] * t, atol=1e-6)
    assert Z.min() >= stats["min_depth"]
    # sizes follow the fitted polynomial in 1/Z (this training set has no size spread)
    w_fit, h_fit = box_size(stats, Z)
    np.testing.assert_allclose(boxes[..., 2], w_fit, rtol=1e-4)
    np.testing.assert_allclose(boxes[..., 3], h_fit, rtol=1e-4)
    # the geometric baseline is exact on synthetic tracks (they are generated with eq. (1))
    out = geometry.geometric_velocity(boxes[:50], CAL, FPS, window=10)
    np.testing.assert_allclose(out["velocity"], V[:50], atol=1e-6)


def test_velocity_scale_widens_the_velocities():
    stats = _stats()
    base = generate_tracks(stats, 4000, np.random.default_rng(4))["velocity"]
    wide = generate_tracks(stats, 4000, np.random.default_rng(4), velocity_scale=3.0)["velocity"]
    assert wide[:, 1].std() == pytest.approx(3 * base[:, 1].std(), rel=0.1)


# ----------------------------------------------------------------------------------- bad input
def _write_tracks(path, boxes, failed, z):
    n = len(boxes)
    np.savez(path, clip=np.arange(n) + 1, track_id=np.zeros(n, int), boxes=np.asarray(boxes, np.float32),
             failed=failed, velocity=np.tile([1.0, -0.5], (n, 1)), position=np.stack([z, np.ones(n)], -1),
             distance=z, bin_index=np.digitize(z, (20, 45)).astype(np.int8))


def test_failed_tracks_and_degenerate_boxes_are_flagged_excluded_and_scored(tmp_path):
    good = _fake_training(3).boxes
    boxes = good.copy()
    boxes[1, -1, 2] = 0.0  # degenerate annotation: zero width
    boxes[2, 5] = np.nan   # a broken box
    failed = np.zeros((3, 40), bool)
    failed[0, :10] = True  # the tracker lost the first vehicle early in the clip
    _write_tracks(tmp_path / "m.npz", boxes, failed, np.array([12.0, 30.0, 60.0]))
    tracks = load_tracks(tmp_path / "m.npz", min_box_px=1.0)
    tracks.calib = CAL
    assert tracks.tracker_failed.tolist() == [True, False, False]
    assert tracks.degenerate.tolist() == [False, True, True] and np.isfinite(tracks.boxes).all()
    assert tracks.velocity[0].tolist() == [-0.5, 1.0]  # converted from TuSimple's [vz, vx]
    q = tracks.quality()
    assert (q["n_tracker_failed"], q["n_degenerate"], q["n_usable"], q["n_clips_with_bad_input"]) == (1, 2, 0, 3)
    assert tracks.bad_input_per_clip()[2] == {"tracker_failed": 0, "degenerate": 1}
    # excluded from training ...
    _, _, counts = training_tracks({"name": "t", "train_on": "tracker"}, tracks, None, 0, np.random.default_rng(0))
    assert counts["train_n"] == 0 and counts["train_excluded"] == 3
    with pytest.raises(ValueError, match="usable"):
        fit_statistics(tracks, CAL, n_frames=40, fps=FPS)
    # ... scored at evaluation, never a crash
    metrics, _ = run_geometric({"test": tracks}, FPS, window=10, timing_repeats=3)
    assert metrics["test_n"] == 3 and np.isfinite(metrics["test_E_v"])
    assert metrics["test_n_tracker_failed"] == 1 and metrics["test_n_degenerate"] == 2
    m = evaluate("x", tracks, np.zeros((3, 2)))
    assert m["x_n"] == 3 and "x_E_v_clean" not in m


def test_fig3_fractions_inside_the_constraint_lines():
    Z = np.array([10.0, 20.0, 40.0])
    values = {"Z": Z, "x": constraint_px("x", 0.0, Z, CAL), "y": constraint_px("y", 1.5, Z, CAL),
              "h": CAL.fy * np.array([1.5, 1.0, 2.0]) / Z, "w": CAL.fx * np.array([1.8, 1.8, 3.5]) / Z}
    table = fig3_table(values, CAL)
    assert table.at["h (box height)", "fraction inside"] == pytest.approx(2 / 3)
    assert table.at["w (box width)", "fraction inside"] == pytest.approx(2 / 3)
    assert table.at["x (lateral offset X)", "fraction inside"] == 1.0
    assert table.at["y (box top)", "median (m)"] == pytest.approx(1.5)
    assert table.at["w (box width)", "median (m)"] == pytest.approx(1.8)


def test_size_jitter_hand_case():
    boxes = np.zeros((1, 4, 4))
    boxes[0, :, 2] = [10, 12, 10, 12]  # second differences |10 - 24 + 10| = 4, |12 - 20 + 12| = 4
    assert size_jitter(boxes) == pytest.approx(2.0)  # averaged with h (all zero)


def test_constant_reference_predicts_the_training_mean():
    train = _fake_training(50)
    test = _fake_training(20, seed=1)
    metrics, predictions = run_constant(train, {"test": test})
    np.testing.assert_allclose(predictions["test"]["velocity"], np.tile(train.velocity.mean(0), (20, 1)))
    expected = tusimple_metrics(predictions["test"]["velocity"], test.velocity, test.bins)["E_v"]
    assert metrics["test_E_v"] == pytest.approx(expected) and metrics["train_n"] == 50


def test_table_frames_use_the_paper_labels():
    m = {"test_E_v": 1.0, "test_E_v_near": 0.5, "test_E_v_medium": 1.0, "test_E_v_far": 1.5, "test_n": 7,
         "forward_ms_median": 0.3, "train_n": 100, "abnormal_E_v": 9.0, "abnormal_E_v_far": 12.0}
    t2 = table2({"Ours (MLP-tracker)": m})
    assert list(t2.columns[:5]) == ["E_v", "E_v^near", "E_v^medium", "E_v^far", "runtime (ms)"]
    assert t2.at["Ours (MLP-tracker)", "E_v^far"] == 1.5 and math.isnan(t2.at["Ours (MLP-tracker)", "E_p"])
    ab = ablation_table({"x": m})
    assert ab.at["x", "E_v (abnormal)"] == 9.0 and ab.at["x", "E_v^far (abnormal)"] == 12.0


def test_seed_runs_and_seed_rows(tmp_path):
    """MLP configurations run once per seed and their row is the seed mean with the seed spread; rows
    without learning get a paired bootstrap over the test vehicles."""
    from redsup.velocity import plan
    from redsup.velocity import tables as velocity_tables

    config = {"profile": "tiny", "velocity": {
        "seeds": 3, "configurations": [{"name": "geometric", "method": "geometric"},
                                       {"name": "mlp_tracker", "method": "mlp",
                                        "train_on": "tracker"}],
        "tables": {"t2": {"layout": "errors", "rows": [{"label": "geometric reprojection", "run": "geometric"},
                                                         {"label": "Ours (MLP-tracker)", "run": "mlp_tracker"}]}}}}
    assert plan.seed_runs(config, "mlp_tracker") == ["mlp_tracker", "mlp_tracker_seed1", "mlp_tracker_seed2"]
    assert plan.seed_runs(config, "geometric") == ["geometric"]
    assert plan.parse_run("mlp_tracker_seed2") == ("mlp_tracker", 2)
    rows = plan.rows(config)["t2"]
    assert [r[1] for r in rows] == ["geometric", "mlp_tracker", "mlp_tracker_seed1", "mlp_tracker_seed2"]
    assert plan.runs(config)["mlp_tracker_seed1"]["tables"] == ["t2"]

    def record(e_v, sq_err, ms=0.1):
        ids = [f"0/{i}" for i in range(len(sq_err))]
        return {"metrics": {"test_E_v": e_v, "forward_ms_median": ms},
                "per_track": {"test": {"id": ids, "bin": [0, 1, 2, 2], "sq_err": sq_err}}}

    results = {"geometric": record(4.0, [1.0, 3.0, 7.0, 9.0]), "mlp_tracker": record(1.0, [1] * 4, 0.2),
               "mlp_tracker_seed1": record(2.0, [2] * 4, 0.3), "mlp_tracker_seed2": record(3.0, [3] * 4, 0.7)}
    ours, noise = velocity_tables.configuration_table("errors", rows, results)
    # the runtime: the mean of the three jobs' medians, their spread its noise; the single geometric run has none
    assert ours.at["Ours (MLP-tracker)", "runtime (ms)"] == pytest.approx(0.4)
    assert noise["Ours (MLP-tracker)"]["runtime (ms)"] == {"kind": "seeds", "values": [0.2, 0.3, 0.7]}
    assert "runtime (ms)" not in noise["geometric reprojection"]
    assert ours.at["Ours (MLP-tracker)", "E_v"] == pytest.approx(2.0)
    rec = noise["Ours (MLP-tracker)"]["E_v"]
    assert rec["kind"] == "seeds" and rec["values"] == [1.0, 2.0, 3.0]
    # its test-sampling noise: each seed's squared errors are constant (1, 2, 3), so every replicate of the seed
    # mean is 2, over the same 4 vehicles as the geometric row's bootstrap
    assert rec["boot"] == pytest.approx([2.0] * 200) and rec["units"] == noise["geometric reprojection"]["E_v"]["units"]
    geo = noise["geometric reprojection"]["E_v^far"]
    assert geo["kind"] == "bootstrap" and set(np.round(geo["values"], 6)) <= {7.0, 8.0, 9.0}
    # E_v of the full sample by hand: bins near 1, medium 3, far (7 + 9) / 2 = 8 -> mean 4
    assert velocity_tables._binned({f"0/{i}": v for i, v in enumerate([1.0, 3.0, 7.0, 9.0])},
                                   {f"0/{i}": b for i, b in enumerate([0, 1, 2, 2])}, [f"0/{i}" for i in range(4)],
                                   None) == pytest.approx(4.0)


def test_configured_tables_share_runs_and_seed_counts():
    """config.yaml: the ablation shows Table II's rows (the same runs, no extra training) beside the two
    variants, so its claims against MLP-tracker have their row; MLPs train 5 seeds in default, 2 in tiny,
    the rows without learning once."""
    from redsup import config as config_lib
    from redsup.velocity import plan

    root = Path(__file__).resolve().parents[1]
    for profile, n_seeds in (("default", 5), ("tiny", 2)):
        cfg = config_lib.load(root / "config.yaml", {"profile": profile})
        rows = plan.rows(cfg)
        tables = cfg["velocity"]["tables"]
        t2, ab = (next(t for t, tc in tables.items() if tc.get("layout") == lay) for lay in ("errors", "ablation"))
        labels_t2 = {label for label, _, _ in rows[t2]}
        assert labels_t2 <= {label for label, _, _ in rows[ab]}
        assert {"Ours (MLP-tracker)", "geometric reprojection"} <= labels_t2
        runs_of = {}
        for label, run, _ in rows[ab]:
            runs_of.setdefault(label, []).append(run)
        assert len(runs_of["Ours (MLP-tracker)"]) == n_seeds and runs_of["geometric reprojection"] == ["geometric"]
        assert plan.runs(cfg)["mlp_tracker"]["tables"] == [t2, ab]
        # Table I: one clip-count result, a row per split
        counts = next(t for t, tc in tables.items() if "counts" in tc)
        assert rows[counts] == [("Train", "clip_counts", None), ("Test", "clip_counts", None)]
        assert plan.result_path("clip_counts") == "results/velocity/clip_counts.json"


def test_mlp_checkpoint_is_the_one_format_with_the_config(tmp_path):
    """save_model writes a redsup.checkpoint of kind velocity_mlp (resolved config inside); load_model
    rebuilds the same network (same outputs) and refuses another kind."""
    from redsup import checkpoint

    torch.manual_seed(0)
    model = mlp.VelocityMLP(in_dim=12, hidden=5, layers=2, dropout=0.0)
    model.eval()
    path = tmp_path / "model.pt"
    config = {"profile": "tiny", "velocity": {"smoothing_sigma": 5.0}}
    mlp.save_model(model, path, config, {"smoothing_sigma": 5.0})
    data = checkpoint.load(path, "velocity_mlp")
    assert data["config"] == config and data["meta"]["smoothing_sigma"] == 5.0
    loaded, meta = mlp.load_model(path)
    x = torch.randn(3, 12)
    with torch.no_grad():
        assert torch.allclose(loaded(x), model(x))
    assert meta["network"] == model.config and not list(tmp_path.glob("*.part"))
    with pytest.raises(ValueError, match="expected 'depth'"):
        checkpoint.load(path, "depth")


# ------------------------------------------------------------------ geometric diagnosis, smoothing protocol
def test_geometric_diagnosis_on_exact_boxes_by_hand():
    from redsup.velocity.diagnosis import diagnosis_note, geometric_diagnosis

    tracks = _fake_training(n=60, seed=4)
    d = geometric_diagnosis(tracks, FPS)
    for name in ("diff", "lsq10"):   # exact boxes, constant velocity: eq. (1) gives Z_t exactly, linear in t
        assert d[f"E_v_{name}"] == pytest.approx(0.0, abs=1e-9)
    # smoothing repeats the edge value: the last-frame derivative of smoothed boxes is damped towards zero
    assert 0 < d["E_v_smooth5_diff"] < np.mean(np.sum(tracks.velocity ** 2, axis=1))
    assert d["E_p_far"] == pytest.approx(0.0, abs=1e-12)
    far = tracks.bins == 2
    z_med = np.median(tracks.position[far, 1])
    assert d["dz_per_px_far"] == pytest.approx(z_med ** 2 / (710.0 * 1.8))
    # box bottom below the horizon: fy H / Z at the last frame (median)
    assert d["horizon_px_far"] == pytest.approx(np.median(710.0 * 1.8 / tracks.position[far, 1]))
    # one pixel of jitter on the far boxes' bottom edge in the last frame: the backward difference error is
    # fps x dZ of that pixel, the 10-frame line dilutes it
    noisy = tracks.subset(np.ones(len(tracks), bool))
    noisy.boxes = noisy.boxes.copy()
    noisy.boxes[:, -1, 1] += 1.0
    n = geometric_diagnosis(noisy, FPS)
    assert n["E_v_diff_far"] > 10 * n["E_v_lsq10_far"] > 0
    note = diagnosis_note({f"test_geo_{k}": v for k, v in n.items()})
    assert "backward difference" in note and f"{n['E_v_diff_far']:.3g}" in note


def test_scale_signal_by_hand():
    """The v_z a track's size change implies, by hand, and its correlation with the truth: about 1 on exact boxes,
    falling when the far boxes' size jitters by a pixel."""
    from redsup.velocity.diagnosis import scale_signal, scale_velocity

    # T = 4 frames at 1 fps: size 10 at the first frame, 8 at frame T - 1 (index 2), Z = 20 m at the last frame:
    # Z_1 = 20 x 8 / 10 = 16 m, v_z = (20 - 16) / 2 s = 2 m/s
    boxes = np.array([[[0, 0, 10, 10], [0, 0, 9, 9], [0, 0, 8, 8], [0, 0, 7.9, 7.9]]], float)
    assert scale_velocity(boxes, np.array([20.0]), 1.0) == pytest.approx([2.0])
    assert np.isnan(scale_velocity(boxes * [1, 1, 0, 1], np.array([20.0]), 1.0)[0])
    tracks = _fake_training(n=60, seed=4)
    exact = scale_signal(tracks, FPS)
    for b in ("near", "medium", "far"):
        assert exact[f"scale_corr_{b}"] > 0.99
    far = tracks.bins == 2
    assert exact["box_px_far"] == pytest.approx(np.median(tracks.boxes[far, -2, 3]))
    noisy = tracks.subset(np.ones(len(tracks), bool))
    noisy.boxes = noisy.boxes.copy()
    rng = np.random.default_rng(0)
    noisy.boxes[:, :, 2:] += rng.normal(0.0, 1.0, noisy.boxes[:, :, 2:].shape)
    jittered = scale_signal(noisy, FPS)
    assert jittered["scale_corr_far"] < exact["scale_corr_far"] - 0.05


def test_scale_jitter_by_hand():
    """The std of log size around its polynomial fit: 0 for a size that changes smoothly, 0.01 for one that
    alternates between 10 and 10 e^0.02 about its mean (degree 0), NaN for a box without area."""
    from redsup.velocity.diagnosis import scale_jitter

    t = np.arange(6.0)
    smooth = 10 * np.exp(0.03 * t - 0.002 * t ** 2)                 # log size quadratic in t: nothing left
    alternating = 10 * np.exp(0.02 * (t % 2))                        # log s - log 10 = 0, 0.02, 0, ... (mean 0.01)
    boxes = np.zeros((3, 6, 4))
    boxes[0, :, 2] = boxes[0, :, 3] = smooth
    boxes[1, :, 2] = boxes[1, :, 3] = alternating
    boxes[2, :, 2:] = 5.0
    boxes[2, 3, 2] = 0.0
    j = scale_jitter(boxes)
    assert j[0] == pytest.approx(0.0, abs=1e-9) and np.isnan(j[2])
    assert scale_jitter(boxes[1:2], degree=0)[0] == pytest.approx(0.01)
    assert 0.0 < j[1] < 0.01                                         # a quadratic absorbs a little of it


def test_truth_diagnosis_by_hand():
    """Per bin, by hand (T = 4 frames at 1 fps, t = 2 s): the v_z term paid by the clip's mean velocity, the
    spread of the true size ratio Z_1 / Z_3, and the tracker's error on it (failed tracks left out)."""
    from redsup.velocity.diagnosis import truth_diagnosis

    boxes = np.array([[[0, 0, 10, 10], [0, 0, 9, 9], [0, 0, 8, 8], [0, 0, 7.9, 7.9]],      # tracked ratio 0.8
                      [[0, 0, 5, 5], [0, 0, 5, 5], [0, 0, 5.5, 5.5], [0, 0, 5, 5]],        # 1.1
                      [[0, 0, 2, 2], [0, 0, 2, 2], [0, 0, 3, 3], [0, 0, 2, 2]]], float)    # failed
    distance = np.array([[16.0, 17.0, 18.0, 20.0], [20.0] * 4, [50.0] * 4])
    tracks = TrackSet(boxes=boxes, velocity=np.array([[0.0, 2.0], [0.0, 0.0], [0.0, 1.0]]),
                      position=np.array([[0.0, 20.0], [0.0, 20.0], [0.0, 50.0]]), bins=np.array([0, 0, 2]),
                      clip=np.array([1, 1, 2]), track_id=np.array([1, 2, 1]),
                      tracker_failed=np.array([False, False, True]), degenerate=np.zeros(3, bool))
    d = truth_diagnosis(tracks, distance, 1.0)
    # v_avg = (18 - 16) / 2 = 1 against the annotated 2, and 0 against 0: mean of 1 and 0
    assert d["accel_floor_near"] == pytest.approx(0.5)
    # true ratios 16 / 18 and 1: std = (1 - 8 / 9) / 2
    assert d["ratio_signal_near"] == pytest.approx((1 - 8 / 9) / 2)
    # tracked minus true: 0.8 - 8 / 9 and 1.1 - 1
    assert d["ratio_noise_near"] == pytest.approx(np.std([0.8 - 8 / 9, 0.1]))
    assert d["accel_floor_far"] == pytest.approx(1.0) and d["ratio_signal_far"] == 0.0
    assert np.isnan(d["ratio_noise_far"]) and "accel_floor_medium" not in d


def test_smoothing_protocol_per_training_data():
    from redsup.velocity.experiment import smoothing_of

    smoothing = {"tracker": {"train": 0.0, "test": 0.0}, "synthetic": {"train": 0.0, "test": 5.0}}
    assert smoothing_of({"train_on": "tracker"}, smoothing) == (0.0, 0.0)
    assert smoothing_of({"train_on": "synthetic"}, smoothing) == (0.0, 5.0)


def test_run_mlp_monitors_val_only(one_thread):
    from redsup.velocity.experiment import run_mlp

    train, val, test = _fake_training(120, 1), _fake_training(30, 2), _fake_training(30, 3)
    cfg = {"hidden": 8, "layers": 1, "dropout": 0.0, "lr": 1e-3, "lr_decay": 1.0, "epochs": 2,
           "epochs_synthetic": 1, "batch_size": 32, "timing_repeats": 2, "features": "relative"}
    smoothing = {"tracker": {"train": 0.0, "test": 0.0}, "synthetic": {"train": 0.0, "test": 5.0}}
    metrics, _, _, curve = run_mlp({"name": "t", "train_on": "tracker"}, cfg, smoothing, 0, train,
                                   {"val": val, "test": test}, None, 0)
    assert set(curve[0]) == {"train_loss", "lr", "val_loss"}
    assert np.isfinite(metrics["val_E_v"]) and np.isfinite(metrics["test_E_v"])
    assert metrics["smoothing_sigma_test"] == 0.0


def test_mlp_keeps_the_epoch_with_the_lowest_val_loss(one_thread):
    """select_on="val": the returned weights are those of the epoch whose val loss is lowest (the curve marks
    it), checked by predicting the val set again; an unknown eval set is refused."""
    rng = np.random.default_rng(0)
    x = rng.normal(size=(64, 6)).astype(np.float32)
    y = np.stack([x[:, 0], -x[:, 1]], axis=1)
    xv = rng.normal(size=(32, 6)).astype(np.float32)
    yv = rng.normal(size=(32, 2)) * 3.0          # val targets unrelated to the inputs: val loss is not monotone
    kw = dict(hidden=8, layers=1, dropout=0.0, lr=3e-2, lr_decay=1.0, epochs=12, batch_size=16, seed=0,
              eval_sets={"val": (xv, yv)})
    model, curve = mlp.train_mlp(x, y, select_on="val", **kw)
    losses = [r["val_loss"] for r in curve]
    best = int(np.argmin(losses))
    assert best != len(curve) - 1                # the case where selecting differs from the last epoch
    assert [r["best"] for r in curve] == [float(i == best) for i in range(len(curve))]
    kept = float(((mlp.predict(model, xv) - yv) ** 2).sum(axis=1).mean())
    assert kept == pytest.approx(losses[best], rel=1e-5)
    last, curve_last = mlp.train_mlp(x, y, **kw)
    assert "best" not in curve_last[0]
    assert float(((mlp.predict(last, xv) - yv) ** 2).sum(axis=1).mean()) == pytest.approx(losses[-1], rel=1e-5)
    with pytest.raises(ValueError, match="not an eval set"):
        mlp.train_mlp(x, y, select_on="test", **kw)


def test_track_statistics_by_hand():
    from redsup.velocity.summary import fig6_table, track_statistics

    velocity = np.array([[0.0, 1.0], [0.0, -1.0], [0.5, 3.0], [-0.5, -3.0]])   # [vx, vz]
    position = np.array([[0.0, 10.0], [0.0, 15.0], [0.0, 60.0], [0.0, 70.0]])  # [x, z]
    st = track_statistics(velocity, position)
    assert (st["share near"], st["share medium"], st["share far"]) == (0.5, 0.0, 0.5)
    assert st["std v_z near (m/s)"] == pytest.approx(1.0) and st["std v_z far (m/s)"] == pytest.approx(3.0)
    assert st["std v_z (m/s)"] == pytest.approx(np.sqrt(5.0)) and st["std v_x (m/s)"] == pytest.approx(np.sqrt(0.125))
    assert math.isnan(st["std v_z medium (m/s)"])
    boxes = np.zeros((4, 3, 4))
    t = fig6_table(boxes, boxes, {"frame rate": 20}, st, st)
    assert t.at["synthetic", "share far"] == 0.5 and t.at["frame rate", "value"] == 20


def test_relative_box_features_by_hand():
    boxes = np.zeros((1, 3, 4))
    boxes[0, :, :] = [[640.0, 360.0, 71.4, 71.0], [650.0, 360.0, 71.4, 71.0], [660.0, 367.1, 71.4, 71.0]]
    f = mlp.box_features(boxes, CAL, 0.0, "relative")
    assert f.shape == (1, 16)
    # the last box standardised: (660 - 640) / 714, (367.1 - 360) / 710, 71.4 / 714, 71 / 710
    np.testing.assert_allclose(f[0, :4], [20 / 714, 0.01, 0.1, 0.1], rtol=1e-5)
    # frame 1 minus the last, over the last height 0.1: x (-20 / 714) / 0.1, y (-0.01) / 0.1, w 0, h 0
    np.testing.assert_allclose(f[0, 4:8], [-20 / 714 / 0.1, -0.1, 0.0, 0.0], rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(f[0, -4:], 0.0, atol=1e-7)     # the last frame itself
    g = mlp.box_features(boxes, CAL, 0.0, "relative_metric")
    assert g.shape == (1, 28)
    np.testing.assert_allclose(g[0, :16], f[0], rtol=1e-6)      # the relative features first, then ...
    # ... frame 1's changes over the last height squared (0.1^2): x (-20 / 714) / 0.01, y (-0.01) / 0.01 = -1
    np.testing.assert_allclose(g[0, 16:20], [-20 / 714 / 0.01, -1.0, 0.0, 0.0], rtol=1e-5, atol=1e-6)
    with pytest.raises(ValueError, match="mode"):
        mlp.box_features(boxes, CAL, 0.0, "polar")


def test_table_caption_states_the_render_and_the_epoch_kept():
    from redsup import config as rconfig
    from redsup.velocity.tables import table_note

    cfg = rconfig.load(Path(__file__).resolve().parents[1] / "config.yaml", {"profile": "default"})
    tcfg = cfg["velocity"]["tables"]["mccraith_ch3_table2"]
    note = table_note(cfg, tcfg)
    plain = copy.deepcopy(cfg)
    plain["velocity_clips"]["foveate"]["car_rays_across"] = 0
    assert "embedded clips rendered at 1280 x 720 px, 1 x 1 ray per pixel (TuSimple: 1280 x 720), foveated (the cars " \
           "and 48 px around them cast at full resolution, the rest 4x coarser and upsampled), JPEG frames at " \
           "quality 80" in table_note(plain, tcfg)
    plain["velocity_clips"]["foveate"].update(car_rays_across=64, car_max_rays=4)
    assert "the rest 4x coarser and upsampled; over every car k x k rays a pixel, k = ceil(64 / its width in px) up " \
           "to 4), JPEG" in table_note(plain, tcfg)
    tiled = copy.deepcopy(cfg)
    tiled["velocity_clips"]["foveate"]["tile_px"] = 32
    assert "cast at full resolution on a fixed 32-px tile grid, the rest 4x coarser" in table_note(tiled, tcfg)
    assert "the epoch with the lowest val loss kept" in note
    assert "scale by more than e^0.1 per frame rejected" in note
    cfg["velocity_clips"].update(supersample=2, foveate={"factor": 1, "margin_px": 0, "tile_px": 1}, image_format="png")
    cfg["velocity"]["mlp"]["select_epoch_on_val"] = False
    cfg["detection"]["medianflow"]["max_scale_step"] = 0.0
    note = table_note(cfg, tcfg)
    assert "2 x 2 rays per pixel" in note and "lowest val loss" not in note
    assert "foveated" not in note and "JPEG" not in note
    assert "MedianFlow run backward" in note and "rejected" not in note
