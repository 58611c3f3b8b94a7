"""Per-pixel losses against hand-computed values."""
import math

import pytest
import torch

from redsup.depth import losses


def test_ssim_of_image_with_itself_is_one():
    torch.manual_seed(0)
    x = torch.rand(2, 3, 8, 12)
    assert torch.allclose(losses.ssim(x, x), torch.ones_like(x), atol=1e-5)
    assert torch.allclose(losses.photometric_error(x, x), torch.zeros(2, 1, 8, 12), atol=1e-6)


@pytest.mark.parametrize("a,b", [(0.2, 0.7), (0.5, 0.5), (0.9, 0.1)])
def test_ssim_constant_images_hand_value(a, b):
    # float64: Monodepth2's sigma = E[x^2] - E[x]^2 cancels to ~1e-9 in float32, i.e. ~1e-4 in SSIM
    x = torch.full((1, 3, 5, 5), a, dtype=torch.float64)
    y = torch.full((1, 3, 5, 5), b, dtype=torch.float64)
    expected = (2 * a * b + losses.C1) / (a * a + b * b + losses.C1)
    assert torch.allclose(losses.ssim(x, y), torch.full_like(x, expected), atol=1e-10)
    assert torch.allclose(losses.ssim(x.float(), y.float()), torch.full_like(x, expected).float(), atol=2e-4)
    alpha = 0.85
    p = alpha * (1 - expected) / 2 + (1 - alpha) * abs(a - b)
    expected_p = torch.full((1, 1, 5, 5), p, dtype=torch.float64)
    assert torch.allclose(losses.photometric_error(x, y, alpha), expected_p, atol=1e-10)


def test_min_reprojection_and_automask_hand_maps():
    e1 = torch.tensor([[[[0.1, 0.5], [0.3, 0.9]]]])
    e2 = torch.tensor([[[[0.4, 0.2], [0.3, 0.8]]]])
    i1 = torch.tensor([[[[0.2, 0.1], [0.6, 0.7]]]])
    i2 = torch.tensor([[[[0.3, 0.4], [0.1, 0.9]]]])
    m = losses.min_reprojection([e1, e2])
    assert m.shape == (1, 1, 2, 2)
    assert torch.equal(m, torch.tensor([[[[0.1, 0.2], [0.3, 0.8]]]]))
    assert torch.equal(losses.min_reprojection(torch.cat([e1, e2], 1)), m)
    mask = losses.automask([e1, e2], [i1, i2])
    # min identity = [[0.2, 0.1], [0.1, 0.7]]: reprojection wins only at (0, 0)
    assert mask.shape == (1, 1, 2, 2) and mask.dtype == torch.bool
    assert torch.equal(mask, torch.tensor([[[[True, False], [False, False]]]]))
    # static scene: identity error 0 masks every pixel
    assert not losses.automask([e1], [torch.zeros_like(e1)]).any()


def test_automask_noise_is_reproducible_with_generator():
    e = torch.rand(1, 2, 4, 4)
    masks = [losses.automask(e, e.clone(), 1e-5, torch.Generator().manual_seed(7)) for _ in range(2)]
    assert torch.equal(masks[0], masks[1])


def test_edge_aware_smoothness_hand_case():
    disp = torch.tensor([[[[1.0, 1.0, 3.0, 3.0]]]])  # mean 2 -> normalised [0.5, 0.5, 1.5, 1.5]
    flat = torch.zeros(1, 3, 1, 4)
    gx, gy = losses.edge_aware_smoothness(disp, flat)
    assert gx.shape == (1, 1, 1, 3) and gy.shape == (1, 1, 0, 4)
    assert torch.allclose(gx, torch.tensor([[[[0.0, 1.0, 0.0]]]]), atol=1e-6)
    edge = torch.tensor([0.0, 0.0, 1.0, 1.0]).expand(1, 3, 1, 4)
    gx, _ = losses.edge_aware_smoothness(disp, edge)
    assert gx[0, 0, 0, 1].item() == pytest.approx(math.exp(-1.0), rel=1e-5)
    # invariant to the disparity's scale (mean normalisation)
    assert torch.allclose(losses.edge_aware_smoothness(7 * disp, edge)[0], gx)


def test_self_supervised_loss_composition():
    torch.manual_seed(1)
    target = torch.rand(1, 3, 16, 32)
    # perfect warps -> photometric 0; disparity step in x at every scale -> known smoothness
    disps = []
    for s in range(4):
        w = 32 // 2 ** s
        d = torch.ones(1, 1, 16 // 2 ** s, w)
        d[..., w // 2:] = 3.0
        disps.append(d)
    warped = [[target, target] for _ in range(4)]
    identity = [torch.rand(1, 3, 16, 32), torch.rand(1, 3, 16, 32)]
    terms = losses.self_supervised_loss(target, warped, identity, disps, smoothness_weight=1e-3, noise_std=0.0)
    assert terms["photometric"].item() == pytest.approx(0.0, abs=1e-6)
    expected = 0.0
    for s, d in enumerate(disps):
        img = torch.nn.functional.interpolate(target, size=d.shape[-2:], mode="area")
        gx, gy = losses.edge_aware_smoothness(d, img)
        expected += 1e-3 * (gx.mean() + gy.mean()).item() / 2 ** s
    assert terms["loss"].item() == pytest.approx(expected / 4, rel=1e-5)
    # without auto-masking the photometric term is the mean min reprojection
    bad = [[torch.zeros_like(target), target.clone()] for _ in range(4)]
    t2 = losses.self_supervised_loss(target, bad, identity, disps, automasking=False)
    assert t2["photometric"].item() == pytest.approx(0.0, abs=1e-6) and t2["automask_fraction"].item() == 1.0
    with pytest.raises(ValueError, match="scales"):
        losses.self_supervised_loss(target, warped[:2], identity, disps)


def test_precomputed_target_statistics_give_the_same_error():
    torch.manual_seed(3)
    x, y = torch.rand(2, 3, 12, 20), torch.rand(2, 3, 12, 20)
    stats = losses.ssim_stats(y)
    assert torch.allclose(losses.ssim(x, y, y_stats=stats), losses.ssim(x, y))
    assert torch.allclose(losses.photometric_error(x, y, 0.85, stats), losses.photometric_error(x, y, 0.85))
