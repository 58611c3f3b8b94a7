"""The lifting stage's library (McCraith ch. 6): object frames, network, criterion composition, batching with
the bad-input rules, post-processing and tables. Hand-computed cases."""
import math

import numpy as np
import pytest
import torch

from redsup.det3d import losses as L
from redsup.det3d import template as T
from redsup.det3d.kitti_pixels import kitti_pixel_scale, scale_frames
from redsup.det3d.kitti_types import FrameDet, FrameGT
from redsup.lifting import data as D
from redsup.lifting import frames as F
from redsup.lifting.criterion import (AlignmentAtBestBin, AlignmentOverHypotheses, MultiViewConsistency,
                                      OutlierAwarePointLoss, SquaredPointLoss, build_criterion)
from redsup.lifting.model import BinYawHead, LiftingNet
from redsup.lifting.postprocess import frame_detections, predict_boxes
from redsup.lifting.tables import gt_count_note, seed_table, table_columns

K = 64
LOSS_CFG = {"hypothesis_temperature": 0.1, "supervised_beta": 0.1, "weights": {}}


@pytest.fixture(scope="module")
def tmpl():
    return T.build_template(T.TemplateSpec(voxel=0.1, margin=1.0))


def _rot(yaw):
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _scan(tmpl, faces, yaw, centre):
    """Template surface points on the visible faces ("left" y = +w/2, "rear" x = -l/2), posed."""
    p = tmpl.points
    half = tmpl.size / 2
    keep = np.zeros(len(p), dtype=bool)
    if "left" in faces:
        keep |= np.isclose(p[:, 1], half[1]) & (p[:, 2] < 0.0)
    if "rear" in faces:
        keep |= np.isclose(p[:, 0], -half[0]) & (p[:, 2] < 0.0)
    local = p[keep][::3]
    return local @ _rot(yaw).T + np.asarray(centre)


def _circ(a, b, n=K):
    d = abs(int(a) - int(b)) % n
    return min(d, n - d)


def _batch_of(points, translation=None):
    """One-object batch in its object frame (pseudo-centre + azimuth) and the translation there."""
    c = F.pseudo_centre(points)
    az = float(F.azimuth_of(c))
    local = F.to_local(points[None], c[None], np.array([az]))[0]
    b = D.Batch(points=torch.tensor(local[None], dtype=torch.float32),
                mask=torch.ones(1, len(points), dtype=torch.bool),
                centre=torch.tensor(c[None], dtype=torch.float32), azimuth=torch.tensor([az], dtype=torch.float32))
    t_local = None
    if translation is not None:
        t_local = F.to_local(np.asarray(translation)[None, None], c[None], np.array([az]))[0, 0]
    return b, az, t_local


# ------------------------------------------------------------------------------------------------ frames
def test_frames_round_trip_and_azimuth():
    c = np.array([10.0, 10.0, 0.5])
    assert F.azimuth_of(c) == pytest.approx(math.pi / 4)
    pts = np.array([[[11.0, 10.0, 0.5], [10.0, 12.0, 1.0]]])
    local = F.to_local(pts, c[None], np.array([math.pi / 4]))
    # +x of the object frame points away from the sensor along the ray through c
    assert np.allclose(local[0, 0], [math.sqrt(0.5), -math.sqrt(0.5), 0.0])
    t_v, yaw_v = F.to_vehicle(torch.tensor([[1.0, 2.0, 0.1]]), torch.tensor([0.3]), torch.tensor(c[None]),
                              torch.tensor([math.pi / 4]))
    t_l, yaw_l = F.pose_to_local(t_v.numpy(), yaw_v.numpy(), c[None], np.array([math.pi / 4]))
    assert np.allclose(t_l, [[1.0, 2.0, 0.1]], atol=1e-6) and np.allclose(yaw_l, [0.3])
    assert F.wrap_angle(np.array([math.pi, -math.pi, 3 * math.pi / 2]))[2] == pytest.approx(-math.pi / 2)


# ------------------------------------------------------------------------------------------------ network
def test_network_batch_one_and_variable_point_counts():
    torch.manual_seed(0)
    net = LiftingNet({"kind": "bins", "n_bins": K}, point_widths=(8, 16), head_widths=(16,), variance_widths=(8,))
    one = torch.randn(1, 1, 3)
    out = net(one, torch.ones(1, 1, dtype=torch.bool))
    assert out["translation"].shape == (1, 3) and out["yaw_logits"].shape == (1, K) and out["log_var"].shape == (1, 1)
    # padding never changes an object's outputs (masked max-pool), whatever it holds
    a, b = torch.randn(5, 3), torch.randn(2, 3)
    pts = torch.zeros(2, 5, 3)
    pts[0], pts[1, :2] = a, b
    pts[1, 2:] = 1e3
    mask = torch.tensor([[True] * 5, [True, True, False, False, False]])
    batched = net(pts, mask)
    alone = net(b[None], torch.ones(1, 2, dtype=torch.bool))
    assert torch.allclose(batched["translation"][1], alone["translation"][0], atol=1e-6)
    assert torch.allclose(batched["yaw_logits"][1], alone["yaw_logits"][0], atol=1e-6)
    assert torch.allclose(batched["log_var"][1, :2], alone["log_var"][0], atol=1e-6)
    lo, hi = net.log_var_min, net.log_var_max
    assert ((batched["log_var"] >= lo) & (batched["log_var"] <= hi)).all()


