"""Template distance field, per-point losses, best-yaw search and multi-cell voting (redsup.det3d)."""
import math

import numpy as np
import pytest
import torch

from redsup.det3d import losses as L
from redsup.det3d import template as T
from redsup.det3d import voting as V

N_BINS = 64


@pytest.fixture(scope="module")
def tmpl():
    # 5 cm surface samples, 10 cm field: ~0.1 s to build, accurate enough for 64 bins
    return T.build_template(T.TemplateSpec(spacing=0.05, voxel=0.1, margin=1.0))


def _car_scan(faces, size=(4.2, 1.75, 1.45), yaw=0.7, centre=(12.0, -3.0, 0.8), cabin=True):
    """LiDAR-like rows on the chosen faces ("left", "rear") of a two-box car a little larger than the
    template, posed at (centre, yaw); returns (P, 3) float64."""
    l, w, h = size
    hb = 0.56 * h
    z_body = np.linspace(-h / 2 + 0.15, -h / 2 + hb - 0.05, 4)
    z_cab = np.linspace(-h / 2 + hb + 0.1, h / 2 - 0.05, 3)
    cab_x0, cab_x1, cab_w = -0.07 * l - 0.25 * l, -0.07 * l + 0.25 * l, 0.88 * w
    pts = []
    for face in faces:
        if face == "left":
            xs, zs = np.meshgrid(np.linspace(-l / 2, l / 2, 40), z_body)
            pts.append(np.c_[xs.ravel(), np.full(xs.size, w / 2), zs.ravel()])
            if cabin:
                xs, zs = np.meshgrid(np.linspace(cab_x0, cab_x1, 20), z_cab)
                pts.append(np.c_[xs.ravel(), np.full(xs.size, cab_w / 2), zs.ravel()])
        elif face == "rear":
            ys, zs = np.meshgrid(np.linspace(-w / 2, w / 2, 16), z_body)
            pts.append(np.c_[np.full(ys.size, -l / 2), ys.ravel(), zs.ravel()])
            if cabin:
                ys, zs = np.meshgrid(np.linspace(-cab_w / 2, cab_w / 2, 12), z_cab)
                pts.append(np.c_[np.full(ys.size, cab_x0), ys.ravel(), zs.ravel()])
    local = np.concatenate(pts)
    c, s = math.cos(yaw), math.sin(yaw)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    return local @ R.T + np.asarray(centre)


def _circ(a, b, n=N_BINS):
    d = abs(int(a) - int(b)) % n
    return min(d, n - d)


# ------------------------------------------------------------------------------ template + field
def test_template_shape(tmpl):
    p = tmpl.points
    assert np.allclose(p.min(axis=0), [-1.95, -0.8, -0.75]) and np.allclose(p.max(axis=0), [1.95, 0.8, 0.75])
    assert len(p) > 2000
    assert np.allclose(tmpl.size, [3.9, 1.6, 1.5])
    # nothing sampled strictly inside the body (e.g. the face shared with the cabin)
    assert not ((np.abs(p[:, 0]) < 1.9) & (np.abs(p[:, 1]) < 0.6) & (np.abs(p[:, 2] - 0.0) < 0.05)).any()


def test_field_matches_bruteforce_inside_grid(tmpl):
    rng = np.random.default_rng(0)
    pts = rng.uniform(tmpl.origin, tmpl.upper, size=(3000, 3))
    d = T.distance_to_template(tmpl, pts, np.zeros(3), 0.0)
    ref = T.nearest_template_point_distance_bruteforce(tmpl, pts, np.zeros(3), 0.0)
    err = np.abs(d - ref)
    assert err.max() < 0.6 * tmpl.voxel and np.median(err) < 0.005


