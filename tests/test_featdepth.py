"""Feature Depth: the FeatureNet losses and the feature-metric loss on hand-computed cases."""
import math

import pytest
import torch

from redsup.depth import featdepth, warping

torch.set_num_threads(1)


def _grid(h, w):
    y, x = torch.meshgrid(torch.arange(h, dtype=torch.float32), torch.arange(w, dtype=torch.float32), indexing="ij")
    return x, y


def test_reconstruction_error_channel_mean():
    image = torch.full((1, 3, 2, 2), 0.5)
    rec = torch.tensor([0.4, 0.7, 0.5]).reshape(1, 3, 1, 1).expand(1, 3, 2, 2)
    assert torch.allclose(featdepth.reconstruction_error(image, rec), torch.full((1, 1, 2, 2), 0.1))


def test_discriminative_ramp_and_image_weight():
    x, _ = _grid(4, 5)
    phi = torch.stack([0.3 * x, 0.3 * x])[None]  # d_x phi = 0.3, d_y phi = 0
    flat = torch.zeros(1, 3, 4, 5)
    dx, dy = featdepth.discriminative_map(phi, flat)
    assert dx.shape == (1, 1, 4, 4) and dy.shape == (1, 1, 3, 5)
    assert torch.allclose(dx, torch.full_like(dx, -0.3)) and torch.all(dy == 0)
    textured = (0.2 * x).expand(1, 3, 4, 5)  # |d_x I| = 0.2: weight e^-0.2
    dx, _ = featdepth.discriminative_map(phi, textured)
    assert torch.allclose(dx, torch.full_like(dx, -0.3 * math.exp(-0.2)))
    # the image is resized to the features (area): a 2x larger constant image gives the same map
    dx2, _ = featdepth.discriminative_map(phi, torch.zeros(1, 3, 8, 10))
    assert torch.allclose(dx2, torch.full_like(dx2, -0.3))


@pytest.mark.parametrize("field, expected", [("x", 0.0), ("x2", 2.0), ("xy", 2.0), ("y2", 2.0)])
def test_convergent_second_order(field, expected):
    x, y = _grid(5, 6)
    phi = {"x": 0.7 * x, "x2": x ** 2, "xy": x * y, "y2": y ** 2}[field][None, None]
    # x^2: d_xx = 2; y^2: d_yy = 2; x y: d_xy = 1, counted twice; a ramp: 0
    cvt = featdepth.convergent_map(phi)
    assert cvt.shape == (1, 1, 3, 4)
    assert torch.allclose(cvt, torch.full_like(cvt, expected), atol=1e-6)


def test_featurenet_loss_is_the_weighted_sum_and_shapes_follow_input():
    torch.manual_seed(0)
    models = featdepth.build_models(base_channels=4)
    image = torch.rand(2, 3, 36, 52)  # not a multiple of 32
    t = featdepth.featurenet_loss(models, image, alpha=0.1, beta=0.2)
    assert t["featurenet_loss"].item() == pytest.approx(
        (t["reconstruction"] + 0.1 * t["discriminative"] + 0.2 * t["convergent"]).item(), rel=1e-6)
    assert t["discriminative"].item() < 0 < t["convergent"].item()
    rec = models["feature_decoder"](models["feature_encoder"](image)[-1], output_size=(36, 52))
    assert rec.shape == image.shape
    assert featdepth.features(models, image).shape == (2, 4, 18, 26)


def test_feature_metric_zero_at_the_true_depth():
    # source camera at x = +0.4, f = 10: a plane at depth 2 shifts by f b / d = 2 pixels
    h, w, f = 6, 16, 10.0
    K = torch.tensor([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]])[None]
    T = {"prev": warping.translation_transform(torch.tensor([[-0.4, 0.0, 0.0]]))}
    torch.manual_seed(0)
    target = torch.rand(1, 4, h, w)
    source = torch.rand(1, 4, h, w)
    source[..., : w - 2] = target[..., 2:]
    weight = torch.zeros(1, 1, h, w)
    weight[..., 2:] = 1.0  # pixels whose source sample exists
    right = featdepth.feature_metric_loss(target, {"prev": source}, torch.full((1, 1, h, w), 2.0), K, T, (h, w),
                                          weight)
    wrong = featdepth.feature_metric_loss(target, {"prev": source}, torch.full((1, 1, h, w), 1.0), K, T, (h, w),
                                          weight)
    assert right.item() == pytest.approx(0.0, abs=1e-6) and wrong.item() > 0.05


def test_featdepth_criterion_features_get_no_gradient_from_depth_losses():
    torch.manual_seed(0)
    models = featdepth.build_models(base_channels=4)
    g = torch.Generator().manual_seed(1)
    b, h, w = 2, 32, 48
    K = torch.tensor([[40.0, 0.0, 23.5], [0.0, 40.0, 15.5], [0.0, 0.0, 1.0]]).expand(b, 3, 3).clone()
    batch = {"target": torch.rand(b, 3, h, w, generator=g), "K": K,
             "sources": {"prev": torch.rand(b, 3, h, w, generator=g), "next": torch.rand(b, 3, h, w, generator=g)}}
    terms = featdepth.FeatDepthLoss(feature_weight=1.0)(models, batch)
    assert terms["loss"].item() == pytest.approx(
        (terms["featurenet_loss"] + terms["depth_loss"] + terms["feature_metric"]).item(), rel=1e-6)
    terms["feature_metric"].backward()
    assert all(p.grad is None for p in models["feature_encoder"].parameters())
    assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in models["depth_decoder"].parameters())
