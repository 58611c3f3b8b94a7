"""Manydepth pieces on hand-computed cases: bins, learned range, plane sweep, consistency mask, gradients."""
import pytest
import torch

from redsup.depth import manydepth, warping

torch.set_num_threads(1)


def _K(b, f, w, h):
    K = torch.tensor([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]])
    return K.expand(b, 3, 3).clone()


def test_bins_uniform_in_inverse_depth():
    bins = manydepth.depth_bins(1.0, 4.0, 4)  # 1/d = 0.25, 0.5, 0.75, 1.0
    assert torch.allclose(bins, torch.tensor([4.0, 2.0, 4.0 / 3.0, 1.0]))
    assert torch.allclose((1 / bins).diff(), torch.full((3,), 0.25))
    with pytest.raises(ValueError):
        manydepth.depth_bins(4.0, 1.0, 4)


def test_depth_range_running_average_of_batch_min_max():
    r = manydepth.DepthRange(0.1, 10.0, momentum=0.5)
    depth = torch.stack([torch.linspace(2, 6, 12).reshape(1, 3, 4), torch.linspace(4, 10, 12).reshape(1, 3, 4)])
    r.update(depth)  # batch-mean min 3, max 8
    assert r.d_min.item() == pytest.approx(0.5 * 0.1 + 0.5 * 3.0)
    assert r.d_max.item() == pytest.approx(0.5 * 10.0 + 0.5 * 8.0)
    r.update(depth)
    assert r.d_min.item() == pytest.approx(0.5 * 1.55 + 0.5 * 3.0)
    assert torch.allclose(r.bins(3), manydepth.depth_bins(r.d_min, r.d_max, 3))


def test_scale_intrinsics_pixel_centres():
    K = _K(1, 10.0, 8, 4)  # cx = 3.5, cy = 1.5
    K2 = manydepth.scale_intrinsics(K, (4, 8), (2, 4))
    # pixel centres: u' = (u + 0.5) / 2 - 0.5
    assert K2[0, 0, 0].item() == pytest.approx(5.0)
    assert K2[0, 0, 2].item() == pytest.approx((3.5 + 0.5) / 2 - 0.5)
    assert K2[0, 1, 2].item() == pytest.approx((1.5 + 0.5) / 2 - 0.5)


def test_plane_sweep_correct_bin_wins_on_fronto_parallel_plane():
    # f b / d = 10 * 0.4 / d: the bins 4, 2, 4/3, 1 shift by exactly 1, 2, 3, 4 pixels; the plane is at d = 2
    f, b, h, w, c = 10.0, 0.4, 5, 16, 6
    torch.manual_seed(0)
    target = torch.rand(2, c, h, w)
    source = torch.rand(2, c, h, w)
    source[..., : w - 2] = target[..., 2:]  # source pixel u sees what the target sees at u + 2
    T = warping.translation_transform(torch.tensor([[-b, 0.0, 0.0]]).expand(2, 3))  # source camera at x = +b
    bins = manydepth.depth_bins(1.0, 4.0, 4)
    cost, missing = manydepth.cost_volume(target, source, _K(2, f, w, h), T, bins)
    assert cost.shape == (2, 4, h, w)
    interior = (slice(None), slice(None), slice(None), slice(4, w))  # every bin projects inside
    assert torch.all(cost[:, 1][interior[1:]].abs() < 1e-6)  # the true plane: zero cost
    assert torch.all(cost.argmin(1)[..., 4:] == 1)
    best = manydepth.best_bin_depth(cost, bins)
    assert torch.allclose(best[..., 4:], torch.full_like(best[..., 4:], 2.0))
    # column 0 projects outside the source for every bin (shift >= 1): missing, zeroed
    assert missing[..., 0].all() and not missing[..., 1:].any()
    assert torch.all(cost[..., 0] == 0)
    # a bin projecting outside takes the pixel's largest valid cost, so it never wins: column 2 (bins 3, 4 out)
    col = cost[..., 2]
    assert torch.all(col[:, 2] == col[:, :2].amax(1)) and torch.all(col[:, 3] == col[:, :2].amax(1))


