"""McCraith ch. 7 detector (redsup.lidar_detector): targets, voting, heatmap peaks + NMS, augmentation,
the network's shapes, bad input, the cached split and the tables. Hand-computed cases."""
import json
import math

import numpy as np
import pandas as pd
import pytest
import torch

from redsup.det3d import losses as L
from redsup.det3d import template as T
from redsup.det3d.boxes import bev_iou
from redsup.lidar_detector import augment as A
from redsup.lidar_detector import criterion as C
from redsup.lidar_detector import postprocess as P
from redsup.lidar_detector import targets as TG
from redsup.lidar_detector.grid import GridSpec
from redsup.lidar_detector.model import CenterDetector

N_BINS = 64
SIC = C.alignment_loss("sic", 5.0, 0.0)


@pytest.fixture(scope="module")
def tmpl():
    return T.build_template(T.TemplateSpec(spacing=0.05, voxel=0.1, margin=1.0))


def _posed(local: np.ndarray, centre, yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    return local @ R.T + np.asarray(centre, dtype=float)


def _left_rear_scan(tmpl, centre, yaw):
    """Template surface points of the left side and the rear, posed (a partial scan as LiDAR sees it)."""
    local = tmpl.points[(tmpl.points[:, 1] > 0.7) | (tmpl.points[:, 0] < -1.9)]
    return _posed(local, centre, yaw)


# ------------------------------------------------------------------------------------------- grid
def test_grid_spec_sizes_and_validation():
    g = GridSpec()
    assert (g.nx, g.ny, g.cell, g.out_width, g.out_height) == (256, 128, pytest.approx(0.4), 128, 64)
    bev = g.bev()
    assert (bev.x_min, bev.y_min, bev.height, bev.width) == (0.0, -12.8, 64, 128)
    with pytest.raises(ValueError, match="whole number"):
        GridSpec(x_range=(0.0, 10.1))
    with pytest.raises(ValueError, match="increasing"):
        GridSpec(y_range=(1.0, -1.0))


# ---------------------------------------------------------------------------------------- targets
def test_median_of_mask_points_picks_the_expected_cell(tmpl):
    bev = GridSpec().bev()                            # cell 0.4 m from (x, y) = (0, -12.8)
    lm = np.array([[10.05, 2.3, 0.5], [10.15, 2.1, 0.6], [10.25, 1.9, 0.4], [30.0, 2.1, 0.5], [10.2, 2.2, 0.9]])
    # median x = 10.2, median y = 2.2 -> col floor(10.2 / 0.4) = 25, row floor(15.0 / 0.4) = 37
    objs = TG.weak_objects([[lm]], min_points=3, max_points=None, rng=np.random.default_rng(0))
    H, W = bev.height, bev.width
    outputs = {"offset": torch.zeros(1, 3, H, W), "yaw": torch.zeros(1, N_BINS, H, W)}
    a = TG.assign_weak(bev, outputs, objs, window=0, loss_fn=SIC, template=tmpl)
    assert a.median[0].tolist() == [37, 25] and a.cell[0].tolist() == [37, 25] and bool(a.valid[0])


def test_target_builder_votes_for_the_lowest_loss_neighbour_end_to_end(tmpl):
    """Median cell -> voting over the 3 x 3 window -> heatmap peak, alignment and yaw target at the cell
    whose prediction fits L_m best; gradients reach only that cell's offset."""
    grid = GridSpec(x_range=(0.0, 12.0), y_range=(-4.0, 4.0), pillar=0.2, stride=2)
    bev = grid.bev()
    centre, yaw = np.array([6.13, 0.35, 0.1]), 0.3
    lm = _left_rear_scan(tmpl, centre, yaw)
    objs = TG.weak_objects([[lm]], min_points=3, max_points=None, rng=np.random.default_rng(0))
    med = TG.median_cell(bev, objs.points, objs.mask)[0]
    H, W = bev.height, bev.width
    offset = torch.zeros(1, 3, H, W)
    offset[0, :2] = 0.2
    offset[0, 1] += 2.5                                   # every cell predicts a centre 2.5 m to its left ...
    offset[0, 2] = 0.1
    good = (int(med[0]) + 1, int(med[1]) - 1)             # ... except one neighbour, which predicts the car
    offset[0, 0, good[0], good[1]] = float(centre[0] - good[1] * bev.cell)
    offset[0, 1, good[0], good[1]] = float(centre[1] - (bev.y_min + good[0] * bev.cell))
    yaw_logits = torch.zeros(1, N_BINS, H, W)
    true_bin = int(L.yaw_to_bin(torch.tensor(yaw), N_BINS))
    yaw_logits[0, true_bin] = 5.0
    offset.requires_grad_(True)
    outputs = {"offset": offset, "yaw": yaw_logits}

    a0 = TG.assign_weak(bev, outputs, objs, window=0, loss_fn=SIC, template=tmpl)
    assert a0.cell[0].tolist() == med.tolist()            # window 0: the median's own cell (CenterPoint)
    a1 = TG.assign_weak(bev, outputs, objs, window=1, loss_fn=SIC, template=tmpl)
    assert tuple(a1.cell[0].tolist()) == good
    assert a1.vote.loss[0] == a1.vote.window_loss[0].min() and a1.vote.window_loss.shape == (1, 9)

    radius = TG.object_radius(3.9, 1.6, bev.cell)
    heat = TG.heatmap_target(1, H, W, objs.frame, a1.cell, torch.tensor([float(radius)]))
    assert heat[0, 0, good[0], good[1]] == 1.0 and int((heat == 1).sum()) == 1
    sigma = (2 * radius + 1) / 6
    assert heat[0, 0, good[0], good[1] + 1].item() == pytest.approx(math.exp(-1 / (2 * sigma ** 2)), rel=1e-5)
    assert heat[0, 0, good[0], good[1] + radius + 1] == 0.0

    terms = C.weak_alignment(outputs, bev, a1, objs, SIC, tmpl)
    assert _circ(int(terms["best_bin"][0]), true_bin) <= 1                      # the best bin is the car's yaw
    assert terms["alignment"][0].item() < -0.45                                 # points on the surface: ~ -sigmoid(0)
    terms["alignment"].sum().backward()
    g = offset.grad[0].abs().sum(dim=0)
    assert g[good[0], good[1]] > 0 and int((g > 0).sum()) == 1


def test_recentred_vote_moves_to_the_cell_of_the_winners_centre(tmpl):
    """vote_recentre (ch. 7 sec. 3.3 "updated center"): with window 0 the first vote can only pick the median's
    cell; a second vote around the cell holding that cell's predicted centre picks that cell, two cells on. A
    predicted centre off the grid keeps the last winner."""
    grid = GridSpec(x_range=(0.0, 12.0), y_range=(-4.0, 4.0), pillar=0.2, stride=2)
    bev = grid.bev()
    lm = _left_rear_scan(tmpl, np.array([6.13, 0.35, 0.1]), 0.3)
    objs = TG.weak_objects([[lm]], min_points=3, max_points=None, rng=np.random.default_rng(0))
    med = TG.median_cell(bev, objs.points, objs.mask)[0]
    H, W = bev.height, bev.width
    offset = torch.zeros(1, 3, H, W)
    offset[0, 0] = 0.2
    offset[0, 1] = 0.2
    offset[0, 0, med[0], med[1]] = 2 * bev.cell + 0.2      # the median's cell points two cells on in x
    outputs = {"offset": offset, "yaw": torch.zeros(1, N_BINS, H, W)}
    once = TG.assign_weak(bev, outputs, objs, window=0, loss_fn=SIC, template=tmpl)
    twice = TG.assign_weak(bev, outputs, objs, window=0, loss_fn=SIC, template=tmpl, recentre=1)
    assert once.cell[0].tolist() == med.tolist()
    assert twice.cell[0].tolist() == [int(med[0]), int(med[1]) + 2] and twice.median[0].tolist() == med.tolist()
    offset[0, 0, med[0], med[1]] = 100.0                   # a centre beyond the grid: stay
    off_grid = TG.assign_weak(bev, outputs, objs, window=0, loss_fn=SIC, template=tmpl, recentre=2)
    assert off_grid.cell[0].tolist() == med.tolist()
    with pytest.raises(ValueError, match="recentre"):
        TG.assign_weak(bev, outputs, objs, window=0, loss_fn=SIC, template=tmpl, recentre=-1)


def test_eq9_vote_adds_the_yaw_cross_entropy(tmpl):
    """Two cells of the window predict the same (true) centre, so their alignment at the best bin ties;
    the eq. (9) vote breaks the tie with the cross-entropy: the cell whose yaw logits already favour the
    best bin wins, while the alignment-only vote ("best") keeps the first cell in row-major order."""
    grid = GridSpec(x_range=(0.0, 12.0), y_range=(-4.0, 4.0))
    bev = grid.bev()
    centre, yaw = np.array([6.13, 0.35, 0.1]), 0.3
    objs = TG.weak_objects([[_left_rear_scan(tmpl, centre, yaw)]], 3, None, np.random.default_rng(0))
    med = TG.median_cell(bev, objs.points, objs.mask)[0]
    H, W = bev.height, bev.width
    offset = torch.zeros(1, 3, H, W)
    offset[0, 1] = 3.0                                     # junk everywhere ...
    first, second = (int(med[0]) - 1, int(med[1]) - 1), (int(med[0]) + 1, int(med[1]) + 1)
    for r, c in (first, second):                           # ... but two cells predict the car's centre
        offset[0, :, r, c] = torch.tensor([centre[0] - c * bev.cell, centre[1] - (bev.y_min + r * bev.cell), 0.1])
    logits = torch.zeros(1, N_BINS, H, W)
    true_bin = int(L.yaw_to_bin(torch.tensor(yaw), N_BINS))
    logits[0, true_bin, second[0], second[1]] = 4.0
    outputs = {"offset": offset, "yaw": logits}
    best = TG.assign_weak(bev, outputs, objs, 1, SIC, tmpl, yaw_mode="best")
    eq9 = TG.assign_weak(bev, outputs, objs, 1, SIC, tmpl, yaw_mode="loss")
    assert tuple(best.cell[0].tolist()) == first and tuple(eq9.cell[0].tolist()) == second
    assert _circ(int(L.yaw_to_bin(eq9.vote.yaw, N_BINS)[0]), true_bin) <= 1
    wl = eq9.vote.window_loss[0]
    ce_uniform = math.log(N_BINS)
    assert wl[0].item() - wl[8].item() == pytest.approx(ce_uniform - (-math.log(math.exp(4) / (math.exp(4) + 63))),
                                                        abs=1e-3)
    # a subset of the points for the vote: same choice, deterministic for a seeded generator
    sub = TG.assign_weak(bev, outputs, objs, 1, SIC, tmpl, yaw_mode="loss", vote_points=32,
                         generator=torch.Generator().manual_seed(0))
    assert tuple(sub.cell[0].tolist()) == second


def _circ(a, b, n=N_BINS):
    d = abs(a - b) % n
    return min(d, n - d)


def test_supervised_targets_by_hand():
    bev = GridSpec().bev()
    box = np.array([[10.3, -1.1, 0.8, 4.2, 1.8, 1.5, math.pi / 2]])
    tg = TG.assign_supervised(bev, [np.zeros((0, 7)), box], N_BINS, np.array([3.9, 1.6, 1.5]))
    # col floor(10.3 / 0.4) = 25, row floor(11.7 / 0.4) = 29; offset from the corner (10.0, -1.2, 0)
    assert tg.frame.tolist() == [1] and tg.cell.tolist() == [[29, 25]]
    assert torch.allclose(tg.offset[0], torch.tensor([0.3, 0.1, 0.8]), atol=1e-5)
    assert tg.yaw_bin.tolist() == [48]                                          # -pi + 2 pi 48 / 64 = pi / 2
    assert torch.allclose(tg.log_size[0], torch.log(torch.tensor([4.2 / 3.9, 1.8 / 1.6, 1.0])))
    outside = TG.assign_supervised(bev, [np.array([[60.0, 0, 0.8, 4, 2, 1.5, 0]])], N_BINS, np.ones(3))
    assert len(outside.frame) == 0


def test_focal_loss_by_hand():
    target = torch.tensor([[[[1.0, 0.5, 0.0]]]])
    logits = torch.logit(torch.tensor([[[[0.9, 0.2, 0.1]]]]))
    per_cell, n_pos = C.focal_heatmap_loss(logits, target)
    assert n_pos.item() == 1
    expected = [-math.log(0.9) * 0.1 ** 2, -math.log(0.8) * 0.2 ** 2 * 0.5 ** 4, -math.log(0.9) * 0.1 ** 2]
    assert torch.allclose(per_cell.flatten(), torch.tensor(expected), rtol=1e-4)


# ---------------------------------------------------------------------------- peaks, decoding, NMS
def test_heatmap_peaks_and_bev_nms_on_a_hand_made_map():
    heat = torch.zeros(10, 12)
    heat[2, 3] = 0.9
    heat[2, 4] = 0.8          # beside the 0.9 peak: not a local maximum
    heat[2, 6] = 0.7          # a local maximum of its own, 3 cells (1.2 m) from the first: same car
    heat[7, 9] = 0.6
    heat[8, 1] = 0.04         # below the threshold
    rows, cols, scores = P.heatmap_peaks(heat, max_peaks=10, threshold=0.05)
    assert list(zip(rows.tolist(), cols.tolist())) == [(2, 3), (2, 6), (7, 9)]
    assert torch.allclose(scores, torch.tensor([0.9, 0.7, 0.6]))
    assert len(P.heatmap_peaks(heat, max_peaks=2, threshold=0.05)[0]) == 2

    bev = GridSpec(x_range=(0.0, 4.8), y_range=(0.0, 4.0)).bev()      # 10 x 12 cells of 0.4 m
    offset = torch.zeros(3, 10, 12)
    offset[:2] = 0.2
    offset[2] = 0.75
    yaw = torch.zeros(N_BINS, 10, 12)
    yaw[N_BINS // 2] = 1.0                                           # bin 32 = yaw 0
    boxes = P.decode_boxes(bev, offset, yaw, rows, cols, np.array([3.9, 1.6, 1.5]))
    assert np.allclose(boxes[0], [3 * 0.4 + 0.2, 2 * 0.4 + 0.2, 0.75, 3.9, 1.6, 1.5, 0.0])
    assert np.allclose(boxes[1, :2], [6 * 0.4 + 0.2, 1.0])
    iou = bev_iou(boxes[:1], boxes[1:2])[0, 0]
    assert iou == pytest.approx((3.9 - 1.2) * 1.6 / ((3.9 + 1.2) * 1.6))     # shifted along the heading
    keep = P.nms_bev(boxes, scores.numpy(), iou_threshold=0.1)
    assert keep.tolist() == [0, 2]
    assert P.nms_bev(boxes, scores.numpy(), iou_threshold=0.6).tolist() == [0, 1, 2]
    size = torch.zeros(3, 10, 12)
    size[0] = math.log(1.1)
    sized = P.decode_boxes(bev, offset, yaw, rows, cols, np.array([3.9, 1.6, 1.5]), size)
    assert np.allclose(sized[0, 3:6], [3.9 * 1.1, 1.6, 1.5], atol=1e-5)


def test_camera_view_drops_boxes_behind_or_beside_the_camera():
    K = np.array([[243.5, 0, 207.5], [0, 243.5, 95.5], [0, 0, 1.0]])
    T_vehicle_camera = np.array([[0, 0, 1, 1.6], [-1, 0, 0, 0], [0, -1, 0, 1.65], [0, 0, 0, 1.0]])
    T_cam = np.linalg.inv(T_vehicle_camera)
    boxes = np.array([[15.0, 0.0, 0.75, 3.9, 1.6, 1.5, 0.0],      # ahead
                      [-10.0, 0.0, 0.75, 3.9, 1.6, 1.5, 0.0],     # behind
                      [3.0, 15.0, 0.75, 3.9, 1.6, 1.5, 0.0]])     # far to the left, outside the 81 deg view
    keep, bbox = P.camera_view(boxes, K, T_cam, (416, 192))
    assert keep.tolist() == [True, False, False]
    assert bbox[0, 3] - bbox[0, 1] > 20


# ------------------------------------------------------------------------------------- augmentation
def test_augmentation_keeps_points_and_targets_consistent(tmpl):
    box = np.array([[12.0, -3.0, 0.75, 3.9, 1.6, 1.5, 0.7]])
    lm = _left_rear_scan(tmpl, box[0, :3], box[0, 6])
    sweep = np.c_[lm, np.linspace(0, 1, len(lm))].astype(np.float32)
    for tf in (A.GlobalTransform(angle=0.4, flip=True, scale=1.05, translation=(0.3, -0.2, 0.1)),
               A.GlobalTransform(angle=-0.7), A.GlobalTransform(flip=True), A.GlobalTransform(scale=0.95)):
        b = tf.boxes(box)[0]
        p = tf.points(sweep)
        assert p.dtype == np.float32 and np.array_equal(p[:, 3], sweep[:, 3])      # reflectance untouched
        # the transformed points are the transformed box's scan: same coordinates in the box frame (x scale)
        local_before = _posed(lm - box[0, :3], (0, 0, 0), -box[0, 6])
        flip_y = np.diag([1.0, -1.0 if tf.flip else 1.0, 1.0])
        local_after = _posed(p[:, :3].astype(float) - b[:3], (0, 0, 0), -b[6])
        assert np.allclose(local_after, tf.scale * local_before @ flip_y, atol=1e-4)
        assert np.allclose(b[3:6], tf.scale * box[0, 3:6])
        # the SIC fit of the template at the transformed pose stays as good (up to the scale change)
        d = T.distance_to_template(tmpl, p[:, :3].astype(float), b[:3], b[6])
        assert np.median(d) < 0.05 + abs(tf.scale - 1) * 2
    # flip negates yaw, rotation adds, angles wrap to [-pi, pi)
    assert A.GlobalTransform(flip=True).boxes(box)[0, 6] == pytest.approx(-0.7)
    assert A.GlobalTransform(angle=3.0).boxes(box)[0, 6] == pytest.approx(3.7 - 2 * math.pi)
    rng = np.random.default_rng(0)
    spec = A.AugmentSpec()
    tfs = [A.sample_transform(rng, spec) for _ in range(200)]
    assert all(abs(t.angle) <= math.pi / 18 and 0.95 <= t.scale <= 1.05 for t in tfs)
    assert 60 < sum(t.flip for t in tfs) < 140


# -------------------------------------------------------------------------------------- the network
@pytest.mark.parametrize("x_range,y_range,stride", [((0.0, 6.4), (-2.8, 2.8), 2), ((0.0, 5.2), (-2.0, 2.4), 2),
                                                     ((0.0, 4.8), (0.0, 3.2), 1), ((0.0, 6.4), (0.0, 4.8), 4)])
def test_network_runs_with_batch_one_and_any_grid_size(x_range, y_range, stride):
    grid = GridSpec(x_range=x_range, y_range=y_range, pillar=0.4 / stride, stride=stride)
    torch.manual_seed(0)
    net = CenterDetector(grid, n_bins=N_BINS, predict_size=True, pillar_channels=4, channels=8, deep_channels=8)
    rng = np.random.default_rng(0)
    pts = np.c_[rng.uniform(x_range[0], x_range[1], 200), rng.uniform(y_range[0], y_range[1], 200),
                rng.uniform(0, 2, 200), rng.uniform(0, 1, 200)]
    pts[:5] += 100.0                                                  # outside the grid: dropped
    for mode in ("train", "eval"):
        getattr(net, mode)()
        out = net([torch.tensor(pts, dtype=torch.float32)])
        h, w = grid.out_height, grid.out_width
        assert out["heatmap"].shape == (1, 1, h, w) and out["offset"].shape == (1, 3, h, w)
        assert out["yaw"].shape == (1, N_BINS, h, w) and out["size"].shape == (1, 3, h, w)
        assert all(torch.isfinite(v).all() for v in out.values())
    net.eval()
    empty = net([torch.zeros((0, 4))])                                 # a sweep with no point in the grid
    assert torch.isfinite(empty["heatmap"]).all()
    # initial offsets point at the cell centre, at a car's centre height
    assert torch.allclose(empty["offset"][0, :, 0, 0], torch.tensor([grid.cell / 2, grid.cell / 2, 0.75]), atol=0.02)


# ------------------------------------------------------------------------------------------ bad input
def test_bad_masks_are_skipped_with_counts_and_the_loss_stays_finite(tmpl):
    grid = GridSpec(x_range=(0.0, 16.0), y_range=(-6.4, 6.4))
    bev = grid.bev()
    good = _left_rear_scan(tmpl, (8.0, 1.0, 0.75), 0.2)
    with_nan = good.copy()
    with_nan[::3] = np.nan
    sets = [[np.zeros((0, 3)), good[:1], with_nan], [good, np.array([[60.0, 0.0, 0.5]] * 4)]]
    objs = TG.weak_objects(sets, min_points=3, max_points=128, rng=np.random.default_rng(0))
    assert objs.n_skipped == 2 and objs.n_nonfinite == int(np.isnan(with_nan[:, 0]).sum())
    assert objs.frame.tolist() == [0, 1, 1]
    net = CenterDetector(grid, n_bins=N_BINS, pillar_channels=4, channels=8, deep_channels=8)
    sweep = torch.tensor(np.c_[good, np.full(len(good), 0.3)], dtype=torch.float32)
    sweep_nan = sweep.clone()
    sweep_nan[::5, 0] = float("nan")                                  # NaN LiDAR returns are ignored
    out = net([sweep_nan, sweep])
    assert all(torch.isfinite(v).all() for v in out.values())
    a = TG.assign_weak(bev, out, objs, window=2, loss_fn=SIC, template=tmpl)
    assert a.valid.tolist() == [True, True, False]                    # the last median is outside the grid
    terms = C.weak_alignment(out, bev, a, objs, SIC, tmpl)
    loss = terms["alignment"].mean() + terms["yaw_ce"].mean()
    loss.backward()
    assert torch.isfinite(loss) and all(torch.isfinite(p.grad).all() for p in net.parameters() if p.grad is not None)
    none = TG.weak_objects([[], [np.zeros((0, 3))]], 3, 128, np.random.default_rng(0))
    a = TG.assign_weak(bev, out, none, 1, SIC, tmpl)
    terms = C.weak_alignment(out, bev, a, none, SIC, tmpl)
    assert len(terms["alignment"]) == 0


# ------------------------------------------------------------------------- the cached split + training
def _scene(root, name="test_000", n_frames=2, nan_frame=1):
    """A hand-made scene: one car 12 m ahead, LiDAR on its left side and rear (+ ground), NaN returns in
    one sweep, three masks per frame: the car, an empty mask, a single-point mask."""
    from redsup.prep.masks_io import offsets_from_counts, pack_masks
    from redsup.sceneio import BOX_COLUMNS

    tmpl = T.build_template(T.TemplateSpec(voxel=0.15, margin=1.0))
    scene = root / name
    (scene / "gt").mkdir(parents=True)
    (scene / "lidar_top").mkdir()
    (scene / "scene.json").write_text(json.dumps({"scene": name, "n_frames": n_frames, "fps": 10,
                                                  "cameras": ["cam_front"], "lidars": ["lidar_top"]}))
    (scene / "cam_front.txt").write_text("243.5 0 207.5\n0 243.5 95.5\n0 0 1\n416 192\n")
    T_cam = np.array([[0, 0, 1, 1.6], [-1, 0, 0, 0], [0, -1, 0, 1.65], [0, 0, 0, 1.0]])
    T_lidar = np.eye(4)
    T_lidar[:3, 3] = [1.3, 0.0, 1.73]
    (scene / "extrinsics.json").write_text(json.dumps({"cam_front": T_cam.tolist(), "lidar_top": T_lidar.tolist()}))
    car = np.array([12.0, 2.0, 0.75, 3.9, 1.6, 1.5, 0.1])
    rows = [[f, 7, "car", *car[:6], car[6], 0, 0, 0, 0, 0.0, 150, 70, 230, 110, 2000, 300] for f in range(n_frames)]
    pd.DataFrame(rows, columns=BOX_COLUMNS).to_csv(scene / "gt" / "boxes.csv", index=False)
    scan = _left_rear_scan(tmpl, car[:3], car[6])
    ground = np.c_[np.random.default_rng(0).uniform(2, 30, (500, 2)) * [1, 0.3], np.zeros(500)]
    pts_v = np.r_[scan, ground]
    lidar = np.c_[pts_v - T_lidar[:3, 3], np.full(len(pts_v), 0.2)].astype(np.float32)
    pts_list, counts = [], []
    for f in range(n_frames):
        sweep = lidar.copy()
        if f == nan_frame:
            sweep[:7, 1] = np.nan
        sweep.tofile(scene / "lidar_top" / f"{f:06d}.bin")
        pts_list += [lidar[:len(scan)], lidar[:0], lidar[:1]]
        counts += [len(scan), 0, 1]
    masks = pack_masks([np.ones((192, 416), bool)] * (3 * n_frames), (416, 192))
    det = scene.parent / f"{name}_det.npz"
    np.savez(det, frame=np.repeat(np.arange(n_frames), 3).astype(np.int32),
             score=np.tile([0.9, 0.8, 0.7], n_frames).astype(np.float32), box=np.zeros((3 * n_frames, 4), np.float32),
             mask=masks, image_size=np.array([416, 192]), matched_track=np.tile([7, -1, -1], n_frames).astype(np.int32),
             points=np.concatenate(pts_list), point_offsets=offsets_from_counts(counts),
             box_points=np.zeros((0, 4), np.float32), box_point_offsets=offsets_from_counts([0] * 3 * n_frames),
             point_inlier_gt=np.ones(sum(counts), bool))
    return scene, det, car


def test_build_split_counts_bad_input_and_train_stays_finite(tmp_path, tmpl):
    from redsup.lidar_detector import data as D
    from redsup.lidar_detector.evaluate import evaluate_split
    from redsup.lidar_detector.train import RunSpec, TrainSpec, train

    scene, det, car = _scene(tmp_path)
    arrays, rep = D.build_split([scene], [det], (-1.0, 4.0), min_score=0.5, min_points=3)
    c = rep.counts
    assert (c["frames"], c["masks"], c["masks_used"], c["masks_no_points"], c["masks_few_points"]) == (2, 6, 2, 2, 2)
    assert c["lidar_nonfinite"] == 7 and c["sweeps_with_nonfinite"] == 1
    assert "2 skipped with no LiDAR point" in rep.message("test", 3)
    D.save_split(tmp_path / "split.npz", arrays)
    data = D.load_split(tmp_path / "split.npz")
    assert data.n_frames == 2 and len(data.objects(0)) == 1 and data.counts == c
    assert np.allclose(data.supervised_boxes(1, 3), [car])
    assert np.isfinite(data.points(1)).all() and len(data.points(1)) < len(data.points(0)) + 1
    grid = GridSpec(x_range=(0.0, 25.6), y_range=(-6.4, 6.4))
    net = {"pillar_channels": 4, "channels": 8, "deep_channels": 8}
    for run in (RunSpec(window=1), RunSpec(loss="l2", window=0), RunSpec(supervision="gt", size="predicted")):
        curves = []
        model, summary = train(data, run, grid, TrainSpec(steps=3, batch=2, log_every=1), A.AugmentSpec(), tmpl,
                               n_bins=16, net=net, seed=0, log=lambda m, s: curves.append(m))
        assert summary["train_steps_nonfinite"] == 0
        assert summary["train_objects_used"] + summary["train_objects_outside_grid"] == 6   # rotations move some out
        assert len(curves) == 3 and all(math.isfinite(v) for m in curves for v in m.values())
        metrics, dets = evaluate_split(model, data, grid, P.InferSpec(), tmpl.size, iou_thresholds=(0.7, 0.5))
        assert metrics["n_gt/moderate"] == 2 and metrics["frames"] == 2 and len(dets) == 2
        assert "Car_bev_0.7/moderate_R40" in metrics and "Car_3d_0.5/hard_R11" in metrics


# ------------------------------------------------------------------------------------------- tables
def _ld_config():
    ld = {"dataset": "world_kitti", "level": "cityscapes", "seeds": [0, 1],
          "eval": {"recall": "R40", "iou": [0.7, 0.5]},
          "runs": {"a": {}, "b": {}},
          "tables": {"mccraith_ch7_table1": {"moderate_label": "Moderate", "lifting_row": "McCraith et al. [2022] †",
                                             "rows": [{"label": "ours†", "run": "a"},
                                                      {"label": "CenterPoint † Yin et al. [2021]", "run": "b"}]},
                     "mccraith_ch7_table3": {"moderate_label": "Medium", "rows": [{"label": "0", "run": "a"}, {"label": "2", "run": "a"}]}}}
    return {"seed": 10, "profile": "tiny", "lidar_detector": ld,
            "lifting": {"seeds": [0, 1, 2], "full_method": "full", "runs": {"full": {}}}}


def _metrics(e, m, h):
    out = {}
    for d, v in zip(("easy", "moderate", "hard"), (e, m, h)):
        out |= {f"Car_bev_0.7/{d}_R40": v, f"Car_bev_0.7/{d}_R11": v + 1, f"Car_bev_0.5/{d}_R40": v + 10}
    return out | {"n_gt/easy": 30, "n_gt/moderate": 80, "n_gt/hard": 100, "frames": 90}


def test_tables_from_hand_made_metrics(tmp_path):
    from redsup.lidar_detector.tables import build_table, caption_note
    from redsup.tables import write_table

    ch6 = "McCraith et al. [2022] †"
    lifting = {"Car_bev_0.7/easy_R40": 40.0, "Car_bev_0.7/moderate_R40": 30.0, "Car_bev_0.7/hard_R40": 25.0}
    t1, noise = build_table("Moderate", {ch6: [lifting], "ours†": [_metrics(60, 50, 45), _metrics(62, 52, 47)],
                                         "CenterPoint † Yin et al. [2021]": [_metrics(80, 70, 65)],
                                         "CenterPoint Yin et al. [2021]": [_metrics(85, 75, 70)]})
    assert list(t1.columns[:3]) == ["AP_BEV Easy", "AP_BEV Moderate", "AP_BEV Hard"]
    # by hand: the mean of the two seeds (51 + 1 on R11, 46 + 10 at IoU 0.5), the record keeps both values
    assert t1.loc["ours†", "AP_BEV Moderate R11"] == 52 and t1.loc["ours†", "AP_BEV@0.5 Hard"] == 56
    assert noise["ours†"]["AP_BEV Moderate"] == {"kind": "seeds", "values": [50.0, 52.0]}
    # with each seed's bootstrap replicates over the test frames the record carries their replicate-wise mean
    key = "Car_bev_0.7/moderate_R40"
    seeds_b = [_metrics(60, 50, 45) | {"bootstrap": {"units": "u", "n_units": 90, "values": {key: [49.0, 51.0, 47.0]}}},
               _metrics(62, 52, 47) | {"bootstrap": {"units": "u", "n_units": 90, "values": {key: [53.0, 52.0, 50.0]}}}]
    _, noise_b = build_table("Moderate", {"ours†": seeds_b})
    assert noise_b["ours†"]["AP_BEV Moderate"]["boot"] == [51.0, 51.5, 48.5]
    assert "boot" not in noise_b["ours†"]["AP_BEV Easy"]                       # no replicates for that key
    assert math.isnan(t1.loc[ch6, "AP_BEV@0.5 Easy"])
    out = {k: tmp_path / f"t1.{k}" for k in ("md", "csv", "tex")}
    note = caption_note("default", _metrics(0, 0, 0), "R40", 3, 2)
    assert "fewer than 41 valid cars for easy" in note and "over 2 training seeds" in note
    score = write_table("mccraith_ch7_table1", t1, out["md"], out["csv"], out["tex"], note=note, noise=noise)
    assert score["rows_both"] == 4 and (tmp_path / "mccraith_ch7_table1.score.json").exists()
    t2, _ = build_table("Medium", {"||p - p'||^2": [_metrics(40, 30, 20)], "SIC_{5,0}": [_metrics(50, 40, 30)]})
    assert "AP_BEV Medium" in t2.columns and "AP_BEV Moderate" not in t2.columns


def test_plan_rows_read_the_lifting_full_method_and_share_runs():
    from redsup.lidar_detector import plan

    config = _ld_config()
    scenes = ["train_000", "train_001", "test_000", "long_000"]
    assert plan.split_scenes(scenes, "train") == ["train_000", "train_001", "long_000"]
    assert plan.split_scenes(scenes, "test") == ["test_000"]
    assert plan.split_scenes(scenes + ["val_000"], "val") == ["val_000"]     # knobs are chosen on it
    assert plan.split_inputs(config["lidar_detector"], scenes, "test") == {
        "scenes": ["results/raw/world_kitti/test_000"],
        "detections": ["results/prepared/world_kitti/test_000/detections_cityscapes.npz"]}
    assert sorted(plan.runs(config)) == ["a/seed0", "a/seed1", "b/seed0", "b/seed1"]
    assert plan.runs(config)["b/seed1"]["training_seed"] == 11
    rows = plan.rows(config)
    # Table 1's ch. 6 row: every seed of lifting.full_method, first; then this stage's rows per seed
    assert rows["mccraith_ch7_table1"][:4] == [("McCraith et al. [2022] †", f"lifting:full/seed{k}", None)
                                               for k in range(3)] + [("ours†", "a/seed0", None)]
    assert plan.result_path("lifting:full/seed2") == "results/lifting/metrics/full/seed2.json"
    assert plan.result_path("a/seed1") == "results/lidar_detector/metrics/a/seed1.json"
    assert rows["mccraith_ch7_table3"] == [("0", "a/seed0", None), ("0", "a/seed1", None),
                                           ("2", "a/seed0", None), ("2", "a/seed1", None)]
    assert plan.tables_of(config, "a/seed1") == ["mccraith_ch7_table1", "mccraith_ch7_table3"]   # shared run
    config["lifting"]["full_method"] = "other"
    with pytest.raises(ValueError, match="full_method"):
        plan.rows(config)
    config = _ld_config()
    config["lidar_detector"]["tables"]["mccraith_ch7_table3"]["rows"].append({"label": "1", "run": "c"})
    with pytest.raises(ValueError, match="unknown configurations"):
        plan.check_tables(config["lidar_detector"])


def test_table_frame_means_and_seed_records():
    from redsup.lidar_detector import plan

    config = _ld_config()
    rows = plan.rows(config)["mccraith_ch7_table1"]
    results = {run: _metrics(10 * i, 10 * i, 10 * i) for i, (_, run, _) in enumerate(rows)}
    frame = plan.table_frame("mccraith_ch7_table1", config, rows, results)
    assert list(frame.ours.index) == ["McCraith et al. [2022] †", "ours†", "CenterPoint † Yin et al. [2021]"]
    assert frame.ours.loc["McCraith et al. [2022] †", "AP_BEV Moderate"] == 10     # (0 + 10 + 20) / 3
    assert frame.noise["ours†"]["AP_BEV Hard"]["values"] == [30.0, 40.0]
    assert "lifting.full_method = full, 3 seeds" in frame.note
    frame3 = plan.table_frame("mccraith_ch7_table3", config, plan.rows(config)["mccraith_ch7_table3"],
                              {"a/seed0": _metrics(1, 2, 3), "a/seed1": _metrics(3, 4, 5)})
    assert frame3.ours.loc["2", "AP_BEV Medium"] == 3 and "lifting" not in frame3.note
    config["lidar_detector"]["tables"]["mccraith_ch7_table3"]["note"] = "why the rows stand where they do."
    frame3 = plan.table_frame("mccraith_ch7_table3", config, plan.rows(config)["mccraith_ch7_table3"],
                              {"a/seed0": _metrics(1, 2, 3), "a/seed1": _metrics(3, 4, 5)})
    assert frame3.note.endswith("; why the rows stand where they do")


@pytest.mark.parametrize("steps", [3, 20])
def test_one_cycle_adamw_matches_torch(steps):
    """The detector's optimiser is torch's AdamW + OneCycleLR (cycled beta1) without torch.optim, step by step,
    including a skipped (non-finite) step that advances only the schedule and a parameter without gradient."""
    from redsup.lidar_detector.optim import OneCycleAdamW

    torch.manual_seed(0)
    a, b = torch.nn.Linear(3, 2), torch.nn.Linear(3, 2)
    b.load_state_dict(a.state_dict())
    extra_a, extra_b = torch.nn.Parameter(torch.ones(2)), torch.nn.Parameter(torch.ones(2))
    mine = OneCycleAdamW(list(a.parameters()) + [extra_a], lr=3e-3, weight_decay=0.01, total_steps=steps,
                         pct_start=0.3, div_factor=10.0, final_div_factor=100.0)
    ref = torch.optim.AdamW(list(b.parameters()) + [extra_b], lr=3e-3, weight_decay=0.01)
    sched = torch.optim.lr_scheduler.OneCycleLR(ref, max_lr=3e-3, total_steps=steps, pct_start=0.3, div_factor=10.0,
                                                final_div_factor=100.0)
    x = torch.randn(5, 3)
    for step in range(steps):
        assert mine.lr == pytest.approx(sched.get_last_lr()[0], rel=1e-12)
        assert mine.beta1 == pytest.approx(ref.param_groups[0]["betas"][0], rel=1e-12)
        for net, opt in ((a, mine), (b, ref)):
            opt.zero_grad()
            (net(x) ** 2).sum().backward()
            if step != 1:                          # step 1: "non-finite", only the schedule moves
                opt.step()
        mine.schedule_step()
        sched.step()
        assert torch.allclose(a.weight, b.weight, atol=1e-7, rtol=1e-6) and torch.allclose(a.bias, b.bias, atol=1e-7)
    assert torch.equal(extra_a, extra_b)                                       # never had a gradient
    assert mine.lr == pytest.approx(sched.get_last_lr()[0], rel=1e-12)


def test_bev_image_puts_points_and_boxes_where_the_grid_says():
    from redsup.lidar_detector.figures import bev_image, bev_pixels

    grid = GridSpec(x_range=(0.0, 20.0), y_range=(-5.0, 5.0), pillar=0.5, stride=2)
    # 10 px/m: x 0..20 m -> columns 0..200, y +5..-5 m -> rows 0..100 (y up)
    assert np.allclose(bev_pixels([[0.0, 5.0], [20.0, -5.0], [3.0, 1.0]], grid, 10.0),
                       [[0, 0], [200, 100], [30, 40]])
    box = np.array([[10.0, 0.0, 0.0, 4.0, 2.0, 1.5, 0.0]])        # 4 x 2 m, facing +x, centre at (100, 50) px
    img = bev_image(np.array([[3.05, 1.05, 0.0]]), box, np.zeros((0, 7)), np.zeros(0), grid, "t")
    assert img.shape == (36 + 100, 200, 3) and img.dtype == np.uint8
    canvas = img[36:]
    assert tuple(canvas[39, 30]) == (150, 150, 150)                 # the point, grey
    assert canvas[40, 80:121, 1].min() < 200 and canvas[40, 80:121, 0].max() < 60   # the left side y=+1 m, green
    assert canvas[45:56, 100:120].min() < 200                        # centre-to-front line
    assert (canvas[20:30, 150:190] == 255).all()                     # nothing elsewhere
    faded = bev_image(np.zeros((0, 3)), np.zeros((0, 7)), box, np.array([0.15]), grid, "t")[36:]
    strong = bev_image(np.zeros((0, 3)), np.zeros((0, 7)), box, np.array([1.0]), grid, "t")[36:]
    assert strong[40, 80:121].sum() < faded[40, 80:121].sum()        # a low score draws paler


def test_values_at_cells_by_hand_and_a_contiguous_gradient():
    """_at_cells reads (N, C) from channel-first maps at (frame, row, col); a cell met twice gets both
    gradients; the gradient of the maps is contiguous (no channel-last copy in the backward)."""
    maps = torch.arange(2 * 3 * 2 * 4, dtype=torch.float32).reshape(2, 3, 2, 4).requires_grad_()
    frame, cells = torch.tensor([1, 0, 1]), torch.tensor([[0, 2], [1, 3], [0, 2]])
    got = C._at_cells(maps, frame, cells)
    # maps[f, c, r, k] = 24 f + 8 c + 4 r + k
    assert got.tolist() == [[26, 34, 42], [7, 15, 23], [26, 34, 42]]
    (grad,) = torch.autograd.grad((got * torch.tensor([[1.0], [2.0], [3.0]])).sum(), maps)
    assert grad.is_contiguous()
    assert grad[1, :, 0, 2].tolist() == [4.0, 4.0, 4.0] and grad[0, :, 1, 3].tolist() == [2.0, 2.0, 2.0]
    assert grad.sum().item() == 3 * (1 + 2 + 3)
