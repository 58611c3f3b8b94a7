"""Depth/pose networks, warping against hand-computed cases, and the loss pipeline on tiny inputs."""
import math

import pytest
import torch

from redsup.depth import networks, pipeline, warping

torch.set_num_threads(1)


def _K(batch, f=50.0, w=64, h=32):
    K = torch.tensor([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]])
    return K.expand(batch, 3, 3).clone()


def _shift_T(tx, batch=1):
    return warping.translation_transform(torch.tensor([[tx, 0.0, 0.0]]).expand(batch, 3))


@pytest.mark.parametrize("size", [(32, 64), (64, 96), (40, 72)])  # (H, W); 40x72 is not a multiple of 32
def test_networks_batch_one_any_size(size):
    torch.manual_seed(0)
    models = networks.build_models(base_channels=8).eval()
    h, w = size
    image = torch.rand(1, 3, h, w)
    with torch.no_grad():
        disps = pipeline.predict_disparities(models, image)
        aa, tr = pipeline.predict_pose_parameters(models, image, torch.rand(1, 3, h, w), "next")
    assert len(disps) == 4
    for s, d in enumerate(disps):
        assert d.shape == (1, 1, math.ceil(h / 2 ** s), math.ceil(w / 2 ** s))
        assert torch.all((d > 0) & (d < 1))
    assert aa.shape == (1, 3) and tr.shape == (1, 3)


def test_resnet18_structure_and_named_submodules():
    enc = networks.ResNetEncoder(3, 64)
    assert sum(p.numel() for p in enc.parameters()) == 11_176_512  # torchvision resnet18 without fc
    assert enc.num_ch_enc == (64, 64, 128, 256, 512)
    assert list(enc.first_layer) == [enc.conv1, enc.bn1] and enc.last_block is enc.layer4
    pose_enc = networks.ResNetEncoder(6, 8)
    with pytest.raises(ValueError, match="6 input channels"):
        pose_enc(torch.rand(1, 3, 32, 64))
    models = networks.build_models(8)
    assert tuple(models.keys()) == networks.MODULE_NAMES


def test_disp_to_depth_range():
    _, depth = networks.disp_to_depth(torch.tensor([0.0, 1.0, 0.5]), 0.1, 100.0)
    assert depth[0].item() == pytest.approx(100.0) and depth[1].item() == pytest.approx(0.1)
    assert depth[2].item() == pytest.approx(1.0 / (0.01 + 0.5 * 9.99))


def test_fronto_parallel_plane_shift_matches_analytic():
    f, d = 50.0, 5.0
    torch.manual_seed(1)
    source = torch.rand(2, 3, 32, 64)
    depth = torch.full((2, 1, 32, 64), d)
    K = _K(2, f)
    # integer shift f * tx / d = 2 px on a random texture
    warped = warping.warp(source, depth, K, _shift_T(0.2, 2))
    assert torch.allclose(warped[..., :-2], source[..., 2:], atol=1e-5)
    # fractional shift 1.3 px: bilinear sampling is exact on a linear ramp
    u = torch.arange(64.0).expand(2, 3, 32, 64)
    ramp = 0.01 * u + 0.2
    warped = warping.warp(ramp, depth, K, _shift_T(0.13, 2))
    assert torch.allclose(warped[..., :-2], 0.01 * (u[..., :-2] + f * 0.13 / d) + 0.2, atol=1e-5)
    grid, valid = warping.sampling_grid(depth, K, _shift_T(0.13, 2))
    pix_u = ((grid[..., 0] + 1) * 64 - 1) / 2
    assert torch.allclose(pix_u, torch.arange(64.0) + 1.3, atol=1e-4)
    assert valid[..., :-2].all() and not valid[..., -1].any()


def test_identity_pose_reproduces_image_and_4x4_intrinsics():
    torch.manual_seed(2)
    image = torch.rand(1, 3, 32, 64)
    depth = 0.5 + 20 * torch.rand(1, 1, 32, 64)
    K4 = torch.eye(4).unsqueeze(0)
    K4[:, :3, :3] = _K(1)
    T = warping.transformation_from_parameters(torch.zeros(1, 3), torch.zeros(1, 3))
    # float32 K^-1 K is exact to ~1e-5 px; a random texture turns that into ~1e-4 intensity
    assert torch.allclose(warping.warp(image, depth, K4, T), image, atol=1e-3)
    assert torch.allclose(warping.warp(image, depth, _K(1), T), image, atol=1e-3)