def test_consistency_mask_factor_two_missing_and_augmented():
    cv = torch.tensor([1.5, 2.0, 3.9, 4.1, 1.0, 1.05]).reshape(1, 1, 1, 6)
    teacher = torch.full_like(cv, 2.0)
    # (cv - t) / t >= 1  or  (t - cv) / cv >= 1
    expected = torch.tensor([False, False, False, True, True, False]).reshape(1, 1, 1, 6)
    assert torch.equal(manydepth.consistency_mask(cv, teacher), expected)
    missing = torch.tensor([True, False, False, False, False, False]).reshape(1, 1, 1, 6)
    assert torch.equal(manydepth.consistency_mask(cv, teacher, missing), expected | missing)
    two = manydepth.consistency_mask(cv.repeat(2, 1, 1, 1), teacher.repeat(2, 1, 1, 1),
                                     augmented=torch.tensor([False, True]))
    assert torch.equal(two[0], expected[0]) and two[1].all()


def _batch(b=2, h=32, w=64, seed=0):
    g = torch.Generator().manual_seed(seed)
    target = torch.rand(b, 3, h, w, generator=g)
    return {"target": target, "K": _K(b, 40.0, w, h),
            "sources": {"prev": torch.rand(b, 3, h, w, generator=g), "next": torch.rand(b, 3, h, w, generator=g)}}


def _grads(models, names):
    return [p.grad for n in names for p in models[n].parameters()]


def test_teacher_gets_no_gradient_from_the_cost_volume_branch():
    torch.manual_seed(0)
    models = manydepth.build_models(base_channels=4, n_bins=8)
    crit = manydepth.ManydepthLoss(static_prob=0.0, zero_prob=0.0, generator=torch.Generator().manual_seed(0))
    terms = crit(models, _batch())
    (terms["multi_loss"] + terms["consistency"]).backward()
    teacher = _grads(models, ["teacher_encoder", "teacher_decoder"])
    assert all(g is None or torch.all(g == 0) for g in teacher)
    assert any(g is not None and g.abs().sum() > 0 for g in _grads(models, ["depth_encoder", "depth_decoder"]))
    # the full loss does train the teacher (the check above can fail)
    models.zero_grad(set_to_none=True)
    crit(models, _batch())["loss"].backward()
    assert any(g is not None and g.abs().sum() > 0 for g in _grads(models, ["teacher_encoder"]))


def test_augmented_batch_is_all_unreliable_and_frozen_teacher():
    torch.manual_seed(0)
    models = manydepth.build_models(base_channels=4, n_bins=8)
    crit = manydepth.ManydepthLoss(static_prob=1.0, zero_prob=0.0, freeze_at=1,
                                   generator=torch.Generator().manual_seed(0))
    terms = crit(models, _batch(), step=1)
    assert terms["unreliable_fraction"].item() == 1.0
    assert terms["photometric"].item() == 0.0  # photometric term only on reliable pixels
    assert models["depth_range"].d_min.item() != pytest.approx(0.1)  # updated before the freeze
    before = (models["depth_range"].d_min.clone(), models["depth_range"].d_max.clone())
    terms = crit(models, _batch(), step=2)  # frozen: no teacher loss, range fixed, no teacher / pose gradient
    assert "teacher_loss" not in terms
    assert torch.equal(models["depth_range"].d_min, before[0]) and torch.equal(models["depth_range"].d_max, before[1])
    terms["loss"].backward()
    assert all(g is None for g in _grads(models, ["teacher_encoder", "pose_encoder", "pose_decoder"]))
    assert not models["teacher_encoder"].training and models["depth_encoder"].training


def test_prediction_with_and_without_previous_frame():
    torch.manual_seed(0)
    models = manydepth.build_models(base_channels=4, n_bins=8).eval()
    batch = _batch(b=1, h=32, w=48)
    d = manydepth.predict_depth(models, batch["target"], batch["sources"]["prev"], batch["K"])
    d0 = manydepth.predict_depth(models, batch["target"], None, batch["K"])
    dt = manydepth.predict_teacher_depth(models, batch["target"])
    assert d.shape == d0.shape == dt.shape == (1, 1, 32, 48)
    assert not torch.allclose(d, d0)  # the cost volume matters
    assert torch.all((d >= 0.1) & (d <= 100.0))