def test_yaw_heads_decode():
    head = BinYawHead(4, 8)
    logits = torch.full((1, 8), -30.0)
    logits[0, 6] = 30.0
    assert head.decode({"yaw_logits": logits}).item() == pytest.approx(-math.pi + 2 * math.pi * 6 / 8)
    assert torch.allclose(head.direction({"yaw_logits": logits}), torch.tensor([[0.0, 1.0]]), atol=1e-6)
    even = torch.full((1, 8), -30.0)
    even[0, [2, 6]] = 30.0                                           # torn between a heading and its reverse
    assert head.direction({"yaw_logits": even}).norm().item() < 1e-6
    net = LiftingNet({"kind": "vector"}, point_widths=(8, 8), head_widths=(8,), variance_widths=(8,))
    # yaw = atan2(x1, x2)
    assert net.yaw.decode({"yaw_vector": torch.tensor([[1.0, 0.0]])}).item() == pytest.approx(math.pi / 2)


# ------------------------------------------------------------------------------------------------ criterion
def test_best_bin_target_on_synthetic_scan(tmpl):
    """An L-shaped scan (left side + rear) of the template at a known pose: the cross-entropy target is the
    bin of the true object-frame yaw (up to the template's near 180-degree symmetry) and the translation
    gets a gradient while the yaw logits get only the cross-entropy."""
    yaw, centre = 0.7, np.array([12.0, -3.0, 0.8])
    pts = _scan(tmpl, ("left", "rear"), yaw, centre)
    b, az, t_local = _batch_of(pts, centre)
    true_bin = int(L.yaw_to_bin(torch.tensor(yaw - az), K))
    term = AlignmentAtBestBin(SquaredPointLoss(), tmpl, BinYawHead(4, K))
    t = torch.tensor(t_local[None], dtype=torch.float32, requires_grad=True)
    logits = torch.zeros(1, K, requires_grad=True)
    out = {"translation": t, "yaw_logits": logits, "log_var": torch.zeros(1, len(pts))}
    best, per_bin = L.best_yaw_bin(b.points, t.detach(), K, lambda d: d * d, tmpl, b.mask)
    assert min(_circ(best, true_bin), _circ(best, true_bin + K // 2)) <= 1
    parts = term(out, b)
    assert parts["align"].item() < 0.01                           # on the surface: ~0 at the best bin
    assert parts["yaw"].item() == pytest.approx(math.log(K), rel=1e-5)   # uniform logits: CE = log K
    (parts["align"] + parts["yaw"]).backward()
    g = logits.grad[0]
    assert g[best].item() == pytest.approx(1 / K - 1, abs=1e-6)   # d CE / d logit of the target bin
    assert t.grad is not None and torch.isfinite(t.grad).all()
    # a translation 0.5 m off costs more at the best bin, and its gradient points back
    t2 = torch.tensor(t_local[None] + [[0.5, 0.0, 0.0]], dtype=torch.float32, requires_grad=True)
    parts2 = term({"translation": t2, "yaw_logits": torch.zeros(1, K), "log_var": out["log_var"]}, b)
    parts2["align"].backward()
    assert parts2["align"].item() > 0.05 and t2.grad[0, 0].item() > 0


def test_outlier_aware_loss_discounts_a_far_outlier(tmpl):
    """Inliers on the surface plus one point 4 m out: the squared loss moves its optimum towards the
    outlier, the outlier-aware loss (sigma 0.05 m on inliers, 4 m on the outlier) does not. By hand, with n
    inliers on the left side, L2 = n dy^2 + (4 - dy)^2 is minimal at dy = 4 / (n + 1) (0.19 m for n = 20)."""
    pts = _scan(tmpl, ("left",), 0.0, np.zeros(3))
    pts = pts[(pts[:, 2] > -0.45) & (pts[:, 2] < -0.25) & (np.abs(pts[:, 0]) < 1.5)]   # side stays the nearest face
    pts = pts[np.random.default_rng(0).choice(len(pts), 20, replace=False)]
    outlier = np.array([[0.0, 0.8 + 4.0, -0.3]])
    allp = torch.tensor(np.vstack([pts, outlier]), dtype=torch.float32)
    n = len(allp)
    log_var = torch.full((1, n), math.log(0.05 ** 2))
    log_var[0, -1] = math.log(4.0 ** 2)
    out = {"log_var": log_var}
    # by hand: the outlier's per-point cost is d^2 / 16 + log 16 = 1 + 2.7726 (vs d^2 = 16)
    d_out = T.distance_to_template(tmpl, allp[-1:], torch.zeros(3), torch.tensor(0.0))
    assert d_out.item() == pytest.approx(4.0, abs=0.06)
    assert OutlierAwarePointLoss()(torch.tensor([[4.0]]), {"log_var": torch.tensor([[math.log(16.0)]])}).item() \
        == pytest.approx(1 + math.log(16.0))
    offsets = torch.linspace(-0.2, 0.3, 51)
    res = {}
    for name, loss in (("squared", SquaredPointLoss()), ("outlier_aware", OutlierAwarePointLoss())):
        vals = []
        for dy in offsets:
            d = T.distance_to_template(tmpl, allp[None], torch.tensor([[0.0, float(dy), 0.0]]), torch.tensor([0.0]))
            vals.append(loss(d, out).mean().item())
        res[name] = offsets[int(np.argmin(vals))].item()
    assert res["squared"] == pytest.approx(4 / 21, abs=0.02)    # pulled towards the outlier (+y)
    assert abs(res["outlier_aware"]) < 0.03      # stays on the inliers


def test_multiview_consistency_zero_for_consistent_pair_under_ego_motion(tmpl):
    """A parked car seen from two ego poses: predictions that agree after the known ego-motion cost 0;
    shifting one prediction by 0.5 m costs 2 keypoints x 0.25 m^2 (one pair, divided by the batch of 2)."""
    bins = yaw_bins = L.yaw_bin_centers(K, dtype=torch.float64)  # noqa: F841
    car_world = np.array([20.0, 5.0, 0.8])
    car_yaw_world = 0.4
    ego_i = np.eye(4)
    ego_j = np.eye(4)
    ego_j[:3, :3] = _rot(2 * math.pi * 3 / K)                     # ego turned 3 bins and moved
    ego_j[:3, 3] = [6.0, 1.0, 0.1]
    poses = [ego_i, ego_j]
    t_v, yaw_v = [], []
    for P in poses:
        inv = np.linalg.inv(P)
        t_v.append(inv[:3, :3] @ car_world + inv[:3, 3])
        yaw_v.append(car_yaw_world - math.atan2(P[1, 0], P[0, 0]))
    # object frames whose local yaw is exactly a bin centre (so the one-hot soft yaw reproduces it)
    k_local = [10, 17]
    az = [yaw_v[m] - float(yaw_bins[k_local[m]]) for m in range(2)]
    centre = [np.array([15 * math.cos(a), 15 * math.sin(a), 0.5]) for a in az]
    t_local = [F.pose_to_local(t_v[m], 0.0, centre[m], az[m])[0] for m in range(2)]
    logits = torch.full((2, K), -50.0, dtype=torch.float64)
    for m in range(2):
        logits[m, k_local[m]] = 50.0
    T_i_from_j = torch.tensor(np.linalg.solve(poses[0], poses[1])[None])
    b = D.Batch(points=torch.zeros(2, 1, 3, dtype=torch.float64), mask=torch.ones(2, 1, dtype=torch.bool),
                centre=torch.tensor(np.array(centre)), azimuth=torch.tensor(az, dtype=torch.float64),
                pairs=(torch.tensor([0]), torch.tensor([1]), T_i_from_j))
    term = MultiViewConsistency(BinYawHead(4, K), tmpl.spec.length)
    out = {"translation": torch.tensor(np.array(t_local)), "yaw_logits": logits}
    assert term(out, b)["multiview"].item() == pytest.approx(0.0, abs=1e-9)
    moved = out["translation"].clone()
    moved[1] += torch.tensor(F.rotate_z(np.array([0.0, 0.5, 0.0]), -az[1]))   # 0.5 m left in frame j
    assert term({**out, "translation": moved}, b)["multiview"].item() == pytest.approx(2 * 0.25 / 2, rel=1e-6)
    # a 180-degree heading flip in frame j moves the front keypoint by a full car length
    flipped = logits.clone()
    flipped[1] = -50.0
    flipped[1, (k_local[1] + K // 2) % K] = 50.0
    val = term({**out, "yaw_logits": flipped}, b)["multiview"].item()
    assert val == pytest.approx(tmpl.spec.length ** 2 / 2, rel=1e-4)
    # for a confident head it is eq. (7) with the posed centre / front keypoints of redsup.det3d.losses
    t_v2, yaw_v2 = F.to_vehicle(moved, bins[torch.tensor(k_local)], b.centre, b.azimuth)
    ref = L.multiframe_consistency(t_v2[0], yaw_v2[0], t_v2[1], yaw_v2[1], T_i_from_j[0],
                                   L.centre_front_keypoints(tmpl.spec.length, dtype=torch.float64))
    assert term({**out, "translation": moved}, b)["multiview"].item() == pytest.approx(ref.sum().item() / 2, rel=1e-6)


def test_hypotheses_min_trains_only_the_best_candidate(tmpl):
    pts = _scan(tmpl, ("left", "rear"), 0.3, np.array([10.0, 0.0, 0.8]))
    b, az, t_local = _batch_of(pts, [10.0, 0.0, 0.8])
    from redsup.lifting.model import HypothesisYawHead

    head = HypothesisYawHead(4, 3)
    yaw_true = 0.3 - az
    cands = [yaw_true, yaw_true + 1.2, yaw_true - 2.0]
    vec = torch.tensor([[[math.sin(c), math.cos(c)] for c in cands]], requires_grad=True)
    out = {"translation": torch.tensor(t_local[None], dtype=torch.float32), "yaw_vectors": vec,
           "yaw_select": torch.zeros(1, 3, requires_grad=True), "log_var": torch.zeros(1, len(pts))}
    parts = AlignmentOverHypotheses(SquaredPointLoss(), tmpl, head, "min")(out, b)
    (parts["align"] + parts["yaw"]).backward()
    assert parts["align"].item() < 0.01
    assert vec.grad[0, 1:].abs().max().item() == 0.0               # winner takes all
    assert out["yaw_select"].grad[0, 0].item() < 0                  # the selector learns to pick candidate 0
    soft = AlignmentOverHypotheses(SquaredPointLoss(), tmpl, head, "soft", temperature=0.1)(out, b)
    assert soft["align"].item() >= parts["align"].item() - 1e-6


def test_build_criterion_composes_the_listed_terms(tmpl):
    net = LiftingNet({"kind": "bins", "n_bins": K}, point_widths=(8, 8), head_widths=(8,), variance_widths=(8,))
    spec = {"terms": ["alignment", "multiview"], "point_loss": "outlier_aware", "yaw": {"kind": "bins", "n_bins": K}}
    crit = build_criterion(spec, LOSS_CFG, tmpl, net.yaw)
    assert list(crit.terms) == ["alignment", "multiview"]
    assert isinstance(crit.terms["alignment"].point_loss, OutlierAwarePointLoss)
    only = build_criterion({**spec, "terms": ["alignment"], "point_loss": "squared"}, LOSS_CFG, tmpl, net.yaw)
    assert list(only.terms) == ["alignment"]
    with pytest.raises(ValueError, match="unknown loss term"):
        build_criterion({**spec, "terms": ["chamfer"]}, LOSS_CFG, tmpl, net.yaw)
    vec = LiftingNet({"kind": "vector"}, point_widths=(8, 8), head_widths=(8,), variance_widths=(8,))
    with pytest.raises(ValueError, match="yaw-bin head"):
        build_criterion({**spec, "terms": ["supervised_box"], "yaw": {"kind": "vector"}}, LOSS_CFG, tmpl, vec.yaw)
    # the total is the weighted sum of the components
    pts = torch.randn(3, 6, 3)
    b = D.Batch(pts, torch.ones(3, 6, dtype=torch.bool), torch.tensor([[10.0, 0, 0.5]] * 3), torch.zeros(3),
                pairs=(torch.tensor([0]), torch.tensor([1]), torch.eye(4)[None]))
    out = net(pts, b.mask)
    total, parts = crit(out, b)
    weighted = build_criterion(spec, {**LOSS_CFG, "weights": {"multiview": 2.0}}, tmpl, net.yaw)(out, b)[0]
    assert total.item() == pytest.approx(sum(v for k, v in parts.items() if k != "total"), rel=1e-5)
    assert weighted.item() == pytest.approx(total.item() + parts["multiview/multiview"], rel=1e-5)


# ------------------------------------------------------------------------------------------------ data
def _raw(sets, frames, tracks, scores=None, target=None):
    n = len(sets)
    return D.RawObjects(sets=sets, frame=np.asarray(frames), detection=np.arange(n), track=np.asarray(tracks),
                        score=np.ones(n) if scores is None else np.asarray(scores), bbox=np.zeros((n, 4)),
                        target=target)


def test_bad_input_is_skipped_with_counts_and_no_nan_loss(tmpl):
    rng = np.random.default_rng(0)
    good = rng.normal([10, 2, 0.5], 0.5, size=(20, 3))
    with_nan = good.copy()
    with_nan[3] = np.nan
    sets = [good, np.zeros((0, 3)), good[:1], with_nan, good[:5]]
    table = D.build_table([_raw(sets, [0, 1, 2, 3, 4], [-1] * 5, scores=[0.9, 0.9, 0.9, 0.9, 0.1])],
                          [np.tile(np.eye(4), (5, 1, 1))], min_points=2, max_points=8, rng=rng, min_score=0.5)
    assert len(table) == 2 and table.detection.tolist() == [0, 3]
    c = table.counts
    got = (c["skipped_no_points"], c["skipped_few_points"], c["nonfinite_points"], c["skipped_low_score"])
    assert got == (1, 2, 1, 1)
    assert "2 objects kept of 5" in table.message() and "1 non-finite" in table.message()
    assert table.mask.sum(1).tolist() == [8, 8]                    # subsampled to max_points
    assert torch.isfinite(table.points).all()
    net = LiftingNet({"kind": "bins", "n_bins": 16}, point_widths=(8, 8), head_widths=(8,), variance_widths=(8,))
    spec = {"terms": ["alignment", "multiview"], "point_loss": "outlier_aware", "yaw": {"kind": "bins", "n_bins": 16}}
    crit = build_criterion(spec, LOSS_CFG, tmpl, net.yaw)
    total, _ = crit(net(table.points, table.mask), table.batch([0, 1], span=4))
    assert torch.isfinite(total)
    empty = D.build_table([_raw([np.zeros((0, 3))], [0], [-1])], [np.eye(4)[None]], 2, None, rng)
    assert len(empty) == 0 and empty.counts["skipped_no_points"] == 1


def test_windows_and_pairs_follow_tracks_and_ego_motion():
    rng = np.random.default_rng(1)
    sets = [rng.normal([10, 0, 0.5], 0.3, size=(6, 3)) for _ in range(8)]
    poses = np.tile(np.eye(4), (8, 1, 1))
    poses[:, 0, 3] = np.arange(8) * 1.5                             # ego drives 1.5 m per frame along x
    # track 5 over frames 0..5, track 9 on frames 1, 2; one untracked
    raw = _raw(sets, [0, 1, 2, 3, 4, 5, 1, 2], [5, 5, 5, 5, 5, 5, 9, 9])
    raw.track[7] = -1
    table = D.build_table([raw], [poses], 2, None, rng)
    wins = table.windows(span=2)
    assert sorted(len(w) for w in wins) == [1, 1, 3, 3]
    i, j, T = table.pairs(np.arange(8), span=2)
    got = {(int(a), int(b)) for a, b in zip(i, j)}
    assert got == {(0, 1), (0, 2), (1, 2), (1, 3), (2, 3), (2, 4), (3, 4), (3, 5), (4, 5)}
    k = [n for n, (a, b) in enumerate(zip(i, j)) if (int(a), int(b)) == (0, 2)][0]
    assert np.allclose(T[k].numpy()[:3, 3], [3.0, 0.0, 0.0])        # frame-2 coordinates seen from frame 0
    batches = table.epoch_batches(3, 2, np.random.default_rng(0))
    assert sorted(np.concatenate(batches).tolist()) == list(range(8))


# ------------------------------------------------------------------------------------------------ outputs
def test_predict_boxes_use_template_size_and_mask_scores(tmpl):
    rng = np.random.default_rng(2)
    raw = _raw([rng.normal([10, 3, 0.5], 0.3, size=(10, 3)) for _ in range(3)], [0, 0, 2], [-1] * 3,
               scores=[0.9, 0.4, 0.7])
    table = D.build_table([raw], [np.tile(np.eye(4), (3, 1, 1))], 2, None, rng)
    net = LiftingNet({"kind": "bins", "n_bins": 16}, point_widths=(8, 8), head_widths=(8,), variance_widths=(8,))
    boxes = predict_boxes(net, table, tmpl.size)
    assert boxes.shape == (3, 7) and np.allclose(boxes[:, 3:6], [3.9, 1.6, 1.5])
    assert np.all(np.abs(boxes[:, 6]) <= math.pi)
    dets = frame_detections(table, boxes, 0, 3)
    assert [len(d.score) for d in dets] == [2, 0, 1] and dets[0].score.tolist() == [0.9, 0.4]


def test_kitti_pixel_scale():
    K_ = np.array([[243.5, 0, 208], [0, 243.5, 96], [0, 0, 1]])
    s = kitti_pixel_scale(K_)
    assert s == pytest.approx(721.5377 / 243.5)
    g = FrameGT(np.zeros((1, 7)), np.array([[10.0, 20.0, 30.0, 40.0]]), np.zeros(1), np.zeros(1), np.array(["Car"]))
    d = FrameDet(np.zeros((1, 7)), np.array([[1.0, 2.0, 3.0, 4.0]]), np.ones(1))
    sg, sd = scale_frames([g, d], 2.0)
    assert np.allclose(sg.bbox, [[20, 40, 60, 80]]) and np.allclose(sd.bbox, [[2, 4, 6, 8]])
    assert np.allclose(g.bbox, [[10, 20, 30, 40]])                  # inputs untouched


def _metrics(base_bev=10, base_3d=20):
    return {f"Car_{k}_0.5/{d}_{r}": v for k, base in (("bev", base_bev), ("3d", base_3d)) for d, v0 in
            zip(("easy", "moderate", "hard"), (1, 2, 3)) for r, v in (("R40", base + v0), ("R11", base + v0 + 0.5))}


def test_tables_from_metrics_average_the_seeds():
    m = _metrics()
    cols = table_columns(m)
    assert cols["AP_BEV Moderate"] == 12 and cols["AP_3D Hard"] == 23 and cols["AP_BEV Easy (R11)"] == 11.5
    results = {"r1/seed0": m, "r1/seed1": _metrics(14, 20), "r2/seed0": m, "r2/seed1": m}
    rows = [("(a) x", "r1/seed0", None), ("(a) x", "r1/seed1", None), ("(b) y", "r2/seed0", None),
            ("(b) y", "r2/seed1", None)]
    df, noise = seed_table(rows, results)
    assert list(df.index) == ["(a) x", "(b) y"] and df.loc["(b) y", "AP_3D Easy"] == 21
    # by hand: BEV moderate 12 and 16 over the two seeds -> mean 14, the record keeps both values
    assert df.loc["(a) x", "AP_BEV Moderate"] == 14
    assert noise["(a) x"]["AP_BEV Moderate"] == {"kind": "seeds", "values": [12.0, 16.0]}
    assert noise["(b) y"]["AP_3D Easy"]["values"] == [21.0, 21.0]
    with pytest.raises(KeyError, match="r3"):
        seed_table([("(c)", "r3/seed0", None)], {"r1/seed0": m})
    # runs that stored bootstrap replicates of their AP over the same test frames: the seed mean's replicates
    # are the seeds' replicate-wise means (12 / 13 and 16 / 18 -> 14 / 15.5), the diagnostic columns keep seeds only
    key = "Car_bev_0.5/moderate_R40"
    boot = {"r1/seed0": {"units": "f", "n_units": 9, "values": {key: [12.0, 13.0]}},
            "r1/seed1": {"units": "f", "n_units": 9, "values": {key: [16.0, 18.0]}}}
    booted = {r: dict(v, bootstrap=boot[r]) if r in boot else v for r, v in results.items()}
    _, noise2 = seed_table(rows, booted)
    rec = noise2["(a) x"]["AP_BEV Moderate"]
    assert rec["values"] == [12.0, 16.0] and rec["boot"] == [14.0, 15.5] and rec["units"] == "f"
    assert "boot" not in noise2["(a) x"]["AP_3D Moderate"] and "boot" not in noise2["(b) y"]["AP_BEV Moderate"]
    assert "fewer than 41 in easy" in gt_count_note({"r": {"n_gt/easy": 9, "n_gt/moderate": 50, "n_gt/hard": 90}})


def _plan_config():
    spec = {"points": "mask", "level": "coco", "point_loss": "outlier_aware", "terms": ["alignment", "multiview"],
            "yaw": {"kind": "bins", "n_bins": 64}, "targets": "none"}
    lift = {"dataset": "w", "train_splits": ["train", "long"], "test_split": "test", "seeds": [0, 1, 2],
            "eval": {"table_iou": 0.5},
            "runs": {"a": spec,
                     "b": {"points": "mask", "level": "cityscapes", "point_loss": "squared",
                           "terms": ["supervised_box"], "yaw": {"kind": "bins", "n_bins": 64}, "targets": "labels", "labels_from": "a"}},
            "tables": {"t1": {"rows": [{"label": "(x)", "run": "a"}, {"label": "(y)", "run": "b"}], "note": "N1"},
                       "t2": {"rows": [{"label": "(z)", "run": "a"}]}},
            "full_method": "a"}
    return {"seed": 100, "profile": "tiny", "lifting": lift}


def test_plan_runs_rows_and_inputs_per_seed():
    from redsup.lifting import plan
    from redsup.lifting.tables import row_summary

    config = _plan_config()
    cfg = config["lifting"]
    assert sorted(plan.runs(config)) == ["a/seed0", "a/seed1", "a/seed2", "b/seed0", "b/seed1", "b/seed2"]
    assert plan.runs(config)["b/seed2"]["training_seed"] == 102
    rows = plan.rows(config)
    assert rows["t1"] == [("(x)", "a/seed0", None), ("(x)", "a/seed1", None), ("(x)", "a/seed2", None),
                          ("(y)", "b/seed0", None), ("(y)", "b/seed1", None), ("(y)", "b/seed2", None)]
    # a run shared by two tables is listed in both tables' rows (and both are its tables)
    assert ("(z)", "a/seed1", None) in rows["t2"] and plan.tables_of(config, "a/seed1") == ["t1", "t2"]
    assert plan.tables_of(config, "b/seed0") == ["t1"] and plan.tables_of_labels(config, "a/seed0") == ["t1"]
    assert plan.result_path("b/seed2") == "results/lifting/metrics/b/seed2.json"
    assert plan.parse_run("bins16_coco/seed10") == ("bins16_coco", 10)
    with pytest.raises(ValueError, match="seed"):
        plan.parse_run("a")
    assert plan.full_method_runs(config) == ["a/seed0", "a/seed1", "a/seed2"]
    scenes = ["train_000", "train_001", "test_000", "long_000"]
    inp = plan.run_inputs(cfg, scenes, "b", 1)
    assert inp["train_scenes"] == ["results/raw/w/train_000", "results/raw/w/train_001", "results/raw/w/long_000"]
    assert inp["test_detections"] == ["results/prepared/w/test_000/detections_cityscapes.npz"]
    assert "test_tracks" not in inp and inp["labels"] == "results/lifting/labels/a/seed1.npz"   # same seed's labels
    assert "labels" not in plan.run_inputs(cfg, scenes, "a", 0)
    assert plan.labels_inputs(cfg, scenes, "a", 2)["model"] == "results/lifting/models/a/seed2.pt"
    bad = {**cfg, "runs": {**cfg["runs"], "b": {**cfg["runs"]["b"], "labels_from": "nope"}}}
    with pytest.raises(ValueError, match="labels_from"):
        plan.run_inputs(bad, scenes, "b", 0)
    with pytest.raises(ValueError, match="unknown configurations"):
        plan.rows({**config, "lifting": {**cfg, "tables": {"t": {"rows": [{"label": "(q)", "run": "nope"}]}}}})
    text = row_summary([(r["label"], r["run"]) for r in cfg["tables"]["t1"]["rows"]], cfg["runs"])
    assert "(x) = a (mask points, coco detector, outlier_aware, alignment+multiview, 64 bins)" in text
    assert "(y) = b (mask points, cityscapes detector, supervised by labels, 64 bins)" in text


def test_table_frame_from_config_section():
    from redsup.lifting import plan

    config = _plan_config()
    rows = plan.rows(config)["t1"]
    results = {run: _metrics(10 + i) | {"diag/bev_centre_within_1m": 0.5, "diag/yaw_within_20deg_mod_pi": 0.25}
               for i, (_, run, _) in enumerate(rows)}
    frame = plan.table_frame("t1", config, rows, results)
    # (x) = a/seed0..2 with BEV bases 10, 11, 12 -> moderate 12, 13, 14: mean 13
    assert frame.ours.loc["(x)", "AP_BEV Moderate"] == 13
    assert frame.noise["(x)"]["AP_BEV Moderate"]["values"] == [12.0, 13.0, 14.0]
    assert frame.ours.loc["(y)", "centre < 1 m (%)"] == 50 and frame.ours.loc["(y)", "yaw < 20° (%)"] == 25
    assert frame.ours.loc["(y)", "AP_BEV Easy"] == 15                       # bases 13, 14, 15 (+1 for easy)
    assert "N1" in frame.note and "3 training seeds (100, 101, 102)" in frame.note


def test_adam_matches_torch_and_step_decay(tmpl):
    from redsup.lifting.train import Adam, clip_grad_norm  # Adam: redsup.optim (tests/test_optim.py)

    torch.manual_seed(0)
    a = torch.nn.Linear(3, 2)
    b = torch.nn.Linear(3, 2)
    b.load_state_dict(a.state_dict())
    mine, ref = Adam(a.parameters(), lr=3e-3), torch.optim.Adam(b.parameters(), lr=3e-3)
    x = torch.randn(5, 3)
    for _ in range(4):
        for net, opt in ((a, mine), (b, ref)):
            opt.zero_grad()
            (net(x) ** 2).sum().backward()
            opt.step()
    assert torch.allclose(a.weight, b.weight, atol=1e-7) and torch.allclose(a.bias, b.bias, atol=1e-7)
    p = torch.nn.Parameter(torch.zeros(2))
    p.grad = torch.tensor([3.0, 4.0])
    assert clip_grad_norm([p], 1.0) == pytest.approx(5.0)
    assert torch.allclose(p.grad, torch.tensor([0.6, 0.8]), atol=1e-5)


def test_checkpoint_round_trip_keeps_the_resolved_config(tmp_path):
    from redsup import checkpoint
    from redsup.lifting.model import build_model
    from redsup.lifting.pipeline import load_model, save_model

    yaw = {"kind": "bins", "n_bins": 8}
    network = {"point_mlp": [8], "head_mlp": [8], "variance_mlp": [8], "sigma_min": 0.05, "sigma_max": 3.0,
               "position_input": False}
    torch.manual_seed(0)
    model = build_model(network, yaw)
    config = {"seed": 7, "lifting": {"network": network}}
    path = tmp_path / "m.pt"
    save_model(model, {"yaw": yaw}, config, path, {"configuration": "x", "seed": 7})
    ckpt = checkpoint.load(path, "lifting")
    assert ckpt["config"] == config and ckpt["meta"]["configuration"] == "x" and ckpt["meta"]["yaw"] == yaw
    again = load_model(path)
    for (k, v), (k2, v2) in zip(model.state_dict().items(), again.state_dict().items()):
        assert k == k2 and torch.equal(v, v2)
    with pytest.raises(ValueError, match="expected 'lidar_detector'"):
        checkpoint.load(path, "lidar_detector")
    assert checkpoint.load(path, None)["kind"] == "lifting"   # any kind: the MLflow model export reads it so
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match="junk.pt: not a readable checkpoint"):
        checkpoint.load(tmp_path / "junk.pt", None)


def test_network_with_position_input():
    net = LiftingNet({"kind": "bins", "n_bins": 8}, point_widths=(8, 8), head_widths=(8,), variance_widths=(8,),
                     context_dim=4)
    b = D.Batch(torch.randn(1, 3, 3), torch.ones(1, 3, dtype=torch.bool), torch.tensor([[10.0, -2.0, 0.7]]),
                torch.tensor([math.atan2(-2.0, 10.0)]))
    ctx = b.context
    r = math.hypot(10, 2)
    assert torch.allclose(ctx, torch.tensor([[10 / r, -2 / r, r / 40, 0.7]]))
    assert net(b.points, b.mask, ctx)["yaw_logits"].shape == (1, 8)
    with pytest.raises(ValueError, match="context"):
        net(b.points, b.mask)


def test_read_tracks_maps_detection_rows_to_track_ids(tmp_path):
    p = tmp_path / "tracks3d_coco.csv"
    p.write_text("detection,frame,track,cx,cy,cz,n_points\n0,0,5,1.0,2.0,0.5,40\n3,1,5,1.1,2.0,0.5,38\n")
    assert D.read_tracks(p, 5).tolist() == [5, -1, -1, 5, -1]          # untracked detections: -1
    assert D.read_tracks(None, 2).tolist() == [-1, -1]
    (tmp_path / "empty.csv").write_text("detection,frame,track,cx,cy,cz,n_points\n")
    assert D.read_tracks(tmp_path / "empty.csv", 2).tolist() == [-1, -1]
    with pytest.raises(ValueError, match="tracks3d_coco.csv: detection index 3 but the detections file has 3 rows"):
        D.read_tracks(p, 3)
    (tmp_path / "bad.csv").write_text("detection,frame\n0,0\n")
    with pytest.raises(ValueError, match="bad.csv: no column track"):
        D.read_tracks(tmp_path / "bad.csv", 2)
    (tmp_path / "nan.csv").write_text("detection,track\n0,x\n")
    with pytest.raises(ValueError, match="nan.csv: a detection or track value is not an integer"):
        D.read_tracks(tmp_path / "nan.csv", 2)


def test_template_file_round_trip_and_spec_check(tmp_path, tmpl):
    """rule template_field's file gives back the same field; a file of another spec is refused by name."""
    path = tmp_path / "lifting.npz"
    T.save_template(path, tmpl)
    back = T.load_template(path, T.TemplateSpec(voxel=0.1, margin=1.0))
    assert torch.equal(back.field, tmpl.field) and np.array_equal(back.points, tmpl.points)
    assert np.array_equal(back.origin, tmpl.origin) and back.voxel == tmpl.voxel and back.spec == tmpl.spec
    pts = np.array([[[0.3, 2.0, 0.1], [1.9, 0.0, 0.0]]])
    assert np.array_equal(T.distance_to_template(back, pts, np.zeros((1, 3)), np.zeros(1)),
                          T.distance_to_template(tmpl, pts, np.zeros((1, 3)), np.zeros(1)))
    with pytest.raises(ValueError, match=r"lifting.npz: built for another template \(voxel 0.1 != 0.15\)"):
        T.load_template(path, T.TemplateSpec(voxel=0.15, margin=1.0))
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="bad.npz: not a template file"):
        T.load_template(tmp_path / "bad.npz", tmpl.spec)
    # the two stages' config sections
    assert T.spec_from_config({"template": {"voxel": 0.1, "margin": 1.0}}) == tmpl.spec
    assert T.spec_from_config({"template_voxel": 0.15}) == T.TemplateSpec(voxel=0.15)