def test_field_pose_and_extrapolation(tmpl):
    yaw, t = 0.9, np.array([5.0, -2.0, 0.3])
    c, s = math.cos(yaw), math.sin(yaw)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    local = np.array([[0.0, 0.8, -0.3], [0.0, 1.8, -0.3], [0.0, 5.0, -0.3]])  # on the side, 1 m and 4.2 m out
    world = local @ R.T + t
    d = T.distance_to_template(tmpl, world, t, yaw)
    assert d[0] < 0.06 and d[1] == pytest.approx(1.0, abs=0.06) and d[2] == pytest.approx(4.2, abs=0.06)
    # differentiable: moving the template towards the far point reduces its distance one-for-one
    tt = torch.tensor(t, requires_grad=True)
    T.distance_to_template(tmpl, torch.tensor(world[2:]), tt, torch.tensor(yaw)).sum().backward()
    assert torch.allclose(tt.grad, torch.tensor([s, -c, 0.0], dtype=tt.grad.dtype), atol=0.05)
    # finite gradients inside the grid and on the surface too (no sqrt(0) in the extrapolation term)
    tt = torch.tensor(t, requires_grad=True)
    ty = torch.tensor(yaw, requires_grad=True)
    T.distance_to_template(tmpl, torch.tensor(world), tt, ty).sum().backward()
    assert torch.isfinite(tt.grad).all() and torch.isfinite(ty.grad)


def test_batched_shapes_match_loops(tmpl):
    rng = np.random.default_rng(1)
    pts = torch.tensor(rng.normal(0, 2, (3, 50, 3)))
    trans = torch.tensor(rng.normal(0, 1, (3, 3)))
    yaws = L.yaw_bin_centers(8, dtype=torch.float64)
    d = T.distance_to_template(tmpl, pts[:, None], trans[:, None], yaws[None].expand(3, 8))
    assert d.shape == (3, 8, 50)
    one = T.distance_to_template(tmpl, pts[1], trans[1], yaws[5])
    assert torch.allclose(d[1, 5], one)


# ----------------------------------------------------------------------------------- per-point losses
def test_l2_and_sic_by_hand(tmpl):
    # a template surface point on the left side, and the same point 1 m further out
    side = tmpl.points[(np.abs(tmpl.points[:, 1] - 0.8) < 1e-9) & (np.abs(tmpl.points[:, 0]) < 0.5)][0]
    pts = np.stack([side, side + [0.0, 1.0, 0.0]])
    d = torch.tensor(T.nearest_template_point_distance_bruteforce(tmpl, pts, np.zeros(3), 0.0))
    assert torch.allclose(d, torch.tensor([0.0, 1.0], dtype=d.dtype))
    assert torch.allclose(L.squared_distance(d), torch.tensor([0.0, 1.0], dtype=d.dtype))
    sic = L.soft_inlier_count(d, alpha=5.0, beta=0.0)
    assert sic[0].item() == pytest.approx(-0.5)                              # -sigmoid(0): the minimum
    assert sic[1].item() == pytest.approx(-1 / (1 + math.exp(5.0)))          # -sigmoid(-5) = -0.00669
    sic2 = L.soft_inlier_count(d, alpha=5.0, beta=2.5)
    assert sic2[0].item() == pytest.approx(-1 / (1 + math.exp(-2.5)))        # -0.9241
    assert sic2[1].item() == pytest.approx(-1 / (1 + math.exp(2.5)))         # -0.0759
    # the same through the distance field, within its interpolation error
    df = torch.tensor(T.distance_to_template(tmpl, pts, np.zeros(3), 0.0))
    assert torch.allclose(L.soft_inlier_count(df, 5.0, 0.0), sic, atol=0.02)
    # SIC is lowest on the surface and bounded for outliers; L2 grows without bound
    far = torch.tensor([0.0, 0.5, 1.0, 10.0])
    assert (torch.diff(L.soft_inlier_count(far, 5.0, 0.0)) > 0).all()
    assert L.soft_inlier_count(far, 5.0, 0.0)[-1].item() > -1e-12


def test_outlier_aware_loss_by_hand():
    d = torch.tensor([1.0, 2.0, 2.0])
    log_var = torch.tensor([0.0, math.log(4.0), 0.0])
    out = L.outlier_aware(d, log_var)
    assert torch.allclose(out, torch.tensor([1.0, 1.0 + math.log(4.0), 4.0]))
    # for a fixed error the loss is minimal at sigma^2 = d^2
    lv = torch.tensor(0.3, requires_grad=True)
    L.outlier_aware(torch.tensor(2.0), lv).backward()
    assert lv.grad.item() < 0
    lv2 = torch.tensor(math.log(4.0), requires_grad=True)
    L.outlier_aware(torch.tensor(2.0), lv2).backward()
    assert lv2.grad.item() == pytest.approx(0.0, abs=1e-6)