def test_transformation_from_parameters():
    aa = torch.tensor([[0.0, math.pi / 2, 0.0], [0.1, -0.2, 0.3]])
    t = torch.tensor([[1.0, 2.0, 3.0], [0.5, 0.0, -0.5]])
    T = warping.transformation_from_parameters(aa, t)
    # 90 deg about y maps x -> -z
    assert torch.allclose(T[0, :3, :3] @ torch.tensor([1.0, 0.0, 0.0]), torch.tensor([0.0, 0.0, -1.0]), atol=1e-6)
    assert torch.allclose(T[:, :3, 3], t)
    Tinv = warping.transformation_from_parameters(aa, t, invert=True)
    assert torch.allclose(T @ Tinv, torch.eye(4).expand(2, 4, 4), atol=1e-6)
    R = T[1, :3, :3]
    assert torch.allclose(R @ R.T, torch.eye(3), atol=1e-6)


def test_backproject_project_roundtrip():
    torch.manual_seed(3)
    depth = 1 + torch.rand(1, 1, 4, 6)
    K = _K(1, 10.0, 6, 4)
    pts = warping.backproject(depth, torch.linalg.inv(K))
    pix, z = warping.project(pts, K)
    grid = warping.pixel_grid(4, 6, depth)
    assert torch.allclose(pix[0], grid[:2], atol=1e-5) and torch.allclose(z.reshape(1, 1, 4, 6), depth)


@pytest.mark.parametrize("mode", ["M", "S", "MS", "next-only"])
def test_batch_loss_modes_are_finite_and_differentiable(mode):
    torch.manual_seed(4)
    models = networks.build_models(8)
    b, h, w = 2, 32, 64
    frames = {n: torch.rand(b, 3, h, w) for n in ("prev", "next", "stereo")}
    names = {"M": ("prev", "next"), "S": ("stereo",), "MS": ("prev", "next", "stereo"), "next-only": ("next",)}[mode]
    batch = {"target": torch.rand(b, 3, h, w), "K": _K(b), "sources": {n: frames[n] for n in names},
             "transforms": {"stereo": _shift_T(-0.1, b)} if "stereo" in names else {}}
    terms = pipeline.batch_loss(models, batch, noise_std=0.0)
    assert set(terms) == {"loss", "photometric", "smoothness", "automask_fraction"}
    assert terms["loss"].ndim == 0 and torch.isfinite(terms["loss"])
    terms["loss"].backward()
    grad = models["depth_encoder"].conv1.weight.grad
    assert grad is not None and torch.isfinite(grad).all() and grad.abs().sum() > 0
    pose_grad = models["pose_encoder"].conv1.weight.grad
    assert (pose_grad is not None) == (mode != "S")


def test_stereo_transform_shifts_like_the_baseline():
    """Left target, right source 0.5 m to the right: a point at depth d appears f * 0.5 / d px further left."""
    image = torch.rand(1, 3, 32, 64)
    T = pipeline.stereo_transform(0.5, image)
    assert torch.allclose(T[0, :3, 3], torch.tensor([-0.5, 0.0, 0.0]))
    grid, _ = warping.sampling_grid(torch.full((1, 1, 32, 64), 10.0), _K(1), T)
    pix_u = ((grid[..., 0] + 1) * 64 - 1) / 2
    assert torch.allclose(pix_u, torch.arange(64.0) - 50.0 * 0.5 / 10.0, atol=1e-4)


@pytest.mark.parametrize("init", [0.02, 0.3])
def test_init_disparity_sets_the_untrained_output(init):
    torch.manual_seed(0)
    models = networks.build_models(base_channels=8, init_disparity=init).eval()
    # zero the last decoder features' weights: the output is then exactly sigmoid(bias)
    for conv in models["depth_decoder"].dispconv:
        torch.nn.init.zeros_(conv.weight)
    with torch.no_grad():
        disps = pipeline.predict_disparities(models, torch.rand(1, 3, 32, 64))
    assert all(torch.allclose(d, torch.full_like(d, init), atol=1e-6) for d in disps)
    _, depth = networks.disp_to_depth(torch.tensor(init), 0.1, 100.0)
    assert depth.item() == pytest.approx(1.0 / (0.01 + 9.99 * init))
    with pytest.raises(ValueError, match="init_disparity"):
        networks.build_models(8, init_disparity=1.0)


def test_warp_with_huge_coordinates_is_finite_and_matches_the_border():
    """A diverged pose (translation 1e30) sends every pixel far outside: the warp is the border colour and the
    backward pass is finite (the unclamped CPU grid sampler crashed on such coordinates)."""
    image = torch.rand(1, 3, 8, 16, requires_grad=True)
    depth = torch.full((1, 1, 8, 16), 5.0, requires_grad=True)
    K = _K(1, f=10.0, w=16, h=8)
    out = warping.warp(image, depth, K, _shift_T(1e30))
    out.sum().backward()
    assert torch.allclose(out[0], image[0, :, :, -1:].detach().expand(3, 8, 16))  # x -> +inf: the right border
    assert torch.isfinite(image.grad).all() and torch.isfinite(depth.grad).all()
    assert depth.grad.abs().max() < 1e-5  # nothing to learn from a view that lies entirely off the image