def test_yaw_bins():
    c = L.yaw_bin_centers(N_BINS)
    assert c[0].item() == pytest.approx(-math.pi) and c[N_BINS // 2].item() == pytest.approx(0.0)
    assert torch.equal(L.yaw_to_bin(c.double(), N_BINS), torch.arange(N_BINS))
    assert L.yaw_to_bin(torch.tensor([math.pi, 3 * math.pi - 1e-3]), N_BINS).tolist() == [0, 0]


# ------------------------------------------------------------------------------------ best-yaw search
@pytest.mark.parametrize("loss_name", ["l2", "sic"])
def test_best_yaw_recovers_l_shaped_scan(tmpl, loss_name):
    yaw, centre = 0.7, (12.0, -3.0, 0.8)
    scan = torch.tensor(_car_scan(["left", "rear"], yaw=yaw, centre=centre))[None]
    loss_fn = L.squared_distance if loss_name == "l2" else (lambda d: L.soft_inlier_count(d, 5.0, 0.0))
    best, per_bin = L.best_yaw_bin(scan, torch.tensor([centre]), N_BINS, loss_fn, tmpl)
    true_bin = int(L.yaw_to_bin(torch.tensor(yaw), N_BINS))
    assert per_bin.shape == (1, N_BINS)
    assert _circ(best[0], true_bin) <= 1
    # two visible sides leave no 90 degree ambiguity; the cabin rows (asymmetric front/back) break the
    # 180 degree one, by less since the body alone is symmetric
    gap = per_bin[0] - per_bin[0, best[0]]
    assert gap[(true_bin + N_BINS // 4) % N_BINS] > 0.15
    assert gap[(true_bin + 3 * N_BINS // 4) % N_BINS] > 0.15
    assert gap[(true_bin + N_BINS // 2) % N_BINS] > 0.01


def test_best_yaw_single_side_is_ambiguous_only_by_180(tmpl):
    yaw, centre = 0.7, (12.0, -3.0, 0.8)
    scan = torch.tensor(_car_scan(["left"], yaw=yaw, centre=centre, cabin=False))[None]
    loss_fn = lambda d: L.soft_inlier_count(d, 5.0, 0.0)  # noqa: E731
    best, per_bin = L.best_yaw_bin(scan, torch.tensor([centre]), N_BINS, loss_fn, tmpl)
    true_bin = int(L.yaw_to_bin(torch.tensor(yaw), N_BINS))
    flipped = (true_bin + N_BINS // 2) % N_BINS
    assert min(_circ(best[0], true_bin), _circ(best[0], flipped)) <= 1
    p = per_bin[0]
    ambiguity = abs(p[true_bin] - p[flipped])
    quarter_gap = p[(true_bin + N_BINS // 4) % N_BINS] - min(p[true_bin], p[flipped])
    assert ambiguity < 0.1 * quarter_gap


def test_best_yaw_masks_padding_and_empty_sets(tmpl):
    scan = torch.tensor(_car_scan(["left", "rear"]))
    pts = torch.full((2, len(scan) + 5, 3), float("nan"), dtype=torch.float64)
    pts[0, :len(scan)] = scan
    mask = torch.zeros(2, len(scan) + 5, dtype=torch.bool)
    mask[0, :len(scan)] = True
    trans = torch.tensor([[12.0, -3.0, 0.8], [0.0, 0.0, 0.0]])
    best, per_bin = L.best_yaw_bin(pts, trans, N_BINS, L.squared_distance, tmpl, mask=mask)
    assert torch.isfinite(per_bin).all() and (per_bin[1] == 0).all()
    ref, ref_bins = L.best_yaw_bin(scan[None], trans[:1], N_BINS, L.squared_distance, tmpl)
    assert best[0] == ref[0] and torch.allclose(per_bin[0], ref_bins[0])


# ------------------------------------------------------------------------------- multi-frame (ch. 6)
def test_multiframe_consistency_by_hand():
    def pose(x, y, yaw):
        c, s = math.cos(yaw), math.sin(yaw)
        return torch.tensor([[c, -s, 0, x], [s, c, 0, y], [0, 0, 1, 0], [0, 0, 0, 1.0]], dtype=torch.float64)

    T_w_vi, T_w_vj = pose(0, 0, 0), pose(5.0, 1.0, 0.1)        # ego drove 5 m and turned 0.1 rad
    obj_w = torch.tensor([10.0, 2.0, 0.75], dtype=torch.float64)
    obj_yaw_w = 0.5
    T_vj_w = torch.linalg.inv(T_w_vj)
    t_j = T_vj_w[:3, :3] @ obj_w + T_vj_w[:3, 3]
    T_i_from_j = torch.linalg.inv(T_w_vi) @ T_w_vj
    kp = L.centre_front_keypoints(3.9, dtype=torch.float64)
    loss = L.multiframe_consistency(obj_w, torch.tensor(obj_yaw_w, dtype=torch.float64), t_j,
                                    torch.tensor(obj_yaw_w - 0.1, dtype=torch.float64), T_i_from_j, kp)
    assert torch.allclose(loss, torch.zeros(2, dtype=torch.float64), atol=1e-12)
    flipped = L.multiframe_consistency(obj_w, torch.tensor(obj_yaw_w, dtype=torch.float64), t_j,
                                       torch.tensor(obj_yaw_w - 0.1 + math.pi, dtype=torch.float64), T_i_from_j, kp)
    assert flipped[0].item() == pytest.approx(0.0, abs=1e-12)     # centre agrees
    assert flipped[1].item() == pytest.approx(3.9 ** 2)            # front keypoint is a car length away


# ------------------------------------------------------------------------------ multi-cell voting
def _voting_setup(tmpl, good_shift, good_yaw_right=True):
    grid = V.BevGrid(x_min=0.0, y_min=-4.0, cell=0.4, height=20, width=30, z_ref=0.0)
    centre, yaw = torch.tensor([6.13, 0.35, 0.1], dtype=torch.float64), 0.3
    local = torch.tensor(tmpl.points[(tmpl.points[:, 1] > 0.7) | (tmpl.points[:, 0] < -1.9)])   # left + rear
    c, s = math.cos(yaw), math.sin(yaw)
    R = torch.tensor([[c, -s, 0], [s, c, 0], [0, 0, 1.0]], dtype=torch.float64)
    pts = (local @ R.T + centre)[None]
    med = V.median_cell(grid, pts)
    H, W = grid.height, grid.width
    rows = torch.arange(H, dtype=torch.float64)[:, None].expand(H, W)
    cols = torch.arange(W, dtype=torch.float64)[None, :].expand(H, W)
    offsets = torch.zeros(1, 3, H, W, dtype=torch.float64)
    offsets[0, 0] = 0.2
    offsets[0, 1] = 0.2 + 2.5              # every cell predicts a centre 2.5 m to its left: junk
    offsets[0, 2] = centre[2]
    logits = torch.zeros(1, N_BINS, H, W)
    true_bin = int(L.yaw_to_bin(torch.tensor(yaw), N_BINS))
    logits[0, true_bin] = 5.0
    good = med[0] + torch.tensor(good_shift)
    gr, gc = int(good[0]), int(good[1])
    offsets[0, 0, gr, gc] = centre[0] - (grid.x_min + cols[gr, gc] * grid.cell)
    offsets[0, 1, gr, gc] = centre[1] - (grid.y_min + rows[gr, gc] * grid.cell)
    if not good_yaw_right:
        logits[:, :, gr, gc] = 0.0
        logits[0, (true_bin + N_BINS // 4) % N_BINS, gr, gc] = 5.0
    return grid, offsets, logits, pts, med, (gr, gc), centre


def test_voting_picks_lowest_loss_neighbour(tmpl):
    sic = lambda d: L.soft_inlier_count(d, 5.0, 0.0)  # noqa: E731
    grid, off, logits, pts, med, good, centre = _voting_setup(tmpl, good_shift=(1, -1))
    frame = torch.zeros(1, dtype=torch.long)
    res1 = V.vote(grid, off, logits, pts, None, med, frame, 1, sic, tmpl)
    assert tuple(res1.cell[0].tolist()) == good
    assert torch.allclose(res1.centre[0], centre)
    assert res1.window_loss.shape == (1, 9) and res1.loss[0] == res1.window_loss[0].min()
    res0 = V.vote(grid, off, logits, pts, None, med, frame, 0, sic, tmpl)
    assert torch.equal(res0.cell, med)


def test_voting_window_reach(tmpl):
    sic = lambda d: L.soft_inlier_count(d, 5.0, 0.0)  # noqa: E731
    grid, off, logits, pts, med, good, _ = _voting_setup(tmpl, good_shift=(-2, 2))
    frame = torch.zeros(1, dtype=torch.long)
    assert tuple(V.vote(grid, off, logits, pts, None, med, frame, 1, sic, tmpl).cell[0].tolist()) != good
    assert tuple(V.vote(grid, off, logits, pts, None, med, frame, 2, sic, tmpl).cell[0].tolist()) == good


def test_voting_best_yaw_mode_and_grid_border(tmpl):
    sic = lambda d: L.soft_inlier_count(d, 5.0, 0.0)  # noqa: E731
    grid, off, logits, pts, med, good, _ = _voting_setup(tmpl, good_shift=(0, 1), good_yaw_right=False)
    frame = torch.zeros(1, dtype=torch.long)
    predicted = V.vote(grid, off, logits, pts, None, med, frame, 1, sic, tmpl, yaw_mode="predicted")
    best = V.vote(grid, off, logits, pts, None, med, frame, 1, sic, tmpl, yaw_mode="best")
    assert tuple(best.cell[0].tolist()) == good
    assert best.loss[0] < predicted.window_loss[0, 5]      # the good cell scored at its (wrong) argmax yaw
    corner = torch.tensor([[0, 0]])
    res = V.vote(grid, off, logits, pts, None, corner, frame, 1, sic, tmpl)
    assert torch.isinf(res.window_loss[0]).sum() == 5 and torch.isfinite(res.loss).all()
    none = V.vote(grid, off, logits, pts, None, torch.tensor([[-1, -1]]), frame, 1, sic, tmpl)
    assert none.cell[0].tolist() == [-1, -1] and torch.isinf(none.loss[0])


# ------------------------------------------------------------------------------------------ bad input
def test_pad_point_sets_skips_empty_and_nan_with_counts(tmpl):
    from redsup.det3d import pointsets

    sets = [np.zeros((0, 4)), np.array([[1.0, 2.0, 0.5, 0.3]]), np.array([[np.nan, 0, 0, 0], [np.inf, 1, 1, 0]]),
            np.c_[_car_scan(["left"]), np.zeros(len(_car_scan(["left"])))]]
    sets[3][5, 1] = np.nan
    padded = pointsets.pad_point_sets(sets, min_points=1, max_points=64, rng=np.random.default_rng(0))
    assert padded.keep.tolist() == [1, 3] and padded.skipped.tolist() == [0, 2] and padded.n_nonfinite == 3
    assert padded.points.shape == (2, 64, 3) and padded.mask.sum(dim=1).tolist() == [1, 64]
    assert "2 skipped" in padded.message()
    trans = torch.tensor([[1.0, 2.0, 0.5], [12.0, -3.0, 0.8]])
    sic = lambda d: L.soft_inlier_count(d, 5.0, 0.0)  # noqa: E731
    best, per_bin = L.best_yaw_bin(padded.points, trans, N_BINS, sic, tmpl, mask=padded.mask)
    assert torch.isfinite(per_bin).all()
    t = trans.clone().requires_grad_(True)
    yaw = L.yaw_bin_centers(N_BINS)[best]
    d = T.distance_to_template(tmpl, padded.points, t, yaw)
    loss = L.masked_mean(sic(d), padded.mask).mean()
    loss.backward()
    assert torch.isfinite(loss) and torch.isfinite(t.grad).all()
